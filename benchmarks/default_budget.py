"""
`dopt train`'s default run at another budget, or with another replay ratio: plain runs one at a time, each timed end
to end and its saved model evaluated alone both ways. Compact results go to benchmarks/results/default-budget/NAME/
(config.yaml, eval.txt, time.txt, the log's last lines).

    python benchmarks/default_budget.py run OUT [--seeds 0 1 2 3 4] [--goals bathtub nightstand] [--steps N]
        [--replay-ratio R] [--features-dtype bfloat16] [--average-ahead]
        # for each seed, each goal (skipping those done): /usr/bin/time -v dopt train --goal G --seed S --out OUT/G-S
        # [--steps N] [--features-dtype D] [--average-ahead], then dopt eval RUN --episodes 100 (100 episodes each way from the run's final-evaluation env
        # seeds). With --replay-ratio (not a dopt train option), the run is dopt train's default as a default run's
        # config.yaml resolves it (--like, the shipped make-run's), ACER's replay ratio replaced, through the library
    python benchmarks/default_budget.py table OUT/G-S [...]   # one row per run, then the means per task
    python benchmarks/default_budget.py curve NAME OUT/G-S [...]  # training success curves into NAME/curves.csv, and
        # where each goal's mean curve first reaches 90%
    python benchmarks/default_budget.py keep NAME OUT/G-S [...]   # copy the compact results into NAME/
    python benchmarks/default_budget.py plot NAME OUT.png          # NAME's kept curves, each goal's mean thick
"""

import argparse
import re
import shutil
import subprocess
import sys
import warnings
from pathlib import Path
from typing import Optional

import numpy as np
from validated_fit import saved_success

RESULTS = Path(__file__).parent / "results" / "default-budget"


LIKE = RESULTS.parent / "validated-fit" / "make-run" / "config.yaml"


def run(out: Path, seeds: list[int], goals: list[str], steps: Optional[int], replay_ratio: Optional[float],
        like: Path, features_dtype: Optional[str] = None, average_ahead: bool = False) -> None:
    dopt = Path(sys.executable).parent / "dopt"
    for seed in seeds:
        for goal in goals:
            folder = out / f"{goal}-{seed}"
            if (folder / "eval.txt").exists():
                continue
            folder.mkdir(parents=True, exist_ok=True)
            if replay_ratio is None:
                command = [str(dopt), "train", "--goal", goal, "--seed", str(seed), "--out", str(folder),
                           *(["--steps", str(steps)] if steps else []),
                           *(["--features-dtype", features_dtype] if features_dtype else []),
                           *(["--average-ahead"] if average_ahead else [])]
            else:
                command = [sys.executable, __file__, "variant", goal, str(seed), str(folder), str(like),
                           str(steps or 100_000), str(replay_ratio)]
            with open(folder / "train.log", "w") as log, open(folder / "time.txt", "w") as timing:
                subprocess.run(["/usr/bin/time", "-v", *command], stdout=log, stderr=timing, check=True)
            model_dir = next(folder.rglob("config.yaml")).parent  # (checkpoints hold model.zip files too)
            with open(folder / "eval.txt", "w") as evals:
                subprocess.run([str(dopt), "eval", str(model_dir), "--episodes", "100"], stdout=evals, check=True)


def variant(goal: str, seed: int, out: Path, like: Path, steps: int, replay_ratio: float) -> None:
    """One run of dopt train's default as ``like`` (a default run's config.yaml) resolved it, for ``goal`` and
    ``seed`` over ``steps``, with ACER's replay ratio replaced; its card evaluated as dopt train's (20 episodes each
    way) and a progress line like dopt train's last, for :func:`table`."""
    import time

    import yaml

    from sb3_disagree.run import RunConfig, train, write_card

    saved = yaml.safe_load(like.read_text())
    config = RunConfig.of_saved({**saved, "goal": goal, "seed": seed, "steps": steps, "priors": "auto",
                                 "acer_kwargs": {**saved["acer_kwargs"], "replay_ratio": replay_ratio}})
    start = time.perf_counter()
    run_dir, model, _ = train(config, out)
    trained = yaml.safe_load((run_dir / "config.yaml").read_text())
    seconds = time.perf_counter() - start - trained["consistency"]["seconds"]
    success = np.mean(model.ep_success_buffer)
    print(f"steps {model.num_timesteps:,}/{steps:,} | {model.num_timesteps / seconds:.0f} env steps/s | "
          f"success {success:.2f}")
    write_card(run_dir, model, 20)


