"""
What bfloat16 features (ACER ``features_dtype``, docs/acer.md item 23) buy on this machine: one update's forward and
backward through `dopt train`'s network on a segment batch (84 stacks), float32 against bfloat16, on one thread; then,
with ``--runs N``, N interleaved pairs of short `dopt train`-like runs (kickstarting, overlapped, loop flags; no harvest)
and their env steps/s after ``--warm`` steps, so that the machine's slow spells fall on both.

    python benchmarks/features_dtype.py [--runs 2] [--steps 20000] [--warm 6000]
"""

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import torch as th
from train_speed import Rate


def update_ms(dtype, repeats: int = 30) -> float:
    import gymnasium as gym

    import sb3_disagree  # noqa: F401  (registers the envs)
    from sb3_disagree.acer import ACER
    from sb3_disagree.acer.torch_layers import loop_flags_kwargs

    env = gym.make("sb3_disagree/Apartment-v0", goal="bathtub")
    model = ACER("CnnPolicy", env, features_dtype=dtype, policy_kwargs=dict(frame_stack=3, **loop_flags_kwargs(3)))
    obs = th.randint(0, 255, (84, 9, 60, 80), dtype=th.uint8)

    def once() -> None:
        logits, q = model.policy.logits_and_q(obs)
        (logits.sum() + q.sum()).backward()

    for _ in range(3):
        once()
    start = time.perf_counter()
    for _ in range(repeats):
        once()
    env.close()
    return (time.perf_counter() - start) / repeats * 1000


class RateAtEnd(Rate):
    """``train_speed.Rate`` read when learning ends (before the run's closing save)."""

    def _on_training_end(self) -> None:
        self.final = self.rate()


def run_rate(dtype, steps: int, warm: int) -> float:
    from sb3_disagree.run import RunConfig, train

    rate = RateAtEnd(warm)
    config = RunConfig(goal="bathtub", steps=steps, overlap=True, frame_stack=3, loop_flags=True, greedy_phase=0,
                       consistency_harvest=0, checkpoint_every=0, acer_kwargs={"features_dtype": dtype})
    with tempfile.TemporaryDirectory() as out:
        train(config, Path(out), callbacks=[rate])
    return rate.final


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=0)
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--warm", type=int, default=6_000)
    args = parser.parse_args()
    th.set_num_threads(1)
    print("one update's forward and backward, 84 stacks, one thread: "
          + ", ".join(f"{name} {update_ms(d):.1f} ms" for name, d in (("float32", None), ("bfloat16", "bfloat16"))))
    th.set_num_threads(2)  # as dopt train
    rates: dict[str, list[float]] = {"float32": [], "bfloat16": []}
    for _ in range(args.runs):
        for name, dtype in (("float32", None), ("bfloat16", "bfloat16")):
            rates[name].append(run_rate(dtype, args.steps, args.warm))
            print(f"{name}: {rates[name][-1]:.0f} env steps/s", flush=True)
    if args.runs:
        print(", ".join(f"{name} {np.mean(r):.0f} env steps/s (runs {' '.join(f'{x:.0f}' for x in r)})"
                        for name, r in rates.items()))
