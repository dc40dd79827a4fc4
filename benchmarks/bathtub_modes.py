"""
First measurement of the method: bathtub with priors shower and toilet, disagreement options against
the room sensor and learning from scratch, several seeds; training success rate and the share of steps
that followed the priors against env steps, written to docs/images/ and docs/results.md.

    python benchmarks/bathtub_modes.py run --seeds 0 1 2 --steps 50000 --jobs 2
    python benchmarks/bathtub_modes.py report --steps 50000

Runs go to benchmarks/results/bathtub_modes/ (one run folder per mode and seed; finished ones are
skipped). Each run is single-threaded in torch.
"""

import argparse
import os
import platform
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import yaml
from docs_section import DOCS, write_section

ROOT = Path(__file__).resolve().parent / "results" / "bathtub_modes"
MODES = ["disagreement", "room-sensor", "scratch"]
COLORS = {"disagreement": "#1a9e2f", "room-sensor": "#ff7f0e", "scratch": "#1f4fd6"}


def _run(args: tuple) -> str:
    mode, seed, steps = args
    import torch as th

    th.set_num_threads(1)
    from sb3_disagree.run import RunConfig, train

    config = RunConfig(goal="bathtub", mode=mode, priors=["shower", "toilet"], seed=seed, steps=steps)
    run_dir, model, _ = train(config, ROOT)
    return f"{mode} seed {seed}: {model.num_timesteps} steps -> {run_dir}"


def _finished(mode: str, seed: int, steps: int) -> bool:
    cfg = ROOT / "sb3_disagree__Apartment-v0" / "bathtub" / f"{mode}-{seed}" / "config.yaml"
    return cfg.exists() and bool(yaml.safe_load(cfg.read_text()).get("finished")) and \
        yaml.safe_load(cfg.read_text()).get("steps") == steps


def cmd_run(args: argparse.Namespace) -> None:
    cells = [(m, s, args.steps) for s in args.seeds for m in args.modes if not _finished(m, s, args.steps)]
    with ProcessPoolExecutor(args.jobs) as pool:
        for line in pool.map(_run, cells):
            print(line, flush=True)


def cmd_report(args: argparse.Namespace) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sb3_disagree.experiments.curves import first_defined, mean_and_band, progress_curve, steps_to, success_curve

    grid = np.linspace(args.steps / 50, args.steps, 50)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    rows, seeds_seen, speeds = [], set(), {}
    for mode in MODES:
        runs = sorted((ROOT / "sb3_disagree__Apartment-v0" / "bathtub").glob(f"{mode}-*"))
        runs = [r for r in runs if (r / "config.yaml").exists() and yaml.safe_load((r / "config.yaml").read_text()).get("finished")]
        if not runs:
            continue
        seeds_seen |= {r.name.split("-")[-1] for r in runs}
        curves = [success_curve(r, grid) for r in runs]
        mean, lo, hi = mean_and_band(curves)
        ax1.plot(grid, mean, color=COLORS[mode], label=f"{mode} ({len(runs)} seeds)")
        ax1.fill_between(grid, np.clip(lo, 0, 1), np.clip(hi, 0, 1), color=COLORS[mode], alpha=0.2)
        if mode != "scratch":
            usage = mean_and_band([progress_curve(r, "prior/usage", grid, smooth=5) for r in runs])
            ax2.plot(grid, usage[0], color=COLORS[mode], label=mode)
            ax2.fill_between(grid, np.clip(usage[1], 0, 1), np.clip(usage[2], 0, 1), color=COLORS[mode], alpha=0.2)
        fps = [float(__import__("pandas").read_csv(r / "progress.csv")["time/fps"].dropna().iloc[-1]) for r in runs]
        speeds[mode] = np.mean(fps)
        s50, s90 = steps_to(mean, grid, 0.5), steps_to(mean, grid, 0.9)
        rows.append(f"| {mode} | {len(runs)} | {first_defined(mean):.2f} | {np.nanmean(mean[-5:]):.2f} | "
                    f"{f'{s50 / 1000:.0f}k' if s50 else 'not reached'} | {f'{s90 / 1000:.0f}k' if s90 else 'not reached'} | "
                    f"{speeds[mode]:.0f} |")
    ax1.set(xlabel="env steps", ylabel="training success rate (last 50 episodes)", ylim=(-0.02, 1.02),
            title="bathtub, priors shower + toilet")
    ax2.set(xlabel="env steps", ylabel="share of steps following the priors", ylim=(-0.02, 1.02),
            title="prior usage (moving average of 5 logged rollouts)")
    ax1.legend(loc="lower right")
    ax2.legend(loc="upper right")
    fig.tight_layout()
    out = DOCS / "images" / "bathtub_modes.png"
    fig.savefig(out, dpi=110)
    overhead = ""
    if "scratch" in speeds and "disagreement" in speeds:
        overhead = (f" The hook's overhead in the same runs: disagreement options train at {speeds['disagreement']:.0f} env "
                    f"steps/s against {speeds['scratch']:.0f} from scratch "
                    f"({100 * (1 - speeds['disagreement'] / speeds['scratch']):.0f}% slower: two prior forward passes "
                    "per step).")
    body = f"""Command: `python benchmarks/bathtub_modes.py run --seeds {' '.join(sorted(seeds_seen))} --steps {args.steps} --jobs 2 &&
python benchmarks/bathtub_modes.py report --steps {args.steps}`. Machine: {platform.machine()}, {os.cpu_count()} cores, two runs
at a time, one torch thread each. Apartment RGB 60x80, 4 envs, ACER CnnPolicy with the defaults of
`sb3_disagree.run.ACER_KWARGS`, alpha 10, beta 0.1; priors from the shipped zoo.

![bathtub modes](images/bathtub_modes.png)

| mode | seeds | success at start | success at end (last 10%) | steps to 50% | steps to 90% | env steps/s |
|---|---|---|---|---|---|---|
{chr(10).join(rows)}

Success is the training success rate over the last 50 episodes (all envs; defined from the 10th
episode on), the behaviour included (priors where they were followed); the band is a 95% t-interval of
the mean over seeds.{overhead}
"""
    write_section("bathtub-modes", "Bathtub: disagreement options, room sensor and scratch", body, page="results.md")
    print(body)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="cmd", required=True)
    run = sub.add_parser("run")
    run.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    run.add_argument("--modes", nargs="+", default=MODES, choices=MODES)
    run.add_argument("--jobs", type=int, default=os.cpu_count())
    for p in (run, sub.add_parser("report")):
        p.add_argument("--steps", type=int, default=50_000)
    args = parser.parse_args()
    {"run": cmd_run, "report": cmd_report}[args.cmd](args)


if __name__ == "__main__":
    main()
