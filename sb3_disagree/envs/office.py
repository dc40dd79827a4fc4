"""
The default scan: an office floor generated from boxes with procedural textures, saved as a .glb
(the format Habitat and Matterport scenes use) with a goals file beside it.

    python -m sb3_disagree.envs.office [OUT_DIR]    # writes office.glb and office.goals.json

Coordinates: x east, y up, z south, metres; the floor at y = 0. Offices line a corridor; the canteen
(south-east) holds the main table, a sofa and a fridge.
"""

import json
import sys
from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

WALL_HEIGHT = 2.6
WALL = 0.12
SCENES = Path(__file__).resolve().parent / "scenes"


def _texture(kind: str, rgb: tuple[int, int, int], size: int = 64, seed: int = 0) -> Image.Image:
    """Small tileable textures: carpet, wood, tiles, paint."""
    rng = np.random.default_rng(seed)
    base = np.ones((size, size, 3)) * np.array(rgb, dtype=float)
    yy, xx = np.mgrid[0:size, 0:size]
    if kind == "carpet":
        base *= 0.85 + 0.3 * rng.random((size, size, 1))
    elif kind == "wood":
        base *= (0.8 + 0.2 * np.sin(yy / size * 2 * np.pi * 6 + 0.6 * np.sin(xx / size * 2 * np.pi))[..., None])
        base *= np.where((yy % 16) == 0, 0.7, 1.0)[..., None]
    elif kind == "tiles":
        grout = ((yy % 32) < 2) | ((xx % 32) < 2)
        base *= np.where(grout, 0.55, 0.95 + 0.1 * rng.random((size, size)))[..., None]
    else:  # paint
        base *= 0.93 + 0.07 * rng.random((size, size, 1))
        base *= np.where(yy > size - 6, 0.75, 1.0)[..., None]  # a skirting band at the bottom
    return Image.fromarray(np.clip(base, 0, 255).astype(np.uint8))


