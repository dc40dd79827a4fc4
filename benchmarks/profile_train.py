"""
Where `dopt train`'s time goes on the apartment RGB with disagreement options: env step and render,
the new policy's forward pass, the priors' forward passes, the behaviour's other work, and ACER's
updates, measured with cProfile after a warm-up that fills the buffer past ``replay_start``.

    python benchmarks/profile_train.py --steps 4000 [--warm 2400] [--threads 1] [--write]
"""

import argparse
import cProfile
import os
import platform
import pstats
import time
from pathlib import Path
from tempfile import TemporaryDirectory

import torch as th
from docs_section import write_section
from stable_baselines3.common.callbacks import BaseCallback

# (label, function name, file fragment): cumulative time of each, the largest match kept.
PARTS = [
    ("env step (MiniWorld render + physics)", "step_wait", "dummy_vec_env"),
    ("priors' forward passes", "probs", "options/priors"),
    ("behaviour (entropy branch, gate, mu)", "__call__", "options/base"),
    ("new policy's forward in rollouts", "action_probs", "acer/policies"),
    ("rollout collection in all", "collect_rollouts", "acer/acer"),
    ("ACER updates (on-policy + replay)", "_update", "acer/acer"),
    ("  backward", "backward", "torch/_tensor"),
    ("  replay sampling", "sample", "acer/buffers"),
]


class ProfileAfter(BaseCallback):
    """cProfile from the first ``skip`` env steps on (env creation, model set-up and warm-up excluded)."""

    def __init__(self, skip: int) -> None:
        super().__init__()
        self.skip, self.profiler, self.t0, self.wall = skip, cProfile.Profile(), None, 0.0

    def _on_step(self) -> bool:
        if self.t0 is None and self.num_timesteps >= self.skip:
            self.t0 = time.perf_counter()
            self.profiler.enable()
        return True

    def stop(self) -> cProfile.Profile:
        self.profiler.disable()
        self.wall = time.perf_counter() - self.t0
        return self.profiler


def own_time_rows(stats: pstats.Stats, n: int) -> list[str]:
    """The ``n`` functions with the largest own time, as table rows."""
    top = sorted(stats.stats.items(), key=lambda kv: kv[1][2], reverse=True)[:n]
    rows = []
    for (file, line, fn), (_, _, tottime, _, _) in top:
        where = fn if file == "~" else f"{Path(file).parent.name}/{Path(file).name}:{line} {fn}"
        rows.append(f"| `{where}` | {tottime:.1f} | {100 * tottime / stats.total_tt:.0f}% |")
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=4_000)
    parser.add_argument("--warm", type=int, default=2_400, help="steps before profiling (ACER's replay starts at 2k)")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--mode", default="disagreement")
    parser.add_argument("--write", action="store_true", help="write the table into docs/benchmarks.md")
    args = parser.parse_args()
    th.set_num_threads(args.threads)
    from sb3_disagree.run import RunConfig, train

    profiled = ProfileAfter(args.warm)
    with TemporaryDirectory() as tmp:
        # One uninterrupted run: a resumed one would start with an empty replay buffer and no replay updates.
        config = RunConfig(goal="bathtub", mode=args.mode, priors=["shower", "toilet"], steps=args.warm + args.steps)
        train(config, Path(tmp), callbacks=[profiled])
    profiler = profiled.stop()
    wall = profiled.wall
    stats = pstats.Stats(profiler)
    total = stats.total_tt
    rows = []
    for label, name, fragment in PARTS:
        best = 0.0
        for (file, _, fn), (_, _, _, cumtime, _) in stats.stats.items():
            if fn == name and fragment in file.replace("\\", "/"):
                best = max(best, cumtime)
        rows.append(f"| {label} | {best:.1f} | {100 * best / total:.0f}% |")
    body = (f"Command: `python benchmarks/profile_train.py --steps {args.steps} --warm {args.warm} --threads {args.threads}`: `dopt train "
            f"--goal bathtub --mode {args.mode}` on the defaults (4 envs, RGB 60x80, priors shower and toilet), "
            f"{args.steps} env steps after a {args.warm}-step warm-up in the same run, under cProfile, {args.threads} torch thread(s); "
            f"{platform.machine()}, {os.cpu_count()} cores. {args.steps} steps in {wall:.1f} s "
            f"({args.steps / wall:.0f} steps/s under the profiler).\n\n"
            "| part | cumulative s | share |\n|---|---|---|\n" + "\n".join(rows) + "\n\n"
            "The functions with the most time spent in themselves (not in what they call):\n\n"
            "| function | own s | share |\n|---|---|---|\n" + "\n".join(own_time_rows(stats, 6)) + "\n")
    if args.write:
        write_section("train-profile", "Where `dopt train`'s time goes", body)
    print(body)
    stats.sort_stats("tottime").print_stats(20)


if __name__ == "__main__":
    main()
