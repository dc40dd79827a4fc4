"""
The grid expert alone, three ways, from the prior cards' env seeds (10000+): what a greedy prior can learn from it.

- ``memoryless``: ``env.expert_action()``, the planner's best action at the pose, what DAgger labels with by default;
- ``no-return``: ``env.expert_action(no_return=True)``, never staying in place (a blocked move) nor going back to the
  pose before the last step, what ``dopt priors train --expert-no-return`` labels with;
- ``visits``: ``GridExpert.__call__``, which avoids a pose it has been in twice in the episode (what the env's
  pictures and tests drive with), a memory no prior sees.

    python benchmarks/expert_alone.py --env sb3_disagree/Office-v0 --goals sofa,fridge,desk --episodes 300
"""

import argparse
import time

import gymnasium as gym
import numpy as np

import sb3_disagree  # noqa: F401  (registers the envs)
from sb3_disagree.defaults import PRIOR_CARD_SEED
from sb3_disagree.envs.expert import GridExpert

WAYS = ("memoryless", "no-return", "visits")


def run(env_id: str, goal: str, way: str, episodes: int) -> tuple[int, float, list[int]]:
    """Successes, mean episode length and failed env seeds of the expert driven ``way``, one episode per seed."""
    env = gym.make(env_id, goal=goal)
    successes, lengths, failed = 0, [], []
    for seed in range(PRIOR_CARD_SEED, PRIOR_CARD_SEED + episodes):
        env.reset(seed=seed)
        u = env.unwrapped
        expert, done = GridExpert(u), False
        while not done:
            action = expert() if way == "visits" else u.expert_action(no_return=way == "no-return")
            _, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        successes += bool(info["is_success"])
        lengths.append(u.step_count)
        if not info["is_success"]:
            failed.append(seed)
    env.close()
    return successes, float(np.mean(lengths)), failed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default="sb3_disagree/Office-v0")
    parser.add_argument("--goals", default="sofa,fridge,desk")
    parser.add_argument("--episodes", type=int, default=300)
    args = parser.parse_args()
    print(f"{args.env}, {args.episodes} episodes per goal from env seed {PRIOR_CARD_SEED}, the env's own step limit")
    print("| goal | " + " | ".join(f"{w}: success (mean length)" for w in WAYS) + " |")
    print("|---|" + "---|" * len(WAYS))
    for goal in args.goals.split(","):
        start, cells, notes = time.perf_counter(), [], []
        for way in WAYS:
            successes, length, failed = run(args.env, goal, way, args.episodes)
            cells.append(f"{successes}/{args.episodes} ({length:.1f})")
            if failed:
                notes.append(f"{way} failed from {', '.join(map(str, failed))}")
        print(f"| {goal} | " + " | ".join(cells) + f" |  <!-- {time.perf_counter() - start:.0f} s; "
              + "; ".join(notes) + " -->")


if __name__ == "__main__":
    main()
