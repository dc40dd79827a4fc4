"""
The office scan's pictures and speed: first-person frames (60x80, shown 4x), the top-down map with the
navigable area, the goals and an expert episode, into docs/images/; env steps/s at 60x80 on one core and
the expert's success, into docs/benchmarks.md.

    python benchmarks/office_pictures.py [--steps 10000] [--episodes 50] [--write]
"""

import argparse
import math
import os
import platform
import time
from pathlib import Path

import numpy as np
from PIL import Image

from sb3_disagree.envs.expert import GridExpert
from sb3_disagree.envs.mesh_scene import SceneGoals, goals_path
from sb3_disagree.envs.scan import DEFAULT_SCENE, ScanEnv

OUT = Path(__file__).resolve().parent.parent / "docs" / "images"
# (name, x, z, heading in degrees)
VIEWS = [("corridor", 1.5, 7.0, 0.0), ("canteen", 15.5, 8.6, -50.0), ("office", 3.0, 4.5, 90.0),
         ("meeting room", 19.0, 4.8, 60.0)]


def pictures() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    OUT.mkdir(parents=True, exist_ok=True)
    env = ScanEnv(goal="table")
    env.reset(seed=0)
    frames = []
    for _, x, z, heading in VIEWS:
        env.set_pose(x, z, math.radians(heading))
        frames.append(env._obs())
    strip = np.concatenate([np.pad(f, ((2, 2), (2, 2), (0, 0)), constant_values=255) for f in frames], axis=1)
    Image.fromarray(strip).resize((strip.shape[1] * 4, strip.shape[0] * 4), Image.NEAREST).save(OUT / "office_views.png")

    env.reset(seed=3)
    expert = GridExpert(env)
    while True:
        _, _, term, trunc, _ = env.step(expert())
        if term or trunc:
            break
    grid = env.grid
    image = np.ones(grid.free.shape + (3,))
    image[grid.floor] = (0.8, 0.8, 0.8)
    image[grid.free] = (1.0, 1.0, 1.0)
    image[grid.obstacle] = (0.25, 0.25, 0.25)
    fig, ax = plt.subplots(figsize=(11, 6.8))
    extent = (grid.x0 - grid.cell / 2, grid.x0 + grid.cell * (grid.free.shape[0] - 0.5),
              grid.z0 + grid.cell * (grid.free.shape[1] - 0.5), grid.z0 - grid.cell / 2)
    ax.imshow(image.transpose(1, 0, 2), extent=extent)
    for name, (x0, z0, x1, z1) in env.scene_goals.regions.items():
        ax.text((x0 + x1) / 2, z0 + 0.5, name, ha="center", fontsize=8, color="#555555")
    for name, goal in env.scene_goals.goals.items():
        canteen = env.scene_goals.region_at(goal.x, goal.z) == "canteen"
        colour = "#d62728" if name == "table" else ("#e6b800" if canteen else "#7f7f7f")
        ax.add_patch(plt.Circle((goal.x, goal.z), goal.radius, color=colour, alpha=0.25))
        ax.plot(goal.x, goal.z, "*" if name == "table" else "o", color=colour, markersize=12 if name == "table" else 7)
        ax.text(goal.x, goal.z - 0.35, name, ha="center", fontsize=9, color=colour, fontweight="bold")
    path = np.array(env.path)
    ax.plot(path[:, 0], path[:, 1], color="#1f4fd6", linewidth=2)
    ax.plot(path[0, 0], path[0, 1], "o", color="black")
    ax.set(xlabel="x (m)", ylabel="z (m)", title="office floor: navigable area (white), obstacles (dark), goals "
           "(red star: the new goal; yellow: the canteen priors' goals); an expert episode to the table (blue)")
    ax.title.set_fontsize(9)
    fig.tight_layout()
    fig.savefig(OUT / "office_topdown.png", dpi=100)
    plt.close(fig)
    env.close()


def speed(steps: int, episodes: int) -> str:
    from sb3_disagree.envs import scan

    rows = []

    for obs in ("rgb", "state"):
        scan._scene.cache_clear()  # time the scene's loading and the grid's derivation too
        scan._field.cache_clear()
        start = time.perf_counter()
        env = ScanEnv(goal="table", obs=obs)
        env.reset(seed=0)
        if obs == "rgb":
            env._obs()
        created = time.perf_counter() - start
        rng = np.random.default_rng(0)
        start = time.perf_counter()
        for _ in range(steps):
            _, _, term, trunc, _ = env.step(int(rng.integers(3)))
            if term or trunc:
                env.reset()
        rate = steps / (time.perf_counter() - start)
        rows.append(f"| {obs} | {rate:,.0f} | {created:.1f} |")
        env.close()
    goals = []
    for goal in SceneGoals.load(goals_path(DEFAULT_SCENE)).goals:
        env = ScanEnv(goal=goal, obs="state")
        expert, lengths, successes = GridExpert(env), [], 0
        for seed in range(episodes):
            env.reset(seed=seed)
            for t in range(500):
                _, _, term, trunc, _ = env.step(expert())
                if term or trunc:
                    break
            successes += int(term)
            lengths.append(t + 1)
        goals.append(f"| {goal} | {successes / episodes:.2f} | {np.mean(lengths):.0f} |")
    return (f"Command: `python benchmarks/office_pictures.py --steps {steps} --episodes {episodes} --write` "
            f"({platform.machine()}, {os.cpu_count()} cores, one process, random actions, 60x80 RGB through moderngl "
            "on EGL/llvmpipe).\n\n| observation | env steps/s | first env (s) |\n|---|---|---|\n" + "\n".join(rows) +
            f"\n\nThe grid expert from {episodes} uniformly random starts per goal (anywhere on the floor):\n\n"
            "| goal | success | mean steps |\n|---|---|---|\n" + "\n".join(goals) + "\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=10_000)
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--write", action="store_true")
    args = parser.parse_args()
    pictures()
    body = speed(args.steps, args.episodes)
    if args.write:
        from docs_section import write_section

        write_section("office-speed", "The office scan: speed and expert", body)
    print(body)


if __name__ == "__main__":
    main()
