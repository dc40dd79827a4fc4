"""
A saved model as a user meets it: ``ACER.load`` and SB3's own ``evaluate_policy`` on the env as registered,
greedy and sampled side by side (success counted from ``info["is_success"]``), from one env seed the runs never
trained or evaluated on.

    python benchmarks/sb3_evaluate.py RUN/model.zip [RUN/checkpoints/000000100000/model.zip ...] \
        [--goal bathtub] [--episodes 100] [--seed 777]
"""

import argparse

from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy

from sb3_disagree import ACER
from sb3_disagree.defaults import DEFAULT_ENV


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
            successes: list[bool] = []
            evaluate_policy(model, env, n_eval_episodes=args.episodes, deterministic=deterministic,
                            callback=lambda l, g: successes.append(bool(l["info"].get("is_success"))) if l["done"] else None)
            env.close()
            row.append(f"{'greedy' if deterministic else 'sampled'} {sum(successes) / len(successes):.2f} "
                       f"({len(successes)} episodes)")
        print(f"{path}: " + ", ".join(row), flush=True)


if __name__ == "__main__":
    main()
