"""
Where a saved policy's greedy failures go: run it alone (SB3's ``predict``, greedy, its memory carried by ``state``)
and, for each episode that fails, count the steps whose frame was already seen in the episode (an exact loop, which
the greedy-consistency phase samples its way out of) and the distinct frames of its last 60 steps (1: pressed
against a wall; 2: turning back and forth), with the actions it took (9b0ec2d:docs/results.md, "The greedy zoo").

    python benchmarks/loop_census.py ZOO/sb3_disagree__Office-v0/sofa/model.zip --env sb3_disagree/Office-v0 \\
        --goal sofa [--episodes 40] [--seed 10000] [--sampled]
"""

import argparse

import numpy as np
from stable_baselines3.common.env_util import make_vec_env

import sb3_disagree  # noqa: F401  (registers the envs)
from sb3_disagree import ACER


def census(model: ACER, env_id: str, goal: str, episodes: int, seed: int, deterministic: bool = True) -> list[dict]:
    """
    Each episode of the model alone: success, length, steps on a frame seen before, distinct frames of the last 60
    steps and the count of each action.
    """
    env = make_vec_env(env_id, n_envs=4, seed=seed, env_kwargs=dict(goal=goal))
    obs, state, starts = env.reset(), None, np.ones(4, dtype=bool)
    trails: list[list[tuple[bytes, int]]] = [[] for _ in range(4)]
    # Each env's first episodes, as SB3's evaluate_policy counts them: the first episodes to end over all envs would
    # be the short ones, and failures (which run to the cut) would be undercounted.
    targets = [(episodes + i) // 4 for i in range(4)]
    ended: list[dict] = []
    while len(ended) < episodes:
        actions, state = model.predict(obs, state=state, episode_start=starts, deterministic=deterministic)
        keys = [o.tobytes() for o in obs]
        obs, _, starts, infos = env.step(actions)
        for i in range(4):
            trails[i].append((keys[i], int(actions[i])))
            if starts[i]:
                trail, trails[i] = trails[i], []
                if targets[i] == 0:
                    continue
                targets[i] -= 1
                seen: set[bytes] = set()
                repeats = 0
                for key, _ in trail:
                    repeats += key in seen
                    seen.add(key)
                ended.append({"success": bool(infos[i].get("is_success")), "length": len(trail), "repeats": repeats,
                              "distinct_last_60": len({key for key, _ in trail[-60:]}),
                              "actions": np.bincount([a for _, a in trail], minlength=3).tolist()})
    return ended


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("model")
    parser.add_argument("--env", default="sb3_disagree/Apartment-v0")
    parser.add_argument("--goal", required=True)
    parser.add_argument("--episodes", type=int, default=40)
    parser.add_argument("--seed", type=int, default=10000, help="env seed of the first of the 4 envs")
    parser.add_argument("--sampled", action="store_true", help="sampled actions instead of greedy")
    args = parser.parse_args()
    rows = census(ACER.load(args.model, device="cpu"), args.env, args.goal, args.episodes, args.seed, not args.sampled)
    print(f"{args.goal}: {sum(r['success'] for r in rows)}/{len(rows)} reached the goal "
          f"({'sampled' if args.sampled else 'greedy'}, env seeds {args.seed}+)")
    for r in rows:
        if not r["success"]:
            print(f"failed: {r['length']} steps, {r['repeats']} on a frame seen before, {r['distinct_last_60']} distinct "
                  f"frames in the last 60, actions left/right/forward {r['actions']}")


if __name__ == "__main__":
    main()