def _row(folder: Path) -> dict:
    import yaml

    config = yaml.safe_load(next(folder.rglob("config.yaml")).read_text())
    (fit,) = config["consistency"]["per_round"]
    greedy, sampled = saved_success(folder)
    timing = (folder / "time.txt").read_text()
    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\d+):([\d.]+)", timing)
    rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", timing).group(1))
    log = folder / "train.log" if (folder / "train.log").exists() else folder / "train-tail.log"  # kept: the tail
    progress = [line for line in log.read_text().splitlines() if line.startswith("steps ")][-1]
    return dict(goal=config["goal"], seed=config["seed"], steps=config["num_timesteps"],
                wall=int(wall.group(1)) * 60 + float(wall.group(2)), gb=rss / 1e6,
                fps=int(re.search(r"\| (\d+) env steps/s", progress).group(1)),
                training=float(re.search(r"success ([\d.]+)", progress).group(1)),
                fit=config["consistency"]["seconds"], validation=fit["validation"], epoch=int(fit["epoch"]),
                greedy=greedy, sampled=sampled)


def table(folders: list[Path]) -> None:
    rows = [_row(folder) for folder in folders if folder.is_dir()]  # (a kept curves.csv beside the runs)
    print("| run | env steps | wall time, `dopt train` end to end | env steps/s | training success, last episodes | "
          "fit + validation | validation after each epoch | kept | saved model alone, greedy / sampled |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['goal']} {r['seed']} | {r['steps']:,} | {int(r['wall'] // 60)} min {r['wall'] % 60:02.0f} s | "
              f"{r['fps']} | {r['training']:.2f} | {r['fit']:.0f} s | {' '.join(f'{v:.2f}' for v in r['validation'])} | "
              f"{r['epoch']} | {r['greedy']:.2f} / {r['sampled']:.2f} |")
    for goal in dict.fromkeys(r["goal"] for r in rows):
        mine = [r for r in rows if r["goal"] == goal]
        wall = np.array([r["wall"] for r in mine])
        print(f"\n{goal}, {len(mine)} runs: greedy mean {np.mean([r['greedy'] for r in mine]):.3f} "
              f"(min {min(r['greedy'] for r in mine):.2f}), sampled mean {np.mean([r['sampled'] for r in mine]):.3f} "
              f"(min {min(r['sampled'] for r in mine):.2f}); wall time {wall.mean() / 60:.2f} min mean, "
              f"{wall.max() / 60:.2f} max; peak memory {max(r['gb'] for r in mine):.1f} GB")


def curve(name: str, folders: list[Path], steps: int = 100_000, points: int = 50) -> None:
    """Each run's training success on a grid of env steps (the last 50 episodes, as `dopt experiment report`'s curves),
    written to ``RESULTS/NAME/curves.csv``; prints the env steps at which each goal's mean curve first reaches 90%."""
    import pandas as pd

    from sb3_disagree.experiments.curves import steps_to, success_curve

    grid = np.linspace(steps / points, steps, points)
    curves = {}
    for folder in folders:
        run_dir = next(folder.rglob("config.yaml")).parent
        curves[folder.name] = success_curve(run_dir, grid)
    (RESULTS / name).mkdir(parents=True, exist_ok=True)
    pd.DataFrame({"env_steps": grid, **curves}).to_csv(RESULTS / name / "curves.csv", index=False, float_format="%.4f")
    for goal in dict.fromkeys(key.rsplit("-", 1)[0] for key in curves):
        mine = [c for key, c in curves.items() if key.rsplit("-", 1)[0] == goal]
        with warnings.catch_warnings():  # grid steps before any run has 10 episodes: no mean
            warnings.simplefilter("ignore", RuntimeWarning)
            reached = steps_to(np.nanmean(mine, axis=0), grid, 0.9)
        print(f"{goal}, {len(mine)} runs: the mean curve first at 90% training success at "
              f"{'never' if reached is None else f'{reached / 1000:.0f}k'} env steps")


