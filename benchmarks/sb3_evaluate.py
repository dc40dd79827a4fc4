"""
A saved model as a user meets it: ``ACER.load`` and SB3's own ``evaluate_policy`` (through the package's
``evaluate``, which counts success from ``info["is_success"]``) on the env as registered, greedy and sampled side by
side, from one env seed the runs never trained or evaluated on.

    python benchmarks/sb3_evaluate.py RUN/model.zip [RUN/checkpoints/000000100000/model.zip ...] \
        [--goal bathtub] [--episodes 100] [--seed 777]
"""

import argparse

from stable_baselines3.common.env_util import make_vec_env

from sb3_disagree import ACER
from sb3_disagree.defaults import DEFAULT_ENV
from sb3_disagree.evaluation import evaluate  # SB3's evaluate_policy, success counted from is_success


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("models", nargs="+")
    parser.add_argument("--goal", default="bathtub")
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=777)
    args = parser.parse_args()
    for path in args.models:
        model, row = ACER.load(path), []
        for deterministic in (True, False):
            env = make_vec_env(DEFAULT_ENV, n_envs=4, seed=args.seed, env_kwargs=dict(goal=args.goal))
            result = evaluate(model, env, args.episodes, deterministic)
            env.close()
            row.append(f"{'greedy' if deterministic else 'sampled'} {result.success_rate:.2f} ({result.episodes} episodes)")
        print(f"{path}: " + ", ".join(row), flush=True)


if __name__ == "__main__":
    main()
