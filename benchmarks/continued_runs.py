"""
How far the new policy alone gets when finished fig3-bathtub runs are continued past 100k env steps.

A finished run of `dopt experiment run fig3-bathtub` is copied and continued with
`dopt train --goal bathtub --resume COPY --steps N` (once or in several legs; runs continued before resumed
runs appended to ``evaluations.npz`` kept each leg's as ``evaluations-<steps>.npz``). This script
reads the new policy alone's periodic evaluations of every leg, the original run's up to 100k, evaluates
each continued model alone over ``--episodes`` episodes (sampled and greedy actions), keeps the small
files under benchmarks/results/continued/, and writes a figure and a table into docs/results.md.

    python benchmarks/continued_runs.py RUN_DIR [RUN_DIR ...] [--episodes 100]
"""

import argparse
import json
import os
import platform
import shutil
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import yaml  # noqa: E402
from docs_section import DOCS, write_section  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
ORIGINAL = RESULTS / "experiments" / "fig3-bathtub" / "disagreement"
KEEP = ("config.yaml", "progress.csv", "monitor")
COLUMNS = (100_000, 140_000, 180_000, 220_000, 260_000, 300_000)


def evaluations(run_dir: Path, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Steps and success of every periodic evaluation of the new policy alone, the original run's first."""
    files = [ORIGINAL / f"seed-{seed}" / "evaluations.npz", *sorted(run_dir.glob("evaluations*.npz"))]
    steps, success = [], []
    for f in files:
        data = np.load(f)
        steps += data["timesteps"].tolist()
        success += data["successes"].mean(1).tolist()
    order = np.argsort(steps, kind="stable")
    steps, success = np.asarray(steps)[order], np.asarray(success)[order]
    keep = np.r_[steps[1:] != steps[:-1], True]  # a step evaluated in two files: the later file's
    return steps[keep], success[keep]


def success_alone(run_dir: Path, episodes: int, deterministic: bool) -> float:
    from sb3_disagree.acer import ACER
    from sb3_disagree.training import evaluate_alone

    config = yaml.safe_load((run_dir / "config.yaml").read_text())
    model = ACER.load(run_dir / "model.zip", device="cpu")
    return evaluate_alone(model, config, episodes, deterministic, seed=50_000).success_rate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", type=Path, nargs="+")
    parser.add_argument("--episodes", type=int, default=100)
    args = parser.parse_args()
    fig, ax = plt.subplots(figsize=(7, 4))
    rows = []
    for run_dir in args.runs:
        config = yaml.safe_load((run_dir / "config.yaml").read_text())
        seed, total = config["seed"], config["num_timesteps"]
        steps, success = evaluations(run_dir, seed)
        sampled = success_alone(run_dir, args.episodes, deterministic=False)
        greedy = success_alone(run_dir, args.episodes, deterministic=True)
        original = json.loads((ORIGINAL / f"seed-{seed}" / "result.json").read_text())["final_alone"]["success_rate"]
        ax.plot(steps, success, marker="o", label=f"seed {seed}")
        reached = steps[success >= 0.95]
        rows.append(f"| {seed} | {original:.2f} | " + " | ".join(
            f"{success[steps == s][0]:.2f}" if (steps == s).any() else "-" for s in COLUMNS)
            + f" | {f'{reached[0] // 1000}k' if len(reached) else 'never'} | {sampled:.2f} | {greedy:.2f} |")
        keep = RESULTS / "continued" / f"bathtub-disagreement-seed-{seed}"
        if keep.exists():
            shutil.rmtree(keep)
        keep.mkdir(parents=True)
        for name in (*KEEP, *(p.name for p in run_dir.glob("evaluations*.npz"))):
            src = run_dir / name
            (shutil.copytree if src.is_dir() else shutil.copy)(src, keep / name)
        (keep / "result.json").write_text(json.dumps({"seed": seed, "num_timesteps": total, "episodes": args.episodes,
                                                      "alone_sampled": sampled, "alone_greedy": greedy}, indent=2) + "\n")
        print(rows[-1], flush=True)
    ax.axhline(0.95, color="grey", lw=0.8, ls="--")
    ax.set(xlabel="env steps", ylabel="success of the new policy alone", ylim=(-0.02, 1.02),
           title="bathtub, disagreement options continued to 300k (20 episodes per point)")
    ax.legend()
    figure = DOCS / "images" / "bathtub-continued.png"
    fig.tight_layout()
    fig.savefig(figure, dpi=110)
    body = (
        "Commands: for a seed S, `cp -r benchmarks/results/experiments/fig3-bathtub/disagreement/seed-S RUN`, "
        "`dopt train --goal bathtub --resume RUN --steps 300000` (in one or more legs), then "
        f"`python benchmarks/continued_runs.py RUN ... --episodes {args.episodes}`. {platform.machine()}, "
        f"{os.cpu_count()} cores, one torch thread, beside other runs. The replay buffer is not kept at the end of a "
        "finished run, so each continuation starts with an empty one.\n\n"
        "![bathtub-continued](images/bathtub-continued.png)\n\n"
        "| seed | alone at 100k (50 ep.) | " + " | ".join(f"{c // 1000}k" for c in COLUMNS) + " | first >= 0.95 | "
        "alone at the end, sampled | alone at the end, greedy |\n|" + "---|" * (len(COLUMNS) + 5) + "\n" + "\n".join(rows) + "\n\n"
        "Columns 100k-300k: the periodic evaluation of the new policy alone (20 episodes, sampled actions, no "
        f"priors); the last two: {args.episodes} episodes from other starts (env seeds 50000+) after the run.\n")
    write_section("bathtub-continued", "The new policy alone in longer bathtub runs", body, page="results.md")
    print(body)


if __name__ == "__main__":
    main()
