"""
Geodesic distance over a grid of free cells: the shortest way through free space to a goal region
(8-connected Dijkstra), with O(1) look-ups for the experts' many queries per step.
"""

import heapq
import math

import numpy as np

_NEIGHBOURS = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


class GridField:
    """
    Geodesic distance to a goal region over a grid of free cells; cell ``(i, j)`` is the point
    ``(x0 + i * cell, z0 + j * cell)``.

    :param free: Free cells, shape (n_x, n_z)
    :param goal: Goal cells, the same shape (only free ones count)
    :param x0: x of cell (0, 0)
    :param z0: z of cell (0, 0)
    :param cell: Grid resolution in metres
    """

    def __init__(self, free: np.ndarray, goal: np.ndarray, x0: float, z0: float, cell: float) -> None:
        self.free, self.x0, self.z0, self.cell = free, float(x0), float(z0), cell
        goal = free & goal
        if not goal.any():
            raise ValueError("the goal region has no free cell: is the goal reachable?")
        self.goal = goal
        self.dist = dijkstra(free, goal, cell)
        # Precomputed look-ups, so that the expert's many queries per step are O(1):
        # the nearest reachable cell of every cell, and the next cell down the distance of every cell.
        from scipy.ndimage import distance_transform_edt

        reachable = np.isfinite(self.dist)
        _, (self._near_i, self._near_j) = distance_transform_edt(~reachable, return_indices=True)
        padded = np.pad(self.dist, 1, constant_values=np.inf)
        n, m = self.dist.shape
        shifted = np.stack([padded[1 + di:1 + di + n, 1 + dj:1 + dj + m] for di, dj in _NEIGHBOURS])
        k = shifted.argmin(0)
        better = shifted.min(0) < self.dist
        ii, jj = np.meshgrid(np.arange(n), np.arange(m), indexing="ij")
        offsets = np.array(_NEIGHBOURS)
        self._down_i = np.where(better, ii + offsets[k, 0], ii)
        self._down_j = np.where(better, jj + offsets[k, 1], jj)
        self._waypoints: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    @property
    def reachable(self) -> np.ndarray:
        """Free cells from which the goal can be reached."""
        return np.isfinite(self.dist)

    def index(self, x: float, z: float) -> tuple[int, int]:
        i = int(round((x - self.x0) / self.cell))
        j = int(round((z - self.z0) / self.cell))
        return min(max(i, 0), self.free.shape[0] - 1), min(max(j, 0), self.free.shape[1] - 1)

    def point(self, i: int, j: int) -> tuple[float, float]:
        return self.x0 + i * self.cell, self.z0 + j * self.cell

    def nearest_free(self, x: float, z: float) -> tuple[int, int]:
        """The reachable free cell nearest to (x, z)."""
        i, j = self.index(x, z)
        return int(self._near_i[i, j]), int(self._near_j[i, j])

    def waypoint(self, x: float, z: float, lookahead: int) -> tuple[float, float]:
        """The point ``lookahead`` cells down the steepest descent of the distance from (x, z)."""
        if lookahead not in self._waypoints:
            wi, wj = self._near_i, self._near_j
            for _ in range(lookahead):
                wi, wj = self._down_i[wi, wj], self._down_j[wi, wj]
            self._waypoints[lookahead] = (wi, wj)
        wi, wj = self._waypoints[lookahead]
        i, j = self.index(x, z)
        return self.point(int(wi[i, j]), int(wj[i, j]))

    def cost(self, x: float, z: float) -> float:
        """Geodesic distance; outside the free cells, that of the nearest free cell plus the offset to it."""
        fi, fj = self.nearest_free(x, z)
        fx, fz = self.point(fi, fj)
        return float(self.dist[fi, fj]) + math.hypot(fx - x, fz - z)


def dijkstra(free: np.ndarray, sources: np.ndarray, cell: float) -> np.ndarray:
    """Shortest 8-connected distance (in metres) from the source cells through free cells; inf elsewhere."""
    dist = np.full(free.shape, np.inf)
    heap = [(0.0, int(i), int(j)) for i, j in zip(*np.nonzero(sources))]
    for _, i, j in heap:
        dist[i, j] = 0.0
    heapq.heapify(heap)
    n, m = free.shape
    while heap:
        d, i, j = heapq.heappop(heap)
        if d > dist[i, j]:
            continue
        for di, dj in _NEIGHBOURS:
            a, b = i + di, j + dj
            if 0 <= a < n and 0 <= b < m and free[a, b]:
                nd = d + cell * (1.4142135623730951 if di and dj else 1.0)
                if nd < dist[a, b]:
                    dist[a, b] = nd
                    heapq.heappush(heap, (nd, a, b))
    return dist
