"""
Try settings of the method on one goal: each variant is a run of ``sb3_disagree.training.train`` with
some RunConfig fields or ACER hyperparameters overridden, evaluated alone (no priors) along the way.

    python benchmarks/tune_method.py --name ent05 --steps 60000 --set acer.ent_coef=0.05 --set beta=0.1

Runs go to benchmarks/results/tune_method/<name>/...; the last line printed is the summary
(training success over the last 10% of steps, prior usage, evaluations of the policy alone).
"""

import argparse
from pathlib import Path

import numpy as np
import pandas as pd
import torch as th
import yaml

ROOT = Path(__file__).resolve().parent / "results" / "tune_method"


def parse_sets(items: list[str]) -> tuple[dict, dict]:
    fields, acer = {}, {}
    for item in items:
        key, value = item.split("=", 1)
        value = yaml.safe_load(value)
        if key.startswith("acer."):
            acer[key[5:]] = value
        else:
            fields[key] = value
    return fields, acer


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--name", required=True)
    parser.add_argument("--goal", default="bathtub")
    parser.add_argument("--priors", default="shower,toilet")
    parser.add_argument("--mode", default="disagreement")
    parser.add_argument("--steps", type=int, default=60_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--eval-every", type=int, default=15_000)
    parser.add_argument("--set", action="append", default=[], help="FIELD=VALUE or acer.KEY=VALUE")
    args = parser.parse_args()
    th.set_num_threads(1)
    from sb3_disagree.training import ACER_KWARGS, RunConfig, train

    fields, acer = parse_sets(args.set)
    config = RunConfig(goal=args.goal, mode=args.mode, priors=args.priors.split(","), seed=args.seed, steps=args.steps,
                       eval_every=args.eval_every, acer_kwargs={**ACER_KWARGS, **acer}, **fields)
    run_dir, model, _ = train(config, ROOT / args.name)
    progress = pd.read_csv(run_dir / "progress.csv")
    tail = progress[progress["time/total_timesteps"] >= 0.9 * args.steps]
    evals = np.load(run_dir / "evaluations.npz")
    alone = ", ".join(f"{t // 1000}k {np.mean(s):.2f}" for t, s in zip(evals["timesteps"], evals["successes"]))
    usage = tail["prior/usage"].mean() if "prior/usage" in tail else float("nan")
    print(f"{args.name}: train success {tail['rollout/success_rate'].mean():.2f}, usage {usage:.2f}, "
          f"entropy {tail['prior/entropy'].mean() if 'prior/entropy' in tail else float('nan'):.2f}; alone: {alone}")


if __name__ == "__main__":
    main()
