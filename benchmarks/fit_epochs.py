"""
How many epochs the harvest's fit needs, paired: from each run's trained policy (its last checkpoint, before the
fit), collect one set of loop-free labels acting as a frozen harvest would (every action sampled from the weights
the model acts with, ``collect_escapes(sampling="always")``, on the run's own consistency env seeds), then fit the
same start weights to the same labels for each number of epochs and evaluate each result alone with SB3's
``evaluate_policy``, greedy and sampled, from one env seed the runs never trained on.

    python benchmarks/fit_epochs.py RUN [RUN ...] [--steps 30000] [--epochs 3,6] [--episodes 100] [--seed 777] \
        [--out rows.jsonl]
"""

import argparse
import copy
import json
import time
from pathlib import Path

import numpy as np
import torch as th
import yaml
from stable_baselines3.common.env_util import make_vec_env

from sb3_disagree import ACER
from sb3_disagree.acer.consistency import collect_escapes, fit_labels
from sb3_disagree.evaluation import evaluate  # SB3's evaluate_policy, success counted from is_success
from sb3_disagree.run.consistency import consistency_env


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--steps", type=int, default=30_000, help="env steps of the collection (the harvest's)")
    parser.add_argument("--epochs", default="3,6", help="the fits to compare, comma-separated")
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=777, help="env seed of the evaluations")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--out", type=Path, default=None, help="append one JSON line per fit")
    args = parser.parse_args()
    th.set_num_threads(args.threads)
    for run in args.runs:
        config = yaml.safe_load((run / "config.yaml").read_text())
        (checkpoint,) = sorted((run / "checkpoints").iterdir())[-1:]
        model = ACER.load(checkpoint / "model.zip", device="cpu")
        env = consistency_env(config)
        start = time.perf_counter()
        labels, counts = collect_escapes(model, env, args.steps, np.random.default_rng(config["seed"]), "always")
        env.close()
        collected = time.perf_counter() - start
        if not labels.actions:  # no episode reached the goal: nothing to fit
            print(json.dumps({"run": str(run), "goal": config["goal"], "labels": 0, **counts}), flush=True)
            continue
        inputs, actions = np.stack(labels.inputs), np.asarray(labels.actions, dtype=np.int64)
        trained = copy.deepcopy(model.policy.acting_net.state_dict())
        for epochs in [int(e) for e in args.epochs.split(",")]:
            model.policy.acting_net.load_state_dict(trained)
            start = time.perf_counter()
            loss, accuracy = fit_labels(model.policy, inputs, actions, epochs, 3e-4, 128,
                                        np.random.default_rng(config["seed"]))
            row = {"run": str(run), "goal": config["goal"], "epochs": epochs, "labels": len(actions), **counts,
                   "collect_seconds": round(collected, 1), "fit_seconds": round(time.perf_counter() - start, 1),
                   "loss": round(loss, 4), "accuracy": round(accuracy, 4)}
            for deterministic in (True, False):
                eval_env = make_vec_env("sb3_disagree/Apartment-v0", n_envs=4, seed=args.seed,
                                        env_kwargs=dict(goal=config["goal"]))
                result = evaluate(model, eval_env, args.episodes, deterministic)
                eval_env.close()
                row["greedy" if deterministic else "sampled"] = result.success_rate
            print(json.dumps(row), flush=True)
            if args.out is not None:
                with open(args.out, "a") as f:
                    f.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
