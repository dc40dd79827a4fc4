"""
Try settings of the method on one goal: each variant is a run of ``sb3_disagree.run.train`` with
some RunConfig fields or ACER hyperparameters overridden, evaluated alone (no priors) along the way.

    python benchmarks/tune_method.py --name ent05 --steps 60000 --set acer.ent_coef=0.05 --set beta=0.1
    python benchmarks/tune_method.py --report NAME [NAME ...]   # figure and table into docs/results.md

Runs go to benchmarks/results/tune_method/<name>/...; the last line printed is the summary
(training success over the last 10% of steps, prior usage, evaluations of the policy alone).
"""

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import torch as th
import yaml

ROOT = Path(__file__).resolve().parent / "results" / "tune_method"


def parse_sets(items: list[str]) -> tuple[dict, dict]:
    fields, acer = {}, {}
    for item in items:
        key, value = item.split("=", 1)
        value = yaml.safe_load(value)
        if key.startswith("acer."):
            acer[key[5:]] = value
        else:
            fields[key] = value
    return fields, acer


def _run_dir(name: str) -> Path:
    return next((ROOT / name).glob("*/*/*-*"))


def report(names: list[str]) -> None:
    """Entropy, training success and the policy alone against steps for the named variants."""
    import os
    import platform

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from docs_section import DOCS, write_section

    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    rows = []
    for i, name in enumerate(names):
        run = _run_dir(name)
        cfg = yaml.safe_load((run / "config.yaml").read_text())
        p = pd.read_csv(run / "progress.csv")
        steps = p["time/total_timesteps"]
        color = plt.get_cmap("tab10")(i)
        axes[0].plot(steps, p["prior/entropy"].rolling(5, min_periods=1).mean(), color=color, label=name)
        axes[1].plot(steps, p["rollout/success_rate"], color=color, label=name)
        evals = np.load(run / "evaluations.npz")
        alone = evals["successes"].mean(axis=1)
        axes[2].plot(evals["timesteps"], alone, "-o", color=color, label=name)
        changed = {k: v for k, v in cfg["acer_kwargs"].items() if k in ("ent_coef", "learning_rate", "q_loss", "reward_scale")}
        peak = int(np.argmax(alone))
        rows.append(f"| {name} | {', '.join(f'{k} {v}' for k, v in changed.items())} | {cfg['steps'] // 1000}k | "
                    f"{p['prior/entropy'].tail(10).mean():.2f} | {p['rollout/success_rate'].dropna().tail(10).mean():.2f} | "
                    f"{alone[peak]:.2f} at {evals['timesteps'][peak] // 1000}k | {alone[-1]:.2f} |")
    axes[0].set(xlabel="env steps", ylabel="mean entropy of the new policy (nats)", title="entropy (5-rollout mean)")
    axes[1].set(xlabel="env steps", ylabel="training success (last 100 episodes)", ylim=(-0.02, 1.02),
                title="training success, priors included")
    axes[2].set(xlabel="env steps", ylabel="success of the new policy alone", ylim=(-0.02, 1.02),
                title="the new policy alone (20 episodes, sampled)")
    axes[2].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(DOCS / "images" / "tune_method.png", dpi=100)
    body = (f"Command: `python benchmarks/tune_method.py --name NAME --steps S --eval-every E --set KEY=VALUE ...` per "
            f"variant (settings in the table), then `python benchmarks/tune_method.py --report {' '.join(names)}`. "
            f"Bathtub, priors shower and toilet, disagreement options (alpha 10, beta 0.1), seed 0, one torch thread "
            f"per run, two to four runs sharing {os.cpu_count()} cores ({platform.machine()}).\n\n"
            "![tuning](images/tune_method.png)\n\n"
            "| variant | ACER settings | steps | entropy at end | training success at end | the new policy alone, best | at end |\n"
            "|---|---|---|---|---|---|---|\n" + "\n".join(rows) + "\n")
    write_section("tune-method", "Choosing ACER's scale for the apartment", body, page="results.md")
    print(body)


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--report":
        report(sys.argv[2:])
        return
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--name", required=True)
    parser.add_argument("--goal", default="bathtub")
    parser.add_argument("--priors", default="shower,toilet")
    parser.add_argument("--mode", default="disagreement")
    parser.add_argument("--steps", type=int, default=60_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--eval-every", type=int, default=15_000)
    parser.add_argument("--set", action="append", default=[], help="FIELD=VALUE or acer.KEY=VALUE")
    args = parser.parse_args()
    th.set_num_threads(1)
    from sb3_disagree.run import ACER_KWARGS, RunConfig, train

    fields, acer = parse_sets(args.set)
    config = RunConfig(goal=args.goal, mode=args.mode, priors=args.priors.split(","), seed=args.seed, steps=args.steps,
                       eval_every=args.eval_every, acer_kwargs={**ACER_KWARGS, **acer}, **fields)
    run_dir, model, _ = train(config, ROOT / args.name)
    progress = pd.read_csv(run_dir / "progress.csv")
    tail = progress[progress["time/total_timesteps"] >= 0.9 * args.steps]
    evals = np.load(run_dir / "evaluations.npz")
    alone = ", ".join(f"{t // 1000}k {np.mean(s):.2f}" for t, s in zip(evals["timesteps"], evals["successes"]))
    usage = tail["prior/usage"].mean() if "prior/usage" in tail else float("nan")
    print(f"{args.name}: train success {tail['rollout/success_rate'].mean():.2f}, usage {usage:.2f}, "
          f"entropy {tail['prior/entropy'].mean() if 'prior/entropy' in tail else float('nan'):.2f}; alone: {alone}")


if __name__ == "__main__":
    main()