def textured_box(lo: tuple[float, float, float], hi: tuple[float, float, float], image: Image.Image,
                 repeat: float = 1.0) -> trimesh.Trimesh:
    """An axis-aligned box whose faces map the texture in world units (one tile per ``repeat`` metres)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    vertices, uvs, faces = [], [], []
    for axis in range(3):
        for side in (0, 1):
            u_axis, v_axis = [a for a in range(3) if a != axis]
            if axis != 1:
                v_axis = 1  # vertical faces: v runs up
                u_axis = 2 if axis == 0 else 0
            corners = []
            for du, dv in ((0, 0), (1, 0), (1, 1), (0, 1)):
                p = lo.copy()
                p[axis] = hi[axis] if side else lo[axis]
                p[u_axis] = hi[u_axis] if du else lo[u_axis]
                p[v_axis] = hi[v_axis] if dv else lo[v_axis]
                corners.append(p)
            n0 = len(vertices)
            vertices += corners
            uvs += [(c[u_axis] / repeat, c[v_axis] / repeat) for c in corners]
            normal = np.zeros(3)
            normal[axis] = 1 if side else -1
            a, b, c = corners[0], corners[1], corners[2]
            if np.dot(np.cross(b - a, c - a), normal) > 0:
                faces += [(n0, n0 + 1, n0 + 2), (n0, n0 + 2, n0 + 3)]
            else:
                faces += [(n0, n0 + 2, n0 + 1), (n0, n0 + 3, n0 + 2)]
    mesh = trimesh.Trimesh(np.array(vertices), np.array(faces), process=False)
    mesh.visual = trimesh.visual.TextureVisuals(uv=np.array(uvs), image=image)
    return mesh


class _Builder:
    def __init__(self) -> None:
        self.scene = trimesh.Scene()
        self.textures: dict[str, Image.Image] = {}
        self.count = 0

    def tex(self, kind: str, rgb: tuple[int, int, int]) -> Image.Image:
        key = f"{kind}{rgb}"
        if key not in self.textures:
            self.textures[key] = _texture(kind, rgb, seed=len(self.textures))
        return self.textures[key]

    def box(self, name: str, lo, hi, kind: str, rgb, repeat: float = 1.0) -> None:
        self.count += 1
        self.scene.add_geometry(textured_box(lo, hi, self.tex(kind, rgb), repeat), geom_name=f"{name}_{self.count}")

    def wall_x(self, z: float, x0: float, x1: float, doors=(), rgb=(214, 208, 196)) -> None:
        """A wall along x at z, from x0 to x1, with door gaps (x_start, x_end)."""
        xs = [x0] + [v for d in sorted(doors) for v in d] + [x1]
        for a, b in zip(xs[0::2], xs[1::2]):
            if b - a > 1e-6:
                self.box("wall", (a, 0, z - WALL / 2), (b, WALL_HEIGHT, z + WALL / 2), "paint", rgb, WALL_HEIGHT)

    def wall_z(self, x: float, z0: float, z1: float, doors=(), rgb=(214, 208, 196)) -> None:
        zs = [z0] + [v for d in sorted(doors) for v in d] + [z1]
        for a, b in zip(zs[0::2], zs[1::2]):
            if b - a > 1e-6:
                self.box("wall", (x - WALL / 2, 0, a), (x + WALL / 2, WALL_HEIGHT, b), "paint", rgb, WALL_HEIGHT)

    def floor(self, name: str, x0, z0, x1, z1, kind: str, rgb) -> None:
        self.box(f"floor_{name}", (x0, -0.05, z0), (x1, 0.0, z1), kind, rgb, 1.0)
        self.box(f"ceiling_{name}", (x0, WALL_HEIGHT, z0), (x1, WALL_HEIGHT + 0.05, z1), "paint", (235, 235, 230), 2.0)


def _desk(b: _Builder, x: float, z: float, w: float = 1.4, d: float = 0.7) -> None:
    b.box("desk", (x - w / 2, 0, z - d / 2), (x + w / 2, 0.75, z + d / 2), "wood", (150, 110, 70), 1.0)
    b.box("chair", (x - 0.25, 0, z + d / 2 + 0.1), (x + 0.25, 0.9, z + d / 2 + 0.6), "carpet", (40, 40, 45))


def build_office() -> tuple[trimesh.Scene, dict]:
    """The office floor and its goals file (goal points with success radii, and named regions)."""
    b = _Builder()
    # Floors and ceilings: offices north (z 0..6), corridor (z 6..8), offices and the canteen south (z 8..14).
    b.floor("north", 0, 0, 24, 6, "carpet", (90, 100, 130))
    b.floor("corridor", 0, 6, 24, 8, "wood", (170, 130, 90))
    b.floor("southwest", 0, 8, 12, 14, "carpet", (120, 95, 85))
    b.floor("canteen", 12, 8, 24, 14, "tiles", (215, 215, 205))
    # Outer walls.
    b.wall_x(0, 0, 24)
    b.wall_x(14, 0, 24)
    b.wall_z(0, 0, 14)
    b.wall_z(24, 0, 14)
    # Corridor walls with doors; the canteen opens wide onto the corridor.
    b.wall_x(6, 0, 24, doors=[(2.5, 3.5), (8.5, 9.5), (14.5, 15.5), (20.5, 21.5)], rgb=(190, 205, 215))
    b.wall_x(8, 0, 24, doors=[(2.5, 3.5), (8.5, 9.5), (15.0, 18.0)], rgb=(190, 205, 215))
    # Walls between rooms.
    for x in (6, 12, 18):
        b.wall_z(x, 0, 6)
    for x in (6, 12):
        b.wall_z(x, 8, 14)
    # Offices: desks along the outer walls; a whiteboard in the meeting room (north-east).
    for x0 in (0, 6, 12):
        _desk(b, x0 + 1.5, 1.2)
        _desk(b, x0 + 4.5, 1.2)
    for x0 in (0, 6):
        _desk(b, x0 + 1.5, 12.6)
        _desk(b, x0 + 4.5, 12.6)
    b.box("meeting_table", (19.5, 0, 2.2), (22.5, 0.75, 3.8), "wood", (110, 80, 55))
    b.box("whiteboard", (18.8, 0.8, 0.07), (23.2, 2.0, 0.15), "paint", (250, 250, 250))
    b.box("printer", (0.2, 0, 6.3), (0.9, 1.0, 7.0), "paint", (70, 75, 80))
    # The canteen: the main table in the middle, a sofa at the east wall, a fridge and a counter at the south wall.
    b.box("table", (16.5, 0, 10.4), (19.5, 0.75, 11.6), "wood", (200, 150, 80))
    for x in (17.0, 18.0, 19.0):  # stools on the south side; the table is reached from the north
        b.box("stool", (x - 0.2, 0, 12.0), (x + 0.2, 0.5, 12.4), "paint", (200, 60, 50))
    b.box("sofa", (22.9, 0, 9.2), (23.9, 0.85, 11.8), "carpet", (60, 110, 70))
    b.box("fridge", (13.0, 0, 13.1), (13.9, 1.9, 13.9), "paint", (225, 230, 235))
    b.box("counter", (14.2, 0, 13.3), (18.5, 0.9, 13.9), "wood", (95, 95, 100))
    goals = {
        "goals": {
            "table": {"position": [18.0, 11.0], "radius": 1.3},
            "sofa": {"position": [23.4, 10.5], "radius": 1.2},
            "fridge": {"position": [13.45, 13.5], "radius": 1.2},
            "whiteboard": {"position": [21.0, 0.1], "radius": 1.3},
            "printer": {"position": [0.55, 6.65], "radius": 1.0},
            "desk": {"position": [1.5, 1.2], "radius": 1.2},
        },
        "regions": {
            "corridor": [0, 6, 24, 8], "canteen": [12, 8, 24, 14], "meeting room": [18, 0, 24, 6],
            "office 1": [0, 0, 6, 6], "office 2": [6, 0, 12, 6], "office 3": [12, 0, 18, 6],
            "office 4": [0, 8, 6, 14], "office 5": [6, 8, 12, 14],
        },
        "start_region": None,
    }
    return b.scene, goals


def write_office(out_dir: Path = SCENES) -> Path:
    """Write ``office.glb`` and ``office.goals.json`` into ``out_dir``; returns the .glb path."""
    out_dir.mkdir(parents=True, exist_ok=True)
    scene, goals = build_office()
    path = out_dir / "office.glb"
    scene.export(path)
    (out_dir / "office.goals.json").write_text(json.dumps(goals, indent=2) + "\n")
    return path


if __name__ == "__main__":
    print(write_office(Path(sys.argv[1]) if len(sys.argv) > 1 else SCENES))
