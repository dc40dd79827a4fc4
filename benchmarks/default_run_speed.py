"""
`dopt train`'s default run (kickstarting, overlapped, three frames with loop flags, priors shower and toilet) timed
two ways, in fresh processes taking turns so that the machine's slow spells fall on both; env steps/s after a
warm-up and the process's minor page faults. Written into docs/benchmarks.md. ``--set allocator``: glibc's default
settings against ``sb3_disagree.run.allocator.keep_freed_memory`` (what ``train`` applies); ``--set teacher``: the
kickstarting teacher computed at each step against once per rollout (``PriorTeacher``'s default), both with the
allocator's settings; ``--set average-ahead``: ACER's ``average_ahead`` off and on.

    python benchmarks/default_run_speed.py [--set allocator|teacher|average-ahead] [--steps 12000] [--warm 2400] [--repeats 2] [--write]
"""

import argparse
import json
import os
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np
from docs_section import write_section

# One timed run in a fresh process (the allocator's settings hold for a whole process).
CHILD = """
import importlib, json, resource, sys
from pathlib import Path
from tempfile import TemporaryDirectory
sys.path.insert(0, {bench!r})
from train_speed import Rate
if {variant!r} == "glibc defaults":
    importlib.import_module("sb3_disagree.run.train").keep_freed_memory = lambda: False
if {variant!r} == "teacher at each step":
    importlib.import_module("sb3_disagree.options.teacher").PriorTeacher.__init__.__defaults__ = (False,)
from sb3_disagree.run import RunConfig, train
with TemporaryDirectory() as tmp:
    rate = Rate({warm})
    config = RunConfig(goal="bathtub", mode="kickstart", priors=["shower", "toilet"], steps={warm} + {steps},
                       overlap=True, frame_stack=3, loop_flags=True,
                       acer_kwargs={{"average_ahead": True}} if {variant!r} == "average_ahead on" else {{}})
    train(config, Path(tmp), callbacks=[rate])
print(json.dumps({{"rate": rate.rate(), "minflt": resource.getrusage(resource.RUSAGE_SELF).ru_minflt}}))
"""
SETS = {"allocator": ("glibc defaults", "keep_freed_memory"),
        "teacher": ("teacher at each step", "teacher once per rollout"),
        "average-ahead": ("average_ahead off", "average_ahead on")}


def timed(variant: str, steps: int, warm: int) -> dict:
    code = CHILD.format(bench=str(Path(__file__).parent), variant=variant, warm=warm, steps=steps)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=12_000)
    parser.add_argument("--warm", type=int, default=2_400, help="steps before timing (ACER's replay starts at 2k)")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--set", choices=sorted(SETS), default="allocator")
    parser.add_argument("--write", action="store_true")
    args = parser.parse_args()
    variants = SETS[args.set]
    rows: dict[str, list[dict]] = {v: [] for v in variants}
    for i in range(args.repeats):
        for variant in variants if i % 2 == 0 else variants[::-1]:
            rows[variant].append(timed(variant, args.steps, args.warm))
            print(variant, rows[variant][-1], flush=True)

    def cell(values: list[float], fmt: str) -> str:
        return f"{np.median(values):{fmt}} ({min(values):{fmt}}-{max(values):{fmt}})"

    table = "\n".join(f"| {v} | {cell([r['rate'] for r in rows[v]], '.0f')} | "
                      f"{cell([r['minflt'] / 1e6 for r in rows[v]], '.2f')} |" for v in variants)
    body = (f"Command: `python benchmarks/default_run_speed.py --set {args.set} --steps {args.steps} --warm {args.warm} --repeats "
            f"{args.repeats}`; {platform.machine()}, {os.cpu_count()} cores, one run at a time; median (min-max) of "
            f"{args.repeats} runs per row, the rows taking turns, each in a fresh process. `dopt train --goal bathtub`'s "
            f"default run (kickstarting, `--overlap`, three frames with loop flags), env steps/s over {args.steps} "
            f"steps after a {args.warm}-step warm-up, and the process's minor page faults (millions, set-up "
            "included).\n\n| " + args.set + " | env steps/s | minor page faults (M) |\n|---|---|---|\n" + table + "\n")
    if args.write:
        write_section(f"{args.set}-speed", {"allocator": "The allocator", "teacher": "The teacher once per rollout"}[args.set],
                      body)
    print(body)


if __name__ == "__main__":
    main()
