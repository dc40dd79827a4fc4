"""
The apartment as data and plane geometry: rooms, doorways, objects, walls, collisions.

Both variants of the apartment (RGB and state) move the agent with this module, so their dynamics
are identical by construction; MiniWorld only renders. Coordinates are MiniWorld's: x to the east,
z to the south (up in the top view is -z), headings in radians with ``dir_vec = (cos t, -sin t)`` in
(x, z).
"""

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np


@dataclass(frozen=True)
class Room:
    """An axis-aligned room with its visual theme (MiniWorld texture names)."""

    name: str
    min_x: float
    max_x: float
    min_z: float
    max_z: float
    wall_tex: str
    floor_tex: str

    def contains(self, x: float, z: float) -> bool:
        return self.min_x <= x <= self.max_x and self.min_z <= z <= self.max_z

    @property
    def center(self) -> tuple[float, float]:
        return (self.min_x + self.max_x) / 2, (self.min_z + self.max_z) / 2


@dataclass(frozen=True)
class Doorway:
    """A passage from the corridor's north or south wall into ``room``, spanning ``min_x..max_x``."""

    room: str
    min_x: float
    max_x: float

    @property
    def center_x(self) -> float:
        return (self.min_x + self.max_x) / 2


@dataclass(frozen=True)
class GoalObject:
    """A coloured box at a fixed place; ``size`` is (sx, sy, sz) in metres."""

    name: str
    room: str
    x: float
    z: float
    color: str
    size: tuple[float, float, float] = (0.8, 0.8, 0.8)

    @property
    def radius(self) -> float:
        # MiniWorld's bounding circle of a box: collisions and the reach test use it.
        return math.hypot(self.size[0], self.size[2]) / 2


# Colours beyond MiniWorld's six, so that every object has its own.
EXTRA_COLORS: dict[str, tuple[float, float, float]] = {
    "cyan": (0.0, 0.85, 0.85),
    "white": (0.95, 0.95, 0.95),
    "orange": (1.0, 0.5, 0.0),
    "brown": (0.45, 0.25, 0.08),
    "black": (0.08, 0.08, 0.08),
    "pink": (1.0, 0.45, 0.75),
}

CORRIDOR = "corridor"


@dataclass(frozen=True)
class Layout:
    """The apartment: rooms north and south of an east-west corridor, doorways, objects."""

    corridor: Room
    rooms: tuple[Room, ...]
    doorways: tuple[Doorway, ...]
    objects: tuple[GoalObject, ...]
    agent_radius: float = 0.4
    _walls: Optional[np.ndarray] = field(default=None, compare=False, repr=False)

    @property
    def all_rooms(self) -> tuple[Room, ...]:
        return (self.corridor, *self.rooms)

    def room(self, name: str) -> Room:
        for r in self.all_rooms:
            if r.name == name:
                return r
        raise KeyError(name)

    def object(self, name: str) -> GoalObject:
        for o in self.objects:
            if o.name == name:
                return o
        raise KeyError(f"unknown goal object {name!r}; the apartment has {', '.join(self.object_names)}")

    @property
    def object_names(self) -> tuple[str, ...]:
        return tuple(o.name for o in self.objects)

    def room_at(self, x: float, z: float) -> str:
        """The room containing (x, z); a doorway's passage counts as the corridor."""
        for r in self.rooms:
            if r.contains(x, z):
                return r.name
        return CORRIDOR

    @property
    def walls(self) -> np.ndarray:
        """Wall segments, shape (n, 2, 2) as ((x0, z0), (x1, z1)): what MiniWorld builds for these rooms."""
        if self._walls is None:
            object.__setattr__(self, "_walls", _wall_segments(self))
        return self._walls  # type: ignore[return-value]

    def blocked(self, x: float, z: float) -> bool:
        """Whether the agent's bounding circle at (x, z) touches a wall or an object."""
        r = self.agent_radius
        a, b = self.walls[:, 0], self.walls[:, 1]
        ab = b - a
        t = np.clip(((np.array([x, z]) - a) * ab).sum(1) / (ab * ab).sum(1), 0.0, 1.0)
        closest = a + t[:, None] * ab
        if (np.hypot(closest[:, 0] - x, closest[:, 1] - z) < r).any():
            return True
        return any(math.hypot(o.x - x, o.z - z) < r + o.radius for o in self.objects)


