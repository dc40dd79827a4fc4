"""
The greedy-consistency phase on an experiment cell's finished runs: each seed's model refined
(``sb3_disagree.run.consistency.refine_run``, written to ``seed-S/consistent/``) and a table of the policy alone
before (the run's result.json) and after, greedy and sampled, 100 episodes each from the run's final-evaluation
env seeds (9b0ec2d:docs/results.md, "Greedy consistency").

    python benchmarks/greedy_consistency.py benchmarks/results/experiments/alone-bathtub/kickstart-rs1-ema-overlap \
        --seeds 0,1,2,3,4 [--rounds 3] [--steps 20000] [--name consistent] [--force] [--threads 1]
"""

import argparse
import json
from pathlib import Path

import torch as th

from sb3_disagree.run.consistency import FOLDER, refine_run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("cell", type=Path)
    parser.add_argument("--seeds", default="0,1,2,3,4")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--epochs", type=int, default=3)
    parser.add_argument("--sampling", default="loops", choices=["loops", "always"],
                        help="where the collection samples: in loops only (greedy elsewhere), or every action")
    parser.add_argument("--name", default=FOLDER, help="the folder inside each run (one per setting)")
    parser.add_argument("--force", action="store_true", help="redo seeds already refined")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (1: two such processes on two cores)")
    args = parser.parse_args()
    th.set_num_threads(args.threads)
    rows = []
    for seed in [int(s) for s in args.seeds.split(",")]:
        run = args.cell / f"seed-{seed}"
        done = run / args.name / "result.json"
        if args.force or not done.exists():
            refine_run(run, rounds=args.rounds, steps=args.steps, epochs=args.epochs, force=args.force, name=args.name,
                       sampling=args.sampling,
                       on_round=lambda r, s=seed: print(f"seed {s}: {r}", flush=True))
        before, after = json.loads((run / "result.json").read_text()), json.loads(done.read_text())
        rows.append((seed, before["final_alone_greedy"]["success_rate"], before["final_alone"]["success_rate"],
                     after["final_alone_greedy"]["success_rate"], after["final_alone"]["success_rate"],
                     after["env_steps"], after["seconds"]))
    print("| seed | before: greedy | sampled | after: greedy | sampled | env steps of the phase | seconds |")
    print("|---|---|---|---|---|---|---|")
    for row in rows:
        print("| {} | {:.2f} | {:.2f} | {:.2f} | {:.2f} | {:,} | {:.0f} |".format(*row))
    n = len(rows)
    print("| mean | {:.2f} | {:.2f} | {:.2f} | {:.2f} | | |".format(*(sum(r[i] for r in rows) / n for i in range(1, 5))))


if __name__ == "__main__":
    main()
