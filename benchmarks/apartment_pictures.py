"""
The apartment's pictures in docs/images/: a first-person frame from each room (60x80, shown 4x) and
the top-down map with an expert episode to the bathtub, its steps coloured as the room-sensor rule
would tag them (green: outside the goal room, following priors; blue: inside it, exploring).

    python benchmarks/apartment_pictures.py
"""

import math
from pathlib import Path

import numpy as np
from PIL import Image

from sb3_disagree.envs import ApartmentEnv
from sb3_disagree.envs.expert import ApartmentExpert
from sb3_disagree.envs.topdown import draw_trajectory

OUT = Path(__file__).resolve().parent.parent / "docs" / "images"
# (room, x, z, heading in degrees): poses looking at each room's objects.
VIEWS = [("corridor", -6.5, 0.0, 0.0), ("bedroom", -3.0, -3.0, 135.0), ("kitchen", 3.0, -3.5, 30.0),
         ("bathroom", 0.0, 2.5, -90.0)]


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    env = ApartmentEnv(goal="bathtub", obs="rgb")
    env.reset(seed=0)
    frames = []
    for room, x, z, heading in VIEWS:
        env.set_pose(x, z, math.radians(heading))
        frame = env._obs()
        frames.append(frame)
        Image.fromarray(frame).resize((320, 240), Image.NEAREST).save(OUT / f"apartment_{room}.png")
    strip = np.concatenate([np.pad(f, ((2, 2), (2, 2), (0, 0)), constant_values=255) for f in frames], axis=1)
    Image.fromarray(strip).resize((strip.shape[1] * 3, strip.shape[0] * 3), Image.NEAREST).save(
        OUT / "apartment_views.png")

    env.reset(seed=4)
    expert = ApartmentExpert(env)
    tags = []
    while True:
        tags.append("prior" if env.layout.room_at(env.x, env.z) != env.goal.room else "explore")
        _, _, term, trunc, _ = env.step(expert())
        if term or trunc:
            break
    draw_trajectory(env.layout, env.path, tags, goal="bathtub", background=env.renderer.top_view(),
                    out=OUT / "apartment_topdown.png")
    draw_trajectory(env.layout, env.path, tags, goal="bathtub", out=OUT / "apartment_schematic.png")
    env.close()
    print(f"wrote {len(VIEWS) + 3} pictures to {OUT}")


if __name__ == "__main__":
    main()
