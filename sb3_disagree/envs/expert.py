"""
The scripted expert of the navigation tasks: it plans the shortest way to the goal on a grid of free
space (the apartment's corridor and doorways, or a scan's navigable area) and drives the agent down
that distance field.

It is what imitation-learned priors are trained from, and the yardstick for how many steps a good
policy needs.
"""

import math
from functools import lru_cache
from collections.abc import Sequence
from typing import Optional

import numpy as np

from sb3_disagree.envs.grid import GridField
from sb3_disagree.envs.layout import Layout
from sb3_disagree.envs.actions import MOVE_FORWARD, TURN_LEFT, TURN_RIGHT, wrap


class DistanceField(GridField):
    """
    Geodesic distance to a goal region over the apartment's free space (see :class:`GridField`).

    :param layout: The apartment
    :param goal_x: Goal centre x
    :param goal_z: Goal centre z
    :param goal_radius: Cells closer than this to the goal centre are the goal region
    :param cell: Grid resolution in metres
    :param margin: Clearance kept from walls and objects beyond the agent's radius
    """

    def __init__(self, layout: Layout, goal_x: float, goal_z: float, goal_radius: float, cell: float = 0.1,
                 margin: float = 0.1) -> None:
        xs = np.arange(min(r.min_x for r in layout.all_rooms), max(r.max_x for r in layout.all_rooms) + cell, cell)
        zs = np.arange(min(r.min_z for r in layout.all_rooms), max(r.max_z for r in layout.all_rooms) + cell, cell)
        gx, gz = np.meshgrid(xs, zs, indexing="ij")
        inside = np.zeros(gx.shape, dtype=bool)
        for r in layout.all_rooms:
            inside |= (gx >= r.min_x) & (gx <= r.max_x) & (gz >= r.min_z) & (gz <= r.max_z)
        for d in layout.doorways:
            room, c = layout.room(d.room), layout.corridor
            z0, z1 = sorted((room.max_z, c.min_z) if room.max_z <= c.min_z else (c.max_z, room.min_z))
            inside |= (gx >= d.min_x) & (gx <= d.max_x) & (gz >= z0) & (gz <= z1)
        free = inside & ~_blocked_grid(layout, gx, gz, layout.agent_radius + margin)
        super().__init__(free, np.hypot(gx - goal_x, gz - goal_z) < goal_radius, xs[0], zs[0], cell)


def _blocked_grid(layout: Layout, gx: np.ndarray, gz: np.ndarray, radius: float) -> np.ndarray:
    """Cells whose circle of ``radius`` touches a wall segment or an object's bounding circle."""
    p = np.stack([gx.ravel(), gz.ravel()], axis=1)
    blocked = np.zeros(len(p), dtype=bool)
    for (ax, az), (bx, bz) in layout.walls:
        a, ab = np.array([ax, az]), np.array([bx - ax, bz - az])
        t = np.clip(((p - a) @ ab) / (ab @ ab), 0.0, 1.0)
        blocked |= np.linalg.norm(a + t[:, None] * ab - p, axis=1) < radius
    for o in layout.objects:
        blocked |= np.hypot(p[:, 0] - o.x, p[:, 1] - o.z) < radius + o.radius
    return blocked.reshape(gx.shape)


@lru_cache(maxsize=64)
def layout_field(layout: Layout, goal: str, reach: float) -> DistanceField:
    g = layout.object(goal)
    # Aim a little inside the reach, so that following the field ends in success.
    return DistanceField(layout, g.x, g.z, goal_radius=reach - 0.05, margin=0.1)


