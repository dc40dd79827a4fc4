"""
Where ACER's time goes on CartPole-v1: rollout collection (policy forward, behaviour, env step) against
updates (forward, Retrace, trust region, backward, optimizer), measured with cProfile on one thread.

    python benchmarks/profile_acer.py [--steps 20000]
"""

import argparse
import cProfile
import pstats
import time

import torch as th
from docs_section import write_section
from stable_baselines3.common.env_util import make_vec_env

from sb3_disagree import ACER
from sb3_disagree.loggers import silent_logger


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--top", type=int, default=25)
    parser.add_argument("--write", action="store_true", help="write the table into docs/benchmarks.md")
    args = parser.parse_args()
    th.set_num_threads(1)
    model = ACER("MlpPolicy", make_vec_env("CartPole-v1", n_envs=8, seed=0), seed=0, ent_coef=0.0)
    model.set_logger(silent_logger())  # SB3's default logger leaves a folder in the temp dir
    model.learn(2_000)  # warm-up: fills the buffer past replay_start
    profiler = cProfile.Profile()
    start = time.perf_counter()
    profiler.enable()
    model.learn(args.steps, reset_num_timesteps=False)
    profiler.disable()
    wall = time.perf_counter() - start
    stats = pstats.Stats(profiler)
    total = stats.total_tt
    # Totals of the parts of one iteration (cumulative time of each function).
    parts = {"collect_rollouts": None, "_update": None, "retrace_targets": None, "trust_region_project": None,
             "policy_terms": None, "step": None, "_checked_behaviour_step": None, "action_probs": None,
             "backward": None, "clip_grad_norm_": None, "update_average": None, "sample": None}
    for (_, _, name), (_, ncalls, _, cumtime, _) in stats.stats.items():
        if name in parts and (parts[name] is None or cumtime > parts[name][1]):
            parts[name] = (ncalls, cumtime)
    rows = [f"| `{name}` | {value[0]} | {value[1]:.2f} | {100 * value[1] / total:.0f}% |"
            for name, value in parts.items() if value]
    body = (f"Command: `python benchmarks/profile_acer.py --steps {args.steps}` (ACER MlpPolicy, CartPole-v1, 8 envs, "
            f"one torch thread, cProfile). {args.steps} env steps in {wall:.2f} s under the profiler "
            f"({args.steps / wall:.0f} steps/s). Cumulative time of the parts of an iteration:\n\n"
            "| function | calls | cumulative s | share |\n|---|---|---|---|\n" + "\n".join(rows) + "\n")
    if args.write:
        write_section("acer-profile", "Where ACER's time goes", body)
    print(body)
    stats.sort_stats("tottime").print_stats(args.top)


if __name__ == "__main__":
    main()
