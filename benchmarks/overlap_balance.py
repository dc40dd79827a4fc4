"""
Where an overlapped `dopt train` run (`--overlap`, the default) spends a segment: the rollout (main
thread), the on-policy update and the replay updates (second thread), timed per segment after the
warm-up, with the run's env steps/s. Printed, not written into the docs.

    python benchmarks/overlap_balance.py [--steps 4000] [--warm 2400] [--threads 2]
"""

import argparse
import time
from collections import defaultdict

import numpy as np
import torch as th
from train_speed import acer_rate

from sb3_disagree.acer import ACER
from sb3_disagree.acer import overlap


def timed(times: dict[str, list[float]], name: str, method):
    def wrapper(self, *args, **kwargs):
        start = time.perf_counter()
        out = method(self, *args, **kwargs)
        times[name].append(time.perf_counter() - start)
        return out

    return wrapper


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=4_000)
    parser.add_argument("--warm", type=int, default=2_400)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    th.set_num_threads(args.threads)
    times: dict[str, list[float]] = defaultdict(list)
    for name, attr in [("rollout", "collect_rollouts"), ("on-policy update", "on_policy_update"),
                       ("replay updates", "replay")]:
        setattr(ACER, attr, timed(times, name, getattr(ACER, attr)))
    overlap.copy_learner = timed(times, "copy to the acting policy", overlap.copy_learner)
    rate = acer_rate("disagreement", args.steps, args.warm, "dummy", overlap=True)
    segments = args.steps // 80  # 4 envs x 20 steps: the segments after the warm-up
    print(f"env steps/s after the warm-up: {rate:.0f}; per segment (mean of the last {segments}):")
    for name, values in times.items():
        print(f"  {name}: {1000 * np.mean(values[-segments:]):.0f} ms")


if __name__ == "__main__":
    main()
