"""
ACER against SB3's A2C, PPO and DQN on CartPole-v1 and Acrobot-v1, same step budgets and seeds.

    python benchmarks/classic_control.py run --seeds 0 1 2 3 4 --jobs 2
    python benchmarks/classic_control.py report          # writes docs/benchmarks.md's classic-control part
    python benchmarks/classic_control.py throughput      # ACER's cost per env step against A2C and PPO

Hyperparameters come from sb3_disagree/hyperparams/<algo>.yml (rl-zoo3's format); every algorithm runs
for the same budget per env (BUDGETS) whatever its file says. Each run evaluates the deterministic
policy every `--eval-freq` steps over 20 episodes and writes one JSON file under benchmarks/results/.
"""

import argparse
import json
import os
import platform
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any, Optional

import numpy as np
import yaml
from docs_section import write_section

from sb3_disagree.rl_zoo import HYPERPARAMS
from sb3_disagree.loggers import silent_logger

ROOT = Path(__file__).resolve().parent
RESULTS = ROOT / "results" / "classic"
ALGOS = ["acer", "a2c", "ppo", "dqn"]
ENVS = {"CartPole-v1": 475.0, "Acrobot-v1": -100.0}  # env id -> return threshold ("solved")
BUDGETS = {"CartPole-v1": 100_000, "Acrobot-v1": 100_000}


def load_hyperparams(algo: str, env_id: str) -> dict[str, Any]:
    """Read rl-zoo3-style hyperparameters and turn them into constructor kwargs."""
    from stable_baselines3.common.utils import LinearSchedule

    with open(HYPERPARAMS / f"{algo}.yml") as f:
        params = dict(yaml.safe_load(f)[env_id])
    kwargs: dict[str, Any] = {}
    for key, value in params.items():
        if isinstance(value, str) and value.startswith("lin_"):
            value = LinearSchedule(float(value[4:]), 0.0, 1.0)
        elif key == "policy_kwargs" and isinstance(value, str):
            value = eval(value, {"dict": dict})  # rl-zoo3 stores policy_kwargs as a Python expression
        kwargs[key] = value
    return kwargs


def algo_class(algo: str):
    if algo == "acer":
        from sb3_disagree import ACER

        return ACER
    import stable_baselines3

    return getattr(stable_baselines3, algo.upper())