def plot(name: str, out: Path) -> None:
    """The kept training curves of ``RESULTS/NAME/curves.csv``: each run thin, each goal's mean thick, one colour a goal,
    and each run's saved policy alone (its ``eval.txt``) in the legend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pandas as pd

    data = pd.read_csv(RESULTS / name / "curves.csv")
    fig, ax = plt.subplots(figsize=(7, 4), dpi=110)
    for goal, color in zip(dict.fromkeys(c.rsplit("-", 1)[0] for c in data.columns[1:]), ("#1f4fd6", "#d62728")):
        runs = [c for c in data.columns[1:] if c.rsplit("-", 1)[0] == goal]
        alone = [_row(RESULTS / name / run) for run in runs]
        for run in runs:
            ax.plot(data.env_steps, data[run], color=color, lw=0.7, alpha=0.4)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            mean = np.nanmean(data[runs].to_numpy(), axis=1)
        ax.plot(data.env_steps, mean, color=color, lw=2.2,
                label=f"{goal}: mean of {len(runs)}; alone {np.mean([r['greedy'] for r in alone]):.2f} greedy, "
                      f"{np.mean([r['sampled'] for r in alone]):.2f} sampled")
    ax.axhline(0.9, color="grey", ls=":", lw=1)
    ax.set(xlabel="env steps", ylabel="training success (last 50 episodes)", ylim=(0, 1.02),
           title=f"dopt train's default ({name}), five runs a task")
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(out)
    print(f"wrote {out}")


def keep(name: str, folders: list[Path]) -> None:
    for folder in folders:
        dest = RESULTS / name / folder.name
        dest.mkdir(parents=True, exist_ok=True)
        shutil.copy(next(folder.rglob("config.yaml")), dest / "config.yaml")
        for file in ("eval.txt", "time.txt"):
            shutil.copy(folder / file, dest / file)
        log = (folder / "train.log").read_text().splitlines()
        (dest / "train-tail.log").write_text("\n".join(log[-12:]) + "\n")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("run")
    p.add_argument("out", type=Path)
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    p.add_argument("--goals", nargs="+", default=["bathtub", "nightstand"])
    p.add_argument("--steps", type=int)
    p.add_argument("--replay-ratio", type=float)
    p.add_argument("--features-dtype", help="passed to dopt train")
    p.add_argument("--average-ahead", action="store_true", help="passed to dopt train")
    p.add_argument("--like", type=Path, default=LIKE)
    p = sub.add_parser("variant")
    for name, kind in (("goal", str), ("seed", int), ("out", Path), ("like", Path), ("steps", int),
                       ("replay_ratio", float)):
        p.add_argument(name, type=kind)
    sub.add_parser("table").add_argument("folders", type=Path, nargs="+")
    p = sub.add_parser("curve")
    p.add_argument("name")
    p.add_argument("folders", type=Path, nargs="+")
    p = sub.add_parser("keep")
    p.add_argument("name")
    p.add_argument("folders", type=Path, nargs="+")
    p = sub.add_parser("plot")
    p.add_argument("name")
    p.add_argument("out", type=Path)
    args = parser.parse_args()
    if args.command == "run":
        run(args.out, args.seeds, args.goals, args.steps, args.replay_ratio, args.like, args.features_dtype,
            args.average_ahead)
    elif args.command == "variant":
        variant(args.goal, args.seed, args.out, args.like, args.steps, args.replay_ratio)
    elif args.command == "table":
        table(args.folders)
    elif args.command == "curve":
        curve(args.name, args.folders)
    elif args.command == "plot":
        plot(args.name, args.out)
    else:
        keep(args.name, args.folders)
