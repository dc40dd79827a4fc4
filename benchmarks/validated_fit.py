"""
The validated fit (docs/method.md, "Greedy consistency after training", item 6), measured on `dopt train`'s default
runs, paired with the unvalidated fit of the same labels.

    python benchmarks/validated_fit.py train GOAL SEED OUT   # dopt train --goal GOAL --seed SEED --out OUT, exactly,
                                                            # with the harvest's labels saved to OUT/harvest.npz
    python benchmarks/validated_fit.py refit OUT [--epochs 3]  # the same labels fitted to the run's trained policy
        # (its last checkpoint) epoch by epoch without validation, each epoch evaluated greedy from the run's
        # final-evaluation env seeds (100 episodes; the fit of the last epoch is the unvalidated default's model.zip)
    python benchmarks/validated_fit.py table OUT [OUT ...]    # one row per run: the validation, the kept epoch, the
        # saved model (dopt eval's two lines, read from OUT/eval.txt) and the unvalidated fit (OUT/refit.jsonl)

`train` imports every module the run needs before it starts, so that edits to the code while it runs do not reach it.
"""

import argparse
import importlib
import json
import sys
from pathlib import Path

import numpy as np


def train(goal: str, seed: int, out: Path) -> None:
    for name in ("sb3_disagree.run.consistency", "sb3_disagree.model_card", "sb3_disagree.run.progress",
                 "sb3_disagree.run.evaluation", "sb3_disagree.evaluation", "sb3_disagree.finish.consistency",
                 "sb3_disagree.cli.app", "sb3_disagree.cli.train", "stable_baselines3.common.evaluation"):
        importlib.import_module(name)
    module = importlib.import_module("sb3_disagree.run.train")
    fit = module.greedy_consistency

    def saving(model, env, rounds, steps, epochs, harvest=None, **kwargs):
        np.savez(out / "harvest.npz", inputs=np.stack(harvest.trails.labels.inputs),
                 actions=np.asarray(harvest.trails.labels.actions))
        return fit(model, env, rounds, steps, epochs, harvest=harvest, **kwargs)

    module.greedy_consistency = saving
    from sb3_disagree.cli.app import app

    app(["train", "--goal", goal, "--seed", str(seed), "--out", str(out)])


def refit(out: Path, epochs: int) -> None:
    import copy

    import torch as th
    import yaml

    from sb3_disagree import ACER
    from sb3_disagree.finish.consistency import fit_labels
    from sb3_disagree.defaults import FINAL_EVAL_SEED_OFFSET
    from sb3_disagree.run.evaluation import evaluate_alone

    th.set_num_threads(1)
    run_dir = next(out.rglob("config.yaml")).parent
    config = yaml.safe_load((run_dir / "config.yaml").read_text())
    model = ACER.load(sorted((run_dir / "checkpoints").iterdir())[-1] / "model.zip", device="cpu")
    with np.load(out / "harvest.npz") as harvest:
        inputs, actions = harvest["inputs"], harvest["actions"].astype(np.int64)
    start = copy.deepcopy(model.policy.acting_net.state_dict())
    seed = config["seed"] + FINAL_EVAL_SEED_OFFSET
    rows = [{"epoch": 0, "greedy": evaluate_alone(model, config, 100, True, seed).success_rate}]
    for n in range(1, epochs + 1):  # each from the trained weights: the fit of n epochs, as dopt train's
        model.policy.acting_net.load_state_dict(start)
        loss, accuracy = fit_labels(model.policy, inputs, actions, n, 3e-4, 128, np.random.default_rng(config["seed"]))
        rows.append({"epoch": n, "loss": round(loss, 4), "accuracy": round(accuracy, 4),
                     "greedy": evaluate_alone(model, config, 100, True, seed).success_rate})
    with open(out / "refit.jsonl", "w") as f:
        f.writelines(json.dumps(row) + "\n" for row in rows)
    print(*rows, sep="\n")


def saved_success(out: Path) -> tuple[float, float]:
    """The saved model's greedy and sampled success, read from ``dopt eval``'s two lines in ``out/eval.txt``."""
    lines = [line for line in (out / "eval.txt").read_text().splitlines() if "success" in line]
    greedy, sampled = (float(line.split("success ")[1].split(",")[0]) for line in lines[:2])
    return greedy, sampled


def table(outs: list[Path]) -> None:
    import yaml

    print("| run | validation after each epoch (40 episodes) | kept | saved model, greedy / sampled | refit greedy: "
          "the kept epoch / the last (unvalidated) / the trained policy |")
    print("|---|---|---|---|---|")
    for out in outs:
        config = yaml.safe_load(next(out.rglob("config.yaml")).read_text())
        (fit,) = config["consistency"]["per_round"]
        greedy, sampled = saved_success(out)
        refits = {row["epoch"]: row["greedy"] for row in map(json.loads, (out / "refit.jsonl").read_text().splitlines())}
        print(f"| {config['goal']} {config['seed']} | {' '.join(f'{v:.2f}' for v in fit['validation'])} | "
              f"{int(fit['epoch'])} | {greedy:.2f} / {sampled:.2f} | {refits[int(fit['epoch'])]:.2f} / "
              f"{refits[max(refits)]:.2f} / {refits[0]:.2f} |")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("train")
    p.add_argument("goal")
    p.add_argument("seed", type=int)
    p.add_argument("out", type=Path)
    p = sub.add_parser("refit")
    p.add_argument("out", type=Path)
    p.add_argument("--epochs", type=int, default=3)
    p = sub.add_parser("table")
    p.add_argument("outs", type=Path, nargs="+")
    args = parser.parse_args()
    if args.command == "train":
        args.out.mkdir(parents=True, exist_ok=True)
        train(args.goal, args.seed, args.out)
    elif args.command == "refit":
        refit(args.out, args.epochs)
    else:
        table(args.outs)
    sys.exit(0)
