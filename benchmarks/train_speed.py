"""
End-to-end training throughput on the apartment RGB: `dopt train` with disagreement options (and from
scratch), each with ``--overlap`` (the default) and with the sequential loop of ``--no-overlap``, against
SB3's PPO CnnPolicy on the same env, one after another in the same process, each for the same number
of env steps after its own warm-up; with ``--repeats N`` the rows are measured N times, interleaved, and
the table gives the median and range. ``--set kickstart`` measures `dopt train`'s default mode instead:
kickstarting while its distillation is weighted (the priors run every step) and after the weight has reached 0
(they no longer run; the first 50k steps of a run against the rest), with both loops.
Written into docs/benchmarks.md.

    python benchmarks/train_speed.py --steps 6000 [--threads 2] [--vec-env dummy subproc] [--repeats 3] [--write]
    python benchmarks/train_speed.py --set kickstart --vec-env dummy --threads 2 --repeats 3 [--write]
"""

import argparse
import os
import platform
import time
from pathlib import Path
from tempfile import TemporaryDirectory
from typing import Optional

import numpy as np
import torch as th
from stable_baselines3.common.callbacks import BaseCallback


class Rate(BaseCallback):
    """Env steps per second after the first ``skip`` steps (env creation, model set-up and warm-up excluded)."""

    def __init__(self, skip: int) -> None:
        super().__init__()
        self.skip, self.t0, self.n0 = skip, None, 0

    def _on_step(self) -> bool:
        if self.t0 is None and self.num_timesteps >= self.skip:
            self.t0, self.n0 = time.perf_counter(), self.num_timesteps
        return True

    def rate(self) -> float:
        return (self.num_timesteps - self.n0) / (time.perf_counter() - self.t0)


def acer_rate(mode: str, steps: int, warm: int, vec_env: str, overlap: bool = False,
              acer_kwargs: Optional[dict] = None) -> float:
    from sb3_disagree.run import RunConfig, train

    with TemporaryDirectory() as tmp:
        rate = Rate(warm)
        config = RunConfig(goal="bathtub", mode=mode, priors=["shower", "toilet"], steps=warm + steps, vec_env=vec_env,
                           overlap=overlap, acer_kwargs=acer_kwargs or {})
        train(config, Path(tmp), callbacks=[rate])
        return rate.rate()


def ppo_rate(steps: int, warm: int, vec_env: str) -> float:
    from stable_baselines3 import PPO

    from sb3_disagree.run import RunConfig, build_env
    from sb3_disagree.loggers import silent_logger

    env = build_env(RunConfig(goal="bathtub", vec_env=vec_env), None)  # the envs dopt train makes
    # rl-zoo3's Atari settings for PPO, with 4 envs.
    model = PPO("CnnPolicy", env, n_steps=128, n_epochs=4, batch_size=256, learning_rate=2.5e-4, clip_range=0.1,
                ent_coef=0.01, vf_coef=0.5, seed=0)
    model.set_logger(silent_logger())  # SB3's default logger leaves a folder in the temp dir
    rate = Rate(warm)
    model.learn(warm + steps, callback=rate)
    env.close()
    return rate.rate()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=6_000)
    parser.add_argument("--warm", type=int, default=2_400, help="steps before timing (ACER's replay starts at 2k)")
    parser.add_argument("--threads", type=int, default=os.cpu_count())
    parser.add_argument("--vec-env", nargs="+", default=["dummy", "subproc"])
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--set", choices=["paper", "kickstart"], default="paper",
                        help="paper: disagreement options and scratch against PPO; kickstart: dopt train's default mode")
    parser.add_argument("--write", action="store_true")
    args = parser.parse_args()
    th.set_num_threads(args.threads)
    # The distillation weight is 0 from the start with distill_steps 1: the steps after a run's first 50k.
    after = dict(distill_steps=1)
    kickstart = {
        "kickstart (--overlap), distilling": lambda v: acer_rate("kickstart", args.steps, args.warm, v, True),
        "kickstart (--overlap), after distillation": lambda v: acer_rate("kickstart", args.steps, args.warm, v, True,
                                                                         after),
        "kickstart --no-overlap, distilling": lambda v: acer_rate("kickstart", args.steps, args.warm, v),
        "kickstart --no-overlap, after distillation": lambda v: acer_rate("kickstart", args.steps, args.warm, v,
                                                                          False, after),
    }
    paper = {
        "dopt train --no-overlap, disagreement": lambda v: acer_rate("disagreement", args.steps, args.warm, v),
        "dopt train (--overlap), disagreement": lambda v: acer_rate("disagreement", args.steps, args.warm, v, True),
        "dopt train --no-overlap, scratch": lambda v: acer_rate("scratch", args.steps, args.warm, v),
        "dopt train (--overlap), scratch": lambda v: acer_rate("scratch", args.steps, args.warm, v, True),
        "SB3 PPO CnnPolicy": lambda v: ppo_rate(args.steps, args.warm, v),
    }
    columns = kickstart if args.set == "kickstart" else paper
    rates: dict[tuple[str, str], list[float]] = {}
    for _ in range(args.repeats):  # interleaved, so that a slow minute of the machine hits every column
        for vec_env in args.vec_env:
            for name, measure in columns.items():
                rates.setdefault((vec_env, name), []).append(measure(vec_env))
                print(vec_env, name, f"{rates[vec_env, name][-1]:.0f}", flush=True)

    def cell(values: list[float]) -> str:
        if len(values) == 1:
            return f"{values[0]:.0f}"
        return f"{np.median(values):.0f} ({min(values):.0f}-{max(values):.0f})"

    rows = [f"| {v} | " + " | ".join(cell(rates[v, name]) for name in columns) + " |" for v in args.vec_env]
    how = "one value per cell" if args.repeats == 1 else f"median (min-max) of {args.repeats} interleaved runs per cell"
    body = (f"Command: `python benchmarks/train_speed.py --set {args.set} --steps {args.steps} --threads {args.threads} --vec-env "
            f"{' '.join(args.vec_env)} --repeats {args.repeats}`; {platform.machine()}, {os.cpu_count()} cores, "
            f"{args.threads} torch threads, one run at a time on a quiet machine; {how}. Env steps/s over {args.steps} "
            f"steps after a {args.warm}-step warm-up (ACER's replay updates have started), apartment RGB 60x80, 4 envs; "
            + ("ACER with the defaults of `dopt train`, PPO CnnPolicy with rl-zoo3's Atari settings (n_steps 128, "
               "4 epochs, batch 256).\n\n" if args.set == "paper" else
               "kickstarting with the defaults of `dopt train` (priors shower and toilet); 'after distillation': "
               "distillation weight 0 from the start, so the priors are not run (a run's steps after 50k).\n\n")
            + "| envs | " + " | ".join(columns) + " |\n|---|" + "---|" * len(columns) + "\n" + "\n".join(rows) + "\n")
    if args.write:
        from docs_section import write_section

        if args.set == "paper":
            write_section("train-speed", "Training throughput: dopt train against PPO", body)
        else:
            write_section("train-speed-kickstart", "Training throughput: kickstarting, during and after distillation",
                          body)
    print(body)


if __name__ == "__main__":
    main()
