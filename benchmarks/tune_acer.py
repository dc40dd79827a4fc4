"""
Small grid search for ACER's hyperparameters on one env; prints steps to threshold per configuration.

    python benchmarks/tune_acer.py --env CartPole-v1 --seeds 0 1 2 --grid '{"learning_rate": [7e-4, 1e-3]}'

Each configuration starts from sb3_disagree/hyperparams/acer.yml and overrides the grid's keys.
"""

import argparse
import itertools
import json
import os
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from classic_control import BUDGETS, run_one


def _cell(args: tuple) -> tuple[str, int, dict]:
    env_id, key, overrides, seed, eval_freq = args
    return key, seed, run_one("acer", env_id, seed, BUDGETS[env_id], eval_freq, overrides=overrides)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="CartPole-v1")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--grid", default="{}", help="JSON: key -> list of values")
    parser.add_argument("--eval-freq", type=int, default=5_000)
    parser.add_argument("--jobs", type=int, default=os.cpu_count())
    args = parser.parse_args()
    grid = json.loads(args.grid)
    configs = [dict(zip(grid, values)) for values in itertools.product(*grid.values())] or [{}]
    cells = [(args.env, json.dumps(c), c, s, args.eval_freq) for c in configs for s in args.seeds]
    results: dict[str, list] = {}
    with ProcessPoolExecutor(args.jobs) as pool:
        for key, seed, rec in pool.map(_cell, cells):
            results.setdefault(key, []).append(rec)
            print(f"{key} seed {seed}: solved at {rec['steps_to_threshold']}, final {rec['final_return']:.1f}", flush=True)
    print("\nconfig | solved seeds | median steps to threshold | mean final return")
    for key, recs in results.items():
        steps = [r["steps_to_threshold"] for r in recs if r["steps_to_threshold"] is not None]
        med = f"{np.median(steps):.0f}" if steps else "-"
        print(f"{key} | {len(steps)}/{len(recs)} | {med} | {np.mean([r['final_return'] for r in recs]):.1f}")


if __name__ == "__main__":
    main()
