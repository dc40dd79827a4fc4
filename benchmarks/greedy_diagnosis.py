"""
Why a trained policy fails greedily: run a saved model alone and report, per episode, whether it succeeded,
its length, how many distinct poses it visited in its last 60 steps (1: stuck at a fixed point), where it
ended (x, z, heading), its last actions and the policy's distribution at its last step (how far the argmax is
from a tie); then the same episodes acting by argmax Q instead of argmax pi (docs/results.md).

    python benchmarks/greedy_diagnosis.py RUN_DIR/model.zip [--episodes 12] [--goal bathtub] [--seed 777]
"""

import argparse

import numpy as np
import torch as th
from stable_baselines3.common.env_util import make_vec_env

import sb3_disagree  # noqa: F401  (registers the envs)
from sb3_disagree import ACER
from sb3_disagree.acer.memory import push_frames


def episodes(model: ACER, goal: str, n: int, by_q: bool, seed: int = 777) -> list[tuple]:
    env = make_vec_env("sb3_disagree/Apartment-v0", n_envs=4, seed=seed, env_kwargs=dict(goal=goal))
    obs, state, starts, stack = env.reset(), None, np.ones(4, bool), None
    trails, ended, actions_taken = [[] for _ in range(4)], [], np.zeros(3)
    while len(ended) < n:
        stack = push_frames(stack, obs.transpose(0, 3, 1, 2), starts, model.policy.frame_stack)
        with th.no_grad():  # the network predict acts with (the moving average where the model keeps one)
            net = model.policy.acting_net
            logits, q = net(model.policy.extract_features(th.as_tensor(stack), net.features_extractor))
        probs = th.softmax(logits, -1).numpy()
        if by_q:  # argmax_a Q(s, a) on the policy's own input
            actions = q.argmax(-1).numpy()
        else:
            actions, state = model.predict(obs, state=state, episode_start=starts, deterministic=True)
        obs, _, dones, infos = env.step(actions)
        for i in range(4):
            actions_taken[actions[i]] += 1
            x, z = infos[i]["position"]
            trails[i].append((round(x, 3), round(z, 3), round(infos[i]["heading"], 3), int(actions[i])))
            if dones[i]:
                tail = trails[i][-60:]
                ended.append((bool(infos[i]["is_success"]), len(trails[i]), len({t[:3] for t in tail}), tail[-1][:3],
                              [t[3] for t in tail[-8:]], np.round(probs[i], 2)))
                trails[i] = []
        starts = dones
    env.close()
    print(f"action shares (turn left, turn right, forward): {np.round(actions_taken / actions_taken.sum(), 3)}")
    return ended[:n]


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("model")
    parser.add_argument("--episodes", type=int, default=12)
    parser.add_argument("--goal", default="bathtub")
    parser.add_argument("--seed", type=int, default=777, help="env seed of the first of the 4 envs")
    args = parser.parse_args()
    th.set_num_threads(1)
    model = ACER.load(args.model, device="cpu")
    for label, by_q in (("greedy (argmax pi)", False), ("argmax Q", True)):
        ends = episodes(model, args.goal, args.episodes, by_q, args.seed)
        stuck = sum(1 for success, _, poses, *_ in ends if not success and poses == 1)
        print(f"{label}: success {np.mean([e[0] for e in ends]):.2f} over {len(ends)} episodes; {stuck} stuck at a "
              "single pose over their last 60 steps")
        for success, length, poses, pose, last, pi in ends:
            print(f"  success {success}, length {length}, distinct poses in the last 60 steps {poses}, ended at {pose}, "
                  f"last actions {last}, pi at the last step {pi}")
