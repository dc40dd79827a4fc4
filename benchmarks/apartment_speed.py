"""
The apartment's speed and the expert's episode lengths, written into docs/benchmarks.md.

    python benchmarks/apartment_speed.py [--steps 20000] [--episodes 100]

RGB and state variants step with random actions on one core (one process, LP_NUM_THREADS=0); the
creation time of the first RGB env is measured in a fresh process; the expert runs from corridor
starts for every goal.
"""

import argparse
import os
import platform
import subprocess
import sys
import time

import numpy as np
from docs_section import write_section

from sb3_disagree.envs import ApartmentEnv, default_layout
from sb3_disagree.envs.expert import ApartmentExpert


def steps_per_second(obs: str, steps: int) -> float:
    env = ApartmentEnv(goal="bathtub", obs=obs)
    env.reset(seed=0)
    actions = np.random.default_rng(0).integers(3, size=steps)
    start = time.perf_counter()
    for a in actions:
        _, _, term, trunc, _ = env.step(int(a))
        if term or trunc:
            env.reset()
    rate = steps / (time.perf_counter() - start)
    env.close()
    return rate


def creation_seconds() -> float:
    code = ("import time; t = time.perf_counter(); from sb3_disagree.envs import ApartmentEnv; "
            "e = ApartmentEnv(obs='rgb'); e.reset(seed=0); print(time.perf_counter() - t)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    return float(out.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--episodes", type=int, default=100)
    args = parser.parse_args()
    creation = [creation_seconds() for _ in range(3)]
    rgb = steps_per_second("rgb", args.steps)
    state = steps_per_second("state", args.steps)
    rows = []
    for goal in default_layout().object_names:
        env = ApartmentEnv(goal=goal, obs="state")
        expert = ApartmentExpert(env)
        lengths, successes = [], 0
        for seed in range(args.episodes):
            env.reset(seed=seed)
            while True:
                _, _, term, trunc, info = env.step(expert())
                if term or trunc:
                    break
            lengths.append(env.step_count)
            successes += info["is_success"]
        rows.append(f"| {goal} | {env.goal.room} | {successes / args.episodes:.2f} | {np.mean(lengths):.1f} | "
                    f"{np.min(lengths)}-{np.max(lengths)} |")
        print(rows[-1], flush=True)
    body = f"""Command: `python benchmarks/apartment_speed.py --steps {args.steps} --episodes {args.episodes}`.
Machine: {platform.machine()}, {os.cpu_count()} cores, Mesa llvmpipe with `LP_NUM_THREADS=0`; one process, random actions.

| variant | env steps/s (one core) |
|---|---|
| RGB 60x80 (`sb3_disagree/Apartment-v0`) | {rgb:.0f} |
| state (`sb3_disagree/ApartmentState-v0`) | {state:.0f} |

Creating the first RGB env in a fresh process (imports, OpenGL context, textures, first frame):
{np.median(creation):.1f} s (median of 3; {', '.join(f'{c:.1f}' for c in creation)}).

The scripted expert (`sb3_disagree/envs/expert.py`) from {args.episodes} random corridor starts per goal (seeds
0-{args.episodes - 1}); episode length in steps:

| goal | room | success | mean length | min-max |
|---|---|---|---|---|
{chr(10).join(rows)}
"""
    write_section("apartment-speed", "The apartment: speed and expert episode lengths", body)
    print(body)


if __name__ == "__main__":
    main()