def _wall_segments(layout: Layout) -> np.ndarray:
    """Room outlines minus the doorway gaps, plus the two side walls of each doorway's passage."""
    segs: list[tuple[tuple[float, float], tuple[float, float]]] = []
    c = layout.corridor
    gaps_by_edge: dict[tuple[str, str], list[tuple[float, float]]] = {}
    passage_sides = []
    for d in layout.doorways:
        room = layout.room(d.room)
        north = room.max_z <= c.min_z
        gaps_by_edge.setdefault((c.name, "north" if north else "south"), []).append((d.min_x, d.max_x))
        gaps_by_edge.setdefault((room.name, "south" if north else "north"), []).append((d.min_x, d.max_x))
        z0, z1 = (room.max_z, c.min_z) if north else (c.max_z, room.min_z)
        if z1 > z0:
            passage_sides += [((d.min_x, z0), (d.min_x, z1)), ((d.max_x, z0), (d.max_x, z1))]
    for r in layout.all_rooms:
        for edge, z in (("north", r.min_z), ("south", r.max_z)):
            x = r.min_x
            for g0, g1 in sorted(gaps_by_edge.get((r.name, edge), [])):
                segs.append(((x, z), (g0, z)))
                x = g1
            segs.append(((x, z), (r.max_x, z)))
        segs += [((r.min_x, r.min_z), (r.min_x, r.max_z)), ((r.max_x, r.min_z), (r.max_x, r.max_z))]
    return np.array(segs + passage_sides, dtype=np.float64)


def default_layout() -> Layout:
    """
    The paper's apartment: a bedroom (north-west) and a kitchen (north-east) north of the corridor,
    a bathroom south of it, each with a distinct theme and three or four coloured boxes.
    """
    corridor = Room(CORRIDOR, -8.0, 8.0, -1.0, 1.0, wall_tex="drywall", floor_tex="concrete_tiles")
    rooms = (
        Room("bedroom", -8.0, -1.0, -8.0, -1.5, wall_tex="stucco", floor_tex="wood_planks"),
        Room("kitchen", 1.0, 8.0, -8.0, -1.5, wall_tex="brick_wall", floor_tex="floor_tiles_bw"),
        Room("bathroom", -3.5, 3.5, 1.5, 7.5, wall_tex="marble", floor_tex="white"),
    )
    doorways = (
        Doorway("bedroom", -5.25, -3.75),
        Doorway("kitchen", 3.75, 5.25),
        Doorway("bathroom", -0.75, 0.75),
    )
    objects = (
        GoalObject("shower", "bathroom", -2.6, 6.6, "cyan"),
        GoalObject("bathtub", "bathroom", 2.3, 6.6, "pink", (1.4, 0.6, 0.8)),
        GoalObject("toilet", "bathroom", 2.7, 2.6, "blue", (0.6, 0.8, 0.6)),
        GoalObject("bed", "bedroom", -6.9, -6.6, "red", (1.2, 0.6, 1.4)),
        GoalObject("wardrobe", "bedroom", -1.7, -7.2, "brown", (0.8, 1.8, 0.6)),
        GoalObject("nightstand", "bedroom", -4.5, -7.4, "orange", (0.6, 0.6, 0.6)),
        GoalObject("stove", "kitchen", 1.7, -7.2, "black", (0.8, 0.9, 0.8)),
        GoalObject("toaster", "kitchen", 4.5, -7.5, "yellow", (0.5, 0.4, 0.5)),
        GoalObject("microwave", "kitchen", 7.3, -6.0, "purple", (0.6, 0.5, 0.6)),
        GoalObject("table", "kitchen", 5.5, -3.6, "green", (1.2, 0.8, 1.2)),
    )
    return Layout(corridor, rooms, doorways, objects)
