"""
A scene mesh (.glb/.gltf/.obj/.ply) in world coordinates, its goals file, and the navigable area
derived from the geometry: floor cells that an agent of a given radius and height can stand on.

The floor is every upward-facing triangle within ``floor_tolerance`` of the lowest one; obstacles are
all geometry between ``step_height`` above the floor and the agent's height (sampled on the triangles,
so thin vertical walls count); the free area is the floor minus the obstacles grown by the agent's
radius.
"""

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np
import trimesh


@dataclass
class Goal:
    """A named goal: a point on the floor (x, z) and the distance within which it counts as reached."""

    name: str
    x: float
    z: float
    radius: float


@dataclass
class SceneGoals:
    """The sidecar file ``<scene>.goals.json``: goals, and named regions as boxes (x0, z0, x1, z1)."""

    goals: dict[str, Goal]
    regions: dict[str, tuple[float, float, float, float]] = field(default_factory=dict)

    @classmethod
    def load(cls, path: Path) -> "SceneGoals":
        data = json.loads(Path(path).read_text())
        goals = {name: Goal(name, float(g["position"][0]), float(g["position"][1]), float(g.get("radius", 1.0)))
                 for name, g in data.get("goals", {}).items()}
        if not goals:
            raise ValueError(f"{path} names no goals")
        regions = {name: tuple(float(v) for v in box) for name, box in (data.get("regions") or {}).items()}
        return cls(goals, regions)

    def region_at(self, x: float, z: float) -> Optional[str]:
        for name, (x0, z0, x1, z1) in self.regions.items():
            if x0 <= x <= x1 and z0 <= z <= z1:
                return name
        return None


def goals_path(scene_path: Path) -> Path:
    """``office.glb`` -> ``office.goals.json`` beside it."""
    scene_path = Path(scene_path)
    return scene_path.with_name(scene_path.name.split(".")[0] + ".goals.json")


def load_meshes(path: Path) -> list[trimesh.Trimesh]:
    """Every mesh of a scene file with its node transform applied (world coordinates, y up)."""
    loaded = trimesh.load(str(path), process=False)
    if isinstance(loaded, trimesh.Trimesh):
        return [loaded]
    meshes = []
    for node in loaded.graph.nodes_geometry:
        transform, name = loaded.graph[node]
        mesh = loaded.geometry[name].copy()
        mesh.apply_transform(transform)
        meshes.append(mesh)
    if not meshes:
        raise ValueError(f"{path} holds no triangle meshes")
    return meshes


def _cells_in_triangles(tri: np.ndarray, xs: np.ndarray, zs: np.ndarray, mask: np.ndarray) -> None:
    """Mark cell centres (xs[i], zs[j]) inside the xz projection of each triangle (n, 3, 2)."""
    x0, z0, cell = xs[0], zs[0], xs[1] - xs[0]
    for t in tri:
        lo, hi = t.min(0), t.max(0)
        i0, i1 = max(int(np.floor((lo[0] - x0) / cell)), 0), min(int(np.ceil((hi[0] - x0) / cell)) + 1, len(xs))
        j0, j1 = max(int(np.floor((lo[1] - z0) / cell)), 0), min(int(np.ceil((hi[1] - z0) / cell)) + 1, len(zs))
        if i0 >= i1 or j0 >= j1:
            continue
        px, pz = np.meshgrid(xs[i0:i1], zs[j0:j1], indexing="ij")
        (ax, az), (bx, bz), (cx, cz) = t
        d = (bz - cz) * (ax - cx) + (cx - bx) * (az - cz)
        if abs(d) < 1e-12:
            continue
        l1 = ((bz - cz) * (px - cx) + (cx - bx) * (pz - cz)) / d
        l2 = ((cz - az) * (px - cx) + (ax - cx) * (pz - cz)) / d
        inside = (l1 >= -1e-9) & (l2 >= -1e-9) & (l1 + l2 <= 1 + 1e-9)
        mask[i0:i1, j0:j1] |= inside


def _sample_triangles(tri: np.ndarray, spacing: float) -> np.ndarray:
    """Points on each triangle (n, 3, 3) no further than about ``spacing`` apart (a barycentric lattice)."""
    points = []
    for t in tri:
        longest = max(np.linalg.norm(t[1] - t[0]), np.linalg.norm(t[2] - t[1]), np.linalg.norm(t[0] - t[2]))
        k = max(int(np.ceil(longest / spacing)), 1)
        i, j = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
        keep = i + j <= k
        a, b = i[keep] / k, j[keep] / k
        points.append(t[0] + a[:, None] * (t[1] - t[0]) + b[:, None] * (t[2] - t[0]))
    return np.concatenate(points) if points else np.zeros((0, 3))


