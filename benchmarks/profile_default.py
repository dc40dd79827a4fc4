"""
Where the time of `dopt train --goal bathtub` (the default: kickstarting with the finish, the overlapped loop) goes on
each of its two threads, per env step: timed wrappers around the rollout's parts on the main thread (the env, acting,
the behaviour with its teacher, the on-policy update, the reference ahead, the copy into the acting policy, waiting
for the worker) and the replay updates on the worker. Two windows: while the priors still teach (the first 50k steps)
and after (distillation ended early here, so that the priors are no longer run, as after 50k in a real run).

    python benchmarks/profile_default.py [--steps 4000] [--warm 2400] [--threads 2]
"""

import argparse
import time
from collections import defaultdict
from concurrent.futures import Future
from pathlib import Path
from tempfile import TemporaryDirectory

import torch as th
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_disagree.acer import ACER, overlap
from sb3_disagree.acer.policies import ACERPolicy
from sb3_disagree.options.teacher import PriorTeacher
from sb3_disagree.run import RunConfig, train

MAIN = ("env step (render + physics)", "acting: the policy's forward", "behaviour (the priors' teacher)",
        "rest of the rollout", "on-policy update", "reference ahead", "copy into the acting policy",
        "waiting for the worker")


class Window(BaseCallback):
    """Counts env steps and wall time from the warm-up's end; clears the timings there."""

    def __init__(self, warm: int, times: dict) -> None:
        super().__init__()
        self.warm, self.times, self.start, self.steps0 = warm, times, None, 0

    def _on_step(self) -> bool:
        if self.start is None and self.num_timesteps >= self.warm:
            self.times.clear()
            self.start, self.steps0 = time.perf_counter(), self.num_timesteps
        return True

    def _on_training_end(self) -> None:
        self.seconds, self.steps = time.perf_counter() - self.start, self.num_timesteps - self.steps0


def wrap(times: dict, name: str, owner, attr: str) -> None:
    method = getattr(owner, attr)

    def timed(*args, **kwargs):
        start = time.perf_counter()
        try:
            return method(*args, **kwargs)
        finally:
            times[name] += time.perf_counter() - start

    setattr(owner, attr, timed)


TIMES: dict[str, float] = defaultdict(float)


def wrap_all(times: dict) -> None:
    wrap(times, "env step (render + physics)", DummyVecEnv, "step_wait")
    wrap(times, "acting: the policy's forward", ACERPolicy, "action_probs")
    wrap(times, "behaviour (the priors' teacher)", PriorTeacher, "__call__")
    wrap(times, "behaviour (the priors' teacher)", PriorTeacher, "rollout_teacher")
    wrap(times, "rollout", ACER, "collect_rollouts")
    wrap(times, "on-policy update", ACER, "on_policy_update")
    wrap(times, "reference ahead", ACER, "replay_references")
    wrap(times, "replay updates (worker thread)", ACER, "replay")
    wrap(times, "copy into the acting policy", overlap, "copy_learner")
    wrap(times, "waiting for the worker", Future, "result")


def profile(steps: int, warm: int, distill_steps: int) -> tuple[dict, Window]:
    times = TIMES
    window = Window(warm, times)
    with TemporaryDirectory() as tmp:
        config = RunConfig(goal="bathtub", steps=warm + steps, consistency_harvest=0, checkpoint_every=0,
                           acer_kwargs={"distill_steps": distill_steps})
        train(config, Path(tmp), callbacks=[window])
    return dict(times), window


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=4_000)
    parser.add_argument("--warm", type=int, default=2_400)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    th.set_num_threads(args.threads)
    wrap_all(TIMES)
    rows = {}
    for label, distill in (("priors teaching", 50_000), ("after distillation", 1)):
        times, window = profile(args.steps, args.warm, distill)
        times["rest of the rollout"] = times.pop("rollout") - sum(
            times.get(k, 0.0) for k in MAIN[:3])
        rows[label] = (times, window)
    print(f"Command: `python benchmarks/profile_default.py --steps {args.steps} --warm {args.warm} --threads "
          f"{args.threads}`: `dopt train --goal bathtub`'s configuration (RunConfig(goal='bathtub'): kickstarting with "
          "the finish's memory, the overlapped loop, the reference ahead; the harvest off, no checkpoint), "
          f"{args.steps} env steps after {args.warm} of warm-up, {args.threads} torch threads.\n")
    print("| part | " + " | ".join(f"ms per env step, {label}" for label in rows) + " |")
    print("|---|" + "---|" * len(rows))
    for name in (*MAIN, "replay updates (worker thread)"):
        print(f"| {name} | " + " | ".join(f"{1000 * t.get(name, 0.0) / w.steps:.2f}" for t, w in rows.values())
              + " |")
    print("| wall clock | " + " | ".join(f"{1000 * w.seconds / w.steps:.2f} ({w.steps / w.seconds:.0f} env steps/s)"
                                         for _, w in rows.values()) + " |")


if __name__ == "__main__":
    main()