class GridExpert:
    """
    Drive an agent to its goal along the shortest free path: each step searches all sequences of
    ``depth`` actions with the exact dynamics and takes the first action of the one ending closest to
    the goal (in steps: distance along the free space plus turns to face it).

    Any environment works that has the apartment's actions and exposes ``x``, ``z``, ``heading``,
    ``step_count``, ``goal_xz``, ``reach``, ``forward_step``, ``turn_step`` (radians),
    ``blocked(x, z)`` and ``nav_field()`` (a :class:`GridField` to the goal): the apartment and scans.

    :param env: The environment (its ``unwrapped`` env is read for the pose and goal)
    :param noise: Probability of a uniformly random action instead of the planned one
    :param lookahead: Distance of the waypoint that gives the path's direction, in grid cells of 0.1 m
    :param depth: Number of actions searched ahead
    :param seed: Seed of the noise
    """

    def __init__(self, env, noise: float = 0.0, lookahead: int = 4, depth: int = 3, seed: Optional[int] = None) -> None:
        self.env = env.unwrapped
        self.noise = noise
        self.lookahead = lookahead
        self.depth = depth
        self.rng = np.random.default_rng(seed)
        self.field: GridField = self.env.nav_field()
        self.gx, self.gz = self.env.goal_xz

    def value(self, x: float, z: float, heading: float) -> float:
        """
        Estimated steps to go: the geodesic distance in forward steps, plus the turn steps between the
        heading and the direction of the path (toward a waypoint down the distance field).
        """
        e = self.env
        if math.hypot(self.gx - x, self.gz - z) < e.reach:
            return 0.0
        tx, tz = self.field.waypoint(x, z, self.lookahead)
        if math.hypot(tx - x, tz - z) < 1e-6:
            tx, tz = self.gx, self.gz
        misalignment = abs(wrap(math.atan2(-(tz - z), tx - x) - heading))
        # In steps: forward steps to cover the distance, turn steps to face the path.
        return self.field.cost(x, z) / e.forward_step + misalignment / e.turn_step

    def _next(self, x: float, z: float, heading: float, action: int) -> tuple[float, float, float]:
        e = self.env
        if action == TURN_LEFT:
            return x, z, heading + e.turn_step
        if action == TURN_RIGHT:
            return x, z, heading - e.turn_step
        nx, nz = x + e.forward_step * math.cos(heading), z - e.forward_step * math.sin(heading)
        return (x, z, heading) if e.blocked(nx, nz) else (nx, nz, heading)

    def _search(self, x: float, z: float, heading: float, depth: int) -> float:
        """Lowest steps-plus-value over all action sequences of ``depth`` steps from a pose."""
        e = self.env
        if math.hypot(self.gx - x, self.gz - z) < e.reach:
            return 0.0
        if depth == 0:
            return self.value(x, z, heading)
        return 1.0 + min(self._search(*self._next(x, z, heading, a), depth - 1) for a in (MOVE_FORWARD, TURN_LEFT, TURN_RIGHT))

    def ranked_actions(self, x: float, z: float, heading: float) -> list[int]:
        """
        Actions from best to worst: each is scored by the best sequence of ``depth`` actions it starts
        (exact dynamics), valued by the pose it ends in (receding horizon).
        """
        scores = [(self._search(*self._next(x, z, heading, a), self.depth - 1), a)
                  for a in (MOVE_FORWARD, TURN_LEFT, TURN_RIGHT)]
        return [a for _, a in sorted(scores)]

    def planned_action(self, x: float, z: float, heading: float,
                       avoid: Sequence[tuple[float, float, float]] = ()) -> int:
        """
        The expert's action at a pose, without noise and without memory of the episode.

        :param avoid: Poses not to go to: the best-ranked action leading elsewhere is taken (the best overall where
            every action leads to one of them)
        """
        ranked = self.ranked_actions(x, z, heading)
        keys = {_pose_key(*pose) for pose in avoid}
        return next((a for a in ranked if _pose_key(*self._next(x, z, heading, a)) not in keys), ranked[0])

    def __call__(self) -> int:
        """
        The expert's action for the environment's current pose (noisy if ``noise`` > 0). Within an
        episode it avoids an action that leads to a pose it has been in twice, which breaks the rare
        cycle of the receding horizon at doorway corners.
        """
        e = self.env
        if e.step_count == 0:
            self._visits: dict[tuple, int] = {}
        if self.noise > 0 and self.rng.random() < self.noise:
            return int(self.rng.integers(3))
        ranked = self.ranked_actions(e.x, e.z, e.heading)
        for action in ranked:
            key = _pose_key(*self._next(e.x, e.z, e.heading, action))
            if self._visits.get(key, 0) < 2:
                break
        else:
            action = ranked[0]
        key = _pose_key(*self._next(e.x, e.z, e.heading, action))
        self._visits[key] = self._visits.get(key, 0) + 1
        return action


ApartmentExpert = GridExpert  # the apartment's expert is the grid expert


def _pose_key(x: float, z: float, heading: float) -> tuple[int, int, int]:
    return round(x * 100), round(z * 100), round(math.degrees(wrap(heading))) % 360