@dataclass
class NavGrid:
    """
    The navigable cells of a scene at ``cell`` metres; cell (i, j) is the point (x0 + i cell, z0 + j cell).

    :param free: Cells where the agent's centre may be
    :param floor: Cells over the floor (before obstacles)
    :param obstacle: Cells with geometry in the agent's height band
    """

    free: np.ndarray
    floor: np.ndarray
    obstacle: np.ndarray
    x0: float
    z0: float
    cell: float
    floor_y: float

    def index(self, x: float, z: float) -> tuple[int, int]:
        return int(round((x - self.x0) / self.cell)), int(round((z - self.z0) / self.cell))

    def eroded(self, margin: float) -> np.ndarray:
        """Free cells with ``margin`` more clearance from obstacles and the floor's edge."""
        from scipy.ndimage import distance_transform_edt

        return distance_transform_edt(self.free) * self.cell > margin

    def is_free(self, x: float, z: float) -> bool:
        i, j = self.index(x, z)
        return 0 <= i < self.free.shape[0] and 0 <= j < self.free.shape[1] and bool(self.free[i, j])

    def coordinates(self) -> tuple[np.ndarray, np.ndarray]:
        """Cell centres as (gx, gz) arrays of the grid's shape."""
        xs = self.x0 + self.cell * np.arange(self.free.shape[0])
        zs = self.z0 + self.cell * np.arange(self.free.shape[1])
        return np.meshgrid(xs, zs, indexing="ij")


def navigable_grid(meshes: list[trimesh.Trimesh], cell: float = 0.1, agent_radius: float = 0.2,
                   agent_height: float = 1.5, step_height: float = 0.15, floor_tolerance: float = 0.1) -> NavGrid:
    """
    Derive the navigable area from the geometry.

    :param meshes: The scene in world coordinates, y up
    :param cell: Grid resolution in metres
    :param agent_radius: Clearance from obstacles
    :param agent_height: Geometry below this height above the floor blocks the agent
    :param step_height: Geometry lower than this above the floor does not (thresholds, rugs)
    :param floor_tolerance: Upward faces within this of the lowest one are floor
    """
    from scipy.ndimage import distance_transform_edt

    tris = np.concatenate([m.triangles for m in meshes])
    normals = np.concatenate([m.face_normals for m in meshes])
    up = normals[:, 1] > 0.9
    if not up.any():
        raise ValueError("the scene has no upward-facing triangles: no floor to walk on")
    top = tris[..., 1].max(1)
    floor_y = float(np.min(top[up]))
    is_floor = up & (top <= floor_y + floor_tolerance)
    lo, hi = tris[is_floor][..., [0, 2]].reshape(-1, 2).min(0), tris[is_floor][..., [0, 2]].reshape(-1, 2).max(0)
    xs = np.arange(lo[0], hi[0] + cell, cell)
    zs = np.arange(lo[1], hi[1] + cell, cell)
    floor = np.zeros((len(xs), len(zs)), dtype=bool)
    _cells_in_triangles(tris[is_floor][..., [0, 2]], xs, zs, floor)
    # Obstacles: any triangle reaching into the band (floor + step_height, floor + agent_height).
    band_lo, band_hi = floor_y + step_height, floor_y + agent_height
    in_band = (tris[..., 1].max(1) > band_lo) & (tris[..., 1].min(1) < band_hi)
    points = _sample_triangles(tris[in_band], cell / 2)
    points = points[(points[:, 1] > band_lo) & (points[:, 1] < band_hi)]
    obstacle = np.zeros_like(floor)
    i = np.round((points[:, 0] - xs[0]) / cell).astype(int)
    j = np.round((points[:, 2] - zs[0]) / cell).astype(int)
    ok = (i >= 0) & (i < len(xs)) & (j >= 0) & (j < len(zs))
    obstacle[i[ok], j[ok]] = True
    clearance = distance_transform_edt(~obstacle) * cell
    free = floor & (clearance > agent_radius)
    return NavGrid(free, floor, obstacle, float(xs[0]), float(zs[0]), cell, floor_y)
