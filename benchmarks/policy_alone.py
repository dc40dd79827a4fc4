"""
The new policy alone (no priors) in an experiment's finished runs, seed by seed: its periodic evaluations
along the run, and after the run over ``--episodes`` episodes from other starts (env seeds 50000+) with
sampled and with greedy actions. Writes a figure and a table into docs/results.md.

    python benchmarks/policy_alone.py fig3-bathtub-300k [--cell disagreement] [--episodes 100]

The end-of-run evaluations need the runs' models (not tracked); each is kept in the experiment's tracked
``alone-CELL.json`` when measured, and read from there where the model is gone, so the figure and table
regenerate from a clone.
"""

import argparse
import json
import os
import platform
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import yaml  # noqa: E402
from docs_section import DOCS, write_section  # noqa: E402

from sb3_disagree.experiments.spec import load_experiment  # noqa: E402

ROOT = Path(__file__).resolve().parent / "results" / "experiments"
SEED = 50_000  # starts no training or evaluation of the runs used


def success_alone(run_dir: Path, episodes: int) -> tuple[float, float]:
    """Success of the run's model alone with sampled and with greedy actions."""
    from sb3_disagree.acer import ACER
    from sb3_disagree.run import evaluate_alone

    config = yaml.safe_load((run_dir / "config.yaml").read_text())
    model = ACER.load(run_dir / "model.zip", device="cpu")
    return tuple(evaluate_alone(model, config, episodes, greedy, seed=SEED).success_rate for greedy in (False, True))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("experiment")
    parser.add_argument("--cell", default="disagreement")
    parser.add_argument("--episodes", type=int, default=100)
    args = parser.parse_args()
    experiment = load_experiment(args.experiment)
    runs = [r for r in experiment.runs() if r.cell == args.cell and r.finished(ROOT / experiment.name)]
    if not runs:
        raise SystemExit(f"no finished {args.cell} runs of {experiment.name}; run: dopt experiment run {experiment.name}")
    kept_path = ROOT / experiment.name / f"alone-{args.cell}.json"
    kept = json.loads(kept_path.read_text()) if kept_path.exists() else {}
    columns = np.linspace(experiment.steps / 5, experiment.steps, 5).astype(int)
    fig, ax = plt.subplots(figsize=(7, 4))
    rows = []
    for run in runs:
        folder = run.folder(ROOT / experiment.name)
        evals = np.load(folder / "evaluations.npz")
        steps, success = evals["timesteps"], evals["successes"].mean(axis=1)
        if (folder / "model.zip").exists():
            sampled, greedy = success_alone(folder, args.episodes)
            kept[str(run.seed)] = {"sampled": sampled, "greedy": greedy, "episodes": args.episodes, "env_seed": SEED}
        elif str(run.seed) in kept and kept[str(run.seed)]["episodes"] == args.episodes:
            sampled, greedy = kept[str(run.seed)]["sampled"], kept[str(run.seed)]["greedy"]
        else:
            raise SystemExit(f"{folder} has no model.zip and {kept_path} no {args.episodes}-episode evaluation of it")
        ax.plot(steps, success, marker="o", ms=3, label=f"seed {run.seed}")
        reached = steps[success >= 0.95]
        rows.append(f"| {run.seed} | " + " | ".join(
            f"{success[steps == c][0]:.2f}" if (steps == c).any() else "-" for c in columns)
            + f" | {f'{reached[0] // 1000}k' if len(reached) else 'never'} | {sampled:.2f} | {greedy:.2f} |")
        print(rows[-1], flush=True)
    kept_path.write_text(json.dumps(kept, indent=2) + "\n")
    ax.axhline(0.95, color="grey", lw=0.8, ls="--")
    ax.set(xlabel="env steps", ylabel="success of the new policy alone", ylim=(-0.02, 1.02),
           title=f"{experiment.name}, {args.cell}: the new policy alone (20 episodes per point)")
    ax.legend()
    figure = DOCS / "images" / f"{experiment.name}-alone.png"
    fig.tight_layout()
    fig.savefig(figure, dpi=110)
    body = (
        f"Command: `python benchmarks/policy_alone.py {experiment.name} --cell {args.cell} --episodes {args.episodes}` "
        f"(after `dopt experiment run {experiment.name}`). {platform.machine()}, {os.cpu_count()} cores.\n\n"
        f"![{experiment.name}-alone](images/{figure.name})\n\n"
        "| seed | " + " | ".join(f"{c // 1000}k" for c in columns) + " | first >= 0.95 | "
        "at the end, sampled | at the end, greedy |\n|" + "---|" * (len(columns) + 4) + "\n" + "\n".join(rows) + "\n\n"
        f"Columns {columns[0] // 1000}k-{columns[-1] // 1000}k: the run's periodic evaluation of the new policy alone "
        f"(20 episodes, sampled actions, no priors); the last two: {args.episodes} episodes from other starts (env "
        f"seeds {SEED}+) after the run, sampled and greedy actions.\n")
    write_section(f"{experiment.name}-alone", f"{experiment.name}: the new policy alone", body, page="results.md")
    print(body)


if __name__ == "__main__":
    main()
