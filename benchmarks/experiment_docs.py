"""
An experiment's report into the docs: the figure into docs/images/NAME.png and the table, with the
commands, seeds, budget and machine, into the NAME section of docs/results.md.

    dopt experiment run NAME --jobs 2 [--seeds 0,1,2]
    python benchmarks/experiment_docs.py NAME [--seeds 0,1]

``--seeds`` reports only those seeds, so that cells with more finished seeds than others are compared on
the same ones.
"""

import argparse
import os
import platform
from pathlib import Path
from typing import Optional

import yaml
from docs_section import DOCS, write_section

from sb3_disagree.experiments.report import (alone_markdown, plot, ratio_markdown, seeds_markdown, summarize,
                                             table_markdown)
from sb3_disagree.experiments.spec import load_experiment

ROOT = Path(__file__).resolve().parent / "results" / "experiments"


def main(name: str, only_seeds: Optional[list[int]] = None, note: str = "") -> None:
    experiment = load_experiment(name)
    experiment.restrict(seeds=only_seeds)
    root = ROOT / experiment.name
    grid, summaries = summarize(experiment, root)
    if not summaries:
        raise SystemExit(f"no finished runs of {name} under {root}")
    figure = DOCS / "images" / f"{experiment.name}.png"
    plot(experiment, grid, summaries, figure, root)
    seeds = sorted({s for c in summaries for s in c.seeds})
    acer = summaries[0].records[0]["config"]["acer_kwargs"]
    continued = ""
    if experiment.continues:
        begun = sorted({r.get("from_steps", 0) for c in summaries for r in c.records})
        continued = (f"Each run continues `{experiment.continues}`'s finished run of the same cell and seed (`continues:` "
                     f"in the YAML): its first {', '.join(f'{b:,}' for b in begun)} env steps are that run's, and the "
                     "replay buffer starts empty where it continues; env steps/s is the continuation's. ")
    copied = [f"{c.cell} = `{experiment.cells[c.cell]['same_as']}`" for c in summaries
              if any("copied_from" in r for r in c.records)]
    if copied:
        continued += (f"Runs taken from another experiment (`same_as:` in the YAML; the same configuration and seed, "
                      f"and runs are deterministic): {', '.join(copied)}. ")
    per_cell = {c.cell: sorted(c.seeds) for c in summaries}
    if len({tuple(v) for v in per_cell.values()}) == 1:
        seeds_text = f"Seeds {', '.join(map(str, seeds))}"
    else:
        seeds_text = "Seeds per cell: " + "; ".join(f"{k} {', '.join(map(str, v))}" for k, v in per_cell.items())
    run_cfg = summaries[0].records[0]["config"]
    alone_every = (f"{run_cfg.get('eval_episodes', 20)} episodes every {run_cfg.get('eval_every', 0) // 1000}k steps"
                   if run_cfg.get("eval_every") else "not evaluated along the way")
    greedy_curve = ("; dotted: the same with greedy actions, SB3's default" if any(len(c.alone_greedy) for c in summaries)
                    else "")
    final_how = (" with SB3's `evaluate_policy` from env seeds the run never trained on, greedy and sampled"
                 if any(c.final_greedy_seeds for c in summaries) else "")
    restricted = f" --seeds {','.join(map(str, only_seeds))}" if only_seeds else ""
    how = "two runs at a time, one torch thread each"
    overlapped = [c.cell for c in summaries if c.records[0]["config"].get("overlap")]
    if overlapped:
        how += (f" (the overlapped cells, {', '.join(overlapped)}: one run at a time, two torch threads for the on-policy "
                "update and one in each of its two threads while the replay updates overlap the rollouts)")
    body = (f"Commands: `dopt experiment run {name} --jobs 2 --seeds {','.join(map(str, seeds))}` then "
            f"`python benchmarks/experiment_docs.py {name}{restricted}` (grid: `sb3_disagree/data/experiments/{name}.yaml`). "
            f"{seeds_text}; {experiment.steps:,} env steps per run; {platform.machine()}, "
            f"{os.cpu_count()} cores, {how}{'; ' + note if note else ''}. ACER: "
            f"{yaml.safe_dump(acer, default_flow_style=True, width=200).strip()}. {continued}\n\n"
            f"![{experiment.name}](images/{figure.name})\n\n{table_markdown(experiment, summaries)}\n\n"
            "Solid lines: training success (the last 50 episodes over all envs, priors included where they were "
            "followed), mean over seeds with a 95% t-interval (none with fewer than 3 seeds); dashed: the new policy "
            f"alone (no priors, sampled actions, {alone_every}){greedy_curve}. Table: steps to 50%/90% and success at "
            "the budgets read from the mean training curve; AUC is the mean of that curve over the run; the new policy "
            f"alone (final) is evaluated over {experiment.final_episodes} episodes after training{final_how}, per seed "
            "in brackets.\n\n"
            f"Per seed, read from each seed's own training curve (the same 50-episode window):\n\n"
            f"{seeds_markdown(summaries)}\n")
    alone = alone_markdown(summaries)
    if alone is not None:
        body += ("\nThe new policy alone along the way (each run's periodic evaluation, "
                 f"{run_cfg.get('eval_episodes', 20)} episodes each way, mean over the seeds), greedy / sampled:\n\n"
                 f"{alone}\n")
    ratio = ratio_markdown(grid, summaries)
    if ratio is not None:
        body += ("\nSteps to 90% training success with disagreement options over those from scratch, per seed and "
                 f"from the mean curves (a curve that never gets there counts as the run's {experiment.steps:,} "
                 f"steps, which bounds the ratio):\n\n{ratio}\n")
    write_section(experiment.name, f"{experiment.name}: {experiment.goal}", body, page="results.md")
    print(body)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("name")
    parser.add_argument("--seeds", help="only these seeds: 0,1,2")
    parser.add_argument("--note", default="", help="what else ran on the machine meanwhile, said beside the machine")
    args = parser.parse_args()
    main(args.name, [int(s) for s in args.seeds.split(",")] if args.seeds else None, args.note)