def run_one(algo: str, env_id: str, seed: int, budget: int, eval_freq: int, overrides: Optional[dict] = None,
            out: Optional[Path] = None) -> dict[str, Any]:
    """Train one model with periodic deterministic evaluation; return (and write) the record."""
    import torch as th
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.evaluation import evaluate_policy

    th.set_num_threads(1)
    kwargs = load_hyperparams(algo, env_id)
    kwargs.update(overrides or {})
    kwargs.pop("n_timesteps", None)
    n_envs = kwargs.pop("n_envs", 1)
    policy = kwargs.pop("policy")
    env = make_vec_env(env_id, n_envs=n_envs, seed=seed)
    eval_env = make_vec_env(env_id, n_envs=1, seed=seed + 10_000)
    model = algo_class(algo)(policy, env, seed=seed, verbose=0, **kwargs)
    model.set_logger(silent_logger())  # SB3's default logger leaves a folder in the temp dir

    class Evaluate(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.next_eval, self.curve, self.eval_time = eval_freq, [], 0.0

        def _on_step(self) -> bool:
            if self.num_timesteps >= self.next_eval:
                start = time.perf_counter()
                mean, std = evaluate_policy(self.model, eval_env, n_eval_episodes=20, deterministic=True)
                self.curve.append((self.num_timesteps, float(mean), float(std)))
                self.next_eval += eval_freq
                self.eval_time += time.perf_counter() - start
            return True

    callback = Evaluate()
    start = time.perf_counter()
    model.learn(budget, callback=callback)
    train_time = time.perf_counter() - start - callback.eval_time
    threshold = ENVS[env_id]
    solved = [step for step, mean, _ in callback.curve if mean >= threshold]
    record = {
        "algo": algo, "env": env_id, "seed": seed, "budget": budget, "n_envs": n_envs,
        "overrides": {k: repr(v) for k, v in (overrides or {}).items()},
        "curve": callback.curve, "threshold": threshold,
        "steps_to_threshold": solved[0] if solved else None,
        "final_return": callback.curve[-1][1] if callback.curve else None,
        "train_seconds": train_time, "steps_per_second": model.num_timesteps / train_time,
    }
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_suffix(".tmp")
        tmp.write_text(json.dumps(record, indent=1))
        os.replace(tmp, out)
    return record


def _run_cell(args: tuple) -> str:
    algo, env_id, seed, eval_freq = args
    out = RESULTS / env_id / algo / f"seed{seed}.json"
    rec = run_one(algo, env_id, seed, BUDGETS[env_id], eval_freq, out=out)
    return f"{algo:5s} {env_id:12s} seed {seed}: solved at {rec['steps_to_threshold']}, final {rec['final_return']:.1f}, " \
           f"{rec['steps_per_second']:.0f} steps/s"


def cmd_run(args: argparse.Namespace) -> None:
    cells = [(a, e, s, args.eval_freq) for e in args.envs for a in args.algos for s in args.seeds
             if args.force or not (RESULTS / e / a / f"seed{s}.json").exists()]
    with ProcessPoolExecutor(args.jobs) as pool:
        for line in pool.map(_run_cell, cells):
            print(line, flush=True)


def _fmt(values: list[Optional[float]]) -> str:
    got = [v for v in values if v is not None]
    if not got:
        return "not reached"
    text = f"{np.median(got) / 1000:.0f}k ({min(got) / 1000:.0f}k-{max(got) / 1000:.0f}k)"
    return text + ("" if len(got) == len(values) else f", {len(got)}/{len(values)} seeds")


def cmd_report(args: argparse.Namespace) -> None:
    rows = []
    for env_id in ENVS:
        for algo in ALGOS:
            recs = [json.loads(p.read_text()) for p in sorted((RESULTS / env_id / algo).glob("seed*.json"))]
            if not recs:
                continue
            finals = [r["final_return"] for r in recs]
            rows.append(
                f"| {env_id} | {algo.upper()} | {len(recs)} | {_fmt([r['steps_to_threshold'] for r in recs])} | "
                f"{np.mean(finals):.1f} +- {np.std(finals):.1f} | {np.median([r['steps_per_second'] for r in recs]):.0f} |"
            )
    table = "\n".join(
        ["| env | algorithm | seeds | steps to threshold: median (min-max) | final return (mean +- std over seeds) "
         "| env steps/s (median) |", "|---|---|---|---|---|---|", *rows]
    )
    body = (
        f"Command: `python benchmarks/classic_control.py run --seeds 0 1 2 3 4 --jobs 2 && "
        f"python benchmarks/classic_control.py report`\n\n"
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, one torch thread per run, two runs at a time. "
        f"Budget: {', '.join(f'{k} {v // 1000}k env steps' for k, v in BUDGETS.items())} for every algorithm. "
        "Thresholds: CartPole-v1 475, Acrobot-v1 -100, reached when the mean return of 20 deterministic evaluation "
        f"episodes (every {args.eval_freq // 1000}k steps) reaches it. Final return: the last evaluation. "
        "env steps/s: training wall-clock, evaluation time excluded. Hyperparameters: "
        "`sb3_disagree/hyperparams/<algo>.yml`.\n\n"
        f"{table}\n"
    )
    write_section("classic-control", "ACER against A2C, PPO and DQN on classic control", body)
    print(table)


def cmd_throughput(args: argparse.Namespace) -> None:
    """Wall-clock cost per env step of ACER, A2C and PPO, one after another in one process, same conditions."""
    import torch as th
    from stable_baselines3.common.env_util import make_vec_env

    th.set_num_threads(1)
    rows = []
    for env_id in args.envs:
        for algo in ("acer", "a2c", "ppo"):
            kwargs = load_hyperparams(algo, env_id)
            kwargs.pop("n_timesteps", None)
            n_envs, policy = kwargs.pop("n_envs", 1), kwargs.pop("policy")
            model = algo_class(algo)(policy, make_vec_env(env_id, n_envs=n_envs, seed=0), seed=0, **kwargs)
            model.set_logger(silent_logger())
            model.learn(2_000)  # warm-up (ACER's replay starts after 1 000 transitions)
            start = time.perf_counter()
            model.learn(args.steps, reset_num_timesteps=False)
            seconds = time.perf_counter() - start
            rows.append(f"| {env_id} | {algo.upper()} | {n_envs} | {args.steps / seconds:.0f} | "
                        f"{1e6 * seconds / args.steps:.0f} |")
            print(rows[-1], flush=True)
    body = (f"Command: `python benchmarks/classic_control.py throughput --steps {args.steps}`: each algorithm with its "
            "tuned hyperparameters (`sb3_disagree/hyperparams/`), one torch thread, one after another in one process, "
            f"{args.steps} env steps after a 2 000-step warm-up, learning included.\n\n"
            "| env | algorithm | n_envs | env steps/s | microseconds per env step |\n|---|---|---|---|---|\n"
            + "\n".join(rows) + "\n")
    write_section("classic-throughput", "ACER's wall-clock cost per env step against A2C and PPO", body)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="cmd", required=True)
    run = sub.add_parser("run")
    run.add_argument("--algos", nargs="+", default=ALGOS, choices=ALGOS)
    run.add_argument("--envs", nargs="+", default=list(ENVS), choices=list(ENVS))
    run.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4])
    run.add_argument("--jobs", type=int, default=os.cpu_count())
    run.add_argument("--force", action="store_true", help="rerun cells that already have a result")
    for p in (run, sub.add_parser("report")):
        p.add_argument("--eval-freq", type=int, default=5_000)
    throughput = sub.add_parser("throughput")
    throughput.add_argument("--steps", type=int, default=20_000)
    throughput.add_argument("--envs", nargs="+", default=list(ENVS), choices=list(ENVS))
    args = parser.parse_args()
    {"run": cmd_run, "report": cmd_report, "throughput": cmd_throughput}[args.cmd](args)


if __name__ == "__main__":
    main()
