"""
`dopt train`'s default against its own env, back to back in one run: the raw RGB apartment stepped with random
actions on one core, then `dopt train --goal bathtub`'s configuration (``RunConfig(goal="bathtub")``, everything as
shipped but the run's length fixed) over ``--steps`` env steps after a warm-up. The ratio of the two is printed last.
Run it on a quiet machine.

    python benchmarks/env_ratio.py [--steps 40000] [--warm 2400] [--raw-steps 20000] [--write]
"""

import argparse
import os
import platform
import time
from pathlib import Path
from tempfile import TemporaryDirectory

from apartment_speed import steps_per_second
from docs_section import write_section
from stable_baselines3.common.callbacks import BaseCallback


class LoopRate(BaseCallback):
    """Env steps per second between the ``skip``-th env step and the last one (set-up, warm-up and the fit after the
    last step excluded)."""

    def __init__(self, skip: int) -> None:
        super().__init__()
        self.skip = skip
        self.t0 = self.t1 = 0.0
        self.n0 = self.n1 = 0

    def _on_step(self) -> bool:
        now = time.perf_counter()
        if not self.n0 and self.num_timesteps >= self.skip:
            self.t0, self.n0 = now, self.num_timesteps
        self.t1, self.n1 = now, self.num_timesteps
        return True

    def rate(self) -> float:
        return (self.n1 - self.n0) / (self.t1 - self.t0)


def default_rate(steps: int, warm: int) -> float:
    from sb3_disagree.run import RunConfig, train

    with TemporaryDirectory() as tmp:
        rate = LoopRate(warm)
        # ready=0: the run is as long as asked (a greedy phase that waited would only make it longer, at the same pace)
        train(RunConfig(goal="bathtub", steps=warm + steps, ready=0), Path(tmp), callbacks=[rate])
        return rate.rate()


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=40_000)
    parser.add_argument("--warm", type=int, default=2_400)
    parser.add_argument("--raw-steps", type=int, default=20_000)
    parser.add_argument("--write", action="store_true")
    args = parser.parse_args()
    raw = steps_per_second("rgb", args.raw_steps)
    print(f"raw env: {raw:.0f} env steps/s", flush=True)
    default = default_rate(args.steps, args.warm)
    print(f"default dopt train: {default:.0f} env steps/s", flush=True)
    body = (f"Command: `python benchmarks/env_ratio.py --steps {args.steps} --warm {args.warm} --raw-steps "
            f"{args.raw_steps}`; {platform.machine()}, {os.cpu_count()} cores, nothing else running. The raw RGB "
            f"apartment with random actions on one core over {args.raw_steps} env steps, then `dopt train --goal "
            f"bathtub`'s configuration (its length fixed: `ready=0`) over {args.steps} env steps after a {args.warm}-step warm-up, in the same "
            "process.\n\n| raw env (env steps/s) | default dopt train (env steps/s) | ratio |\n|---|---|---|\n"
            f"| {raw:.0f} | {default:.0f} | {default / raw:.0%} |\n")
    if args.write:
        write_section("env-ratio", "The default against its own env", body)
    print(f"ratio: {default / raw:.0%}")


if __name__ == "__main__":
    main()
