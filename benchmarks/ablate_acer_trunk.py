"""
Shared against separate MLPs for ACER's policy and Q heads on Acrobot-v1: the mean training episode
return (last 100 episodes) every 10k env steps, one seed per arm.

    python benchmarks/ablate_acer_trunk.py [--steps 60000] [--seed 0]
"""

import argparse

import numpy as np
import torch as th
from stable_baselines3.common.env_util import make_vec_env

from sb3_disagree import ACER
from sb3_disagree.loggers import silent_logger

ARMS = {"shared [64, 64]": [64, 64], "separate pi [64, 64], qf [64, 64]": dict(pi=[64, 64], qf=[64, 64])}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=60_000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    th.set_num_threads(1)
    for name, net_arch in ARMS.items():
        env = make_vec_env("Acrobot-v1", n_envs=4, seed=args.seed)
        model = ACER("MlpPolicy", env, seed=args.seed, ent_coef=0.0, learning_rate=7e-4, replay_ratio=4,
                     policy_kwargs=dict(net_arch=net_arch))
        model.set_logger(silent_logger())  # SB3's default logger leaves a folder in the temp dir
        curve = []
        for _ in range(args.steps // 10_000):
            model.learn(10_000, reset_num_timesteps=False)
            curve.append(np.mean([ep["r"] for ep in model.ep_info_buffer]))
        print(f"| {name} | " + " | ".join(f"{r:.0f}" for r in curve) + " |", flush=True)


if __name__ == "__main__":
    main()
