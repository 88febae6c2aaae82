"""The holonomic-with-obstacles heuristic of Hybrid A*: rear-axle distances on a grid.

A car whose footprint clears every obstacle by the margin has its rear axle at least
W/2 + margin from every obstacle (the disc of radius W/2 around the rear axle lies inside
the footprint). So the rear axle moves in the set {d >= W/2 + margin}; grid cells whose
centre is within res/√2 of that set are *free*, and a cell unreachable on the 8-connected
grid is unreachable for the car. Shortest grid distances to a target (scipy Dijkstra)
are the heuristic, and a target the start cannot reach means "goal unreachable" before
any search.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from parknss.sim.geometry import point_distance
from parknss.sim.planning.collision_field import CHUNK_POINTS


class HolonomicGrid:
    """The rear-axle configuration space on a grid, for the holonomic heuristic.

    ``dist_obstacle`` holds the exact distance (m) of each cell centre to the obstacles
    and the map edge. A cell is free when it is at least ``clearance - res/√2``: a
    necessary condition for the rear axle of a collision-free car (the disc of radius
    W/2 around the rear axle lies inside the footprint), so a cell unreachable on the
    grid is unreachable for the car.
    """

    def __init__(
        self, obstacles, bounds, clearance: float, res: float, cap: float, edge_distance=None
    ) -> None:
        """``edge_distance(x, y)``: signed distance (m) of points to the map's edge, when
        the map is not (only) ``bounds``."""
        xmin, ymin, xmax, ymax = bounds
        self.res = res
        self.x0, self.y0 = xmin + 0.5 * res, ymin + 0.5 * res
        self.nx = max(1, math.floor((xmax - xmin) / res))
        self.ny = max(1, math.floor((ymax - ymin) / res))
        xs = self.x0 + res * np.arange(self.nx)
        ys = self.y0 + res * np.arange(self.ny)
        d = np.minimum(
            np.minimum(xs - xmin, xmax - xs)[None, :], np.minimum(ys - ymin, ymax - ys)[:, None]
        )
        if edge_distance is not None:
            d = np.minimum(d, edge_distance(*np.meshgrid(xs, ys)))
        d = np.minimum(d, cap)  # beyond ``cap`` m only a lower bound is needed
        for poly in obstacles:  # exact distances within ``cap`` of each polygon
            lo, hi = poly.min(axis=0) - cap, poly.max(axis=0) + cap
            i0, i1 = np.searchsorted(xs, lo[0]), np.searchsorted(xs, hi[0], side="right")
            j0, j1 = np.searchsorted(ys, lo[1]), np.searchsorted(ys, hi[1], side="right")
            if i1 <= i0 or j1 <= j0:
                continue
            rows = max(1, CHUNK_POINTS // (i1 - i0))  # bounded temporaries
            for ja in range(j0, j1, rows):
                jb = min(j1, ja + rows)
                gx, gy = np.meshgrid(xs[i0:i1], ys[ja:jb])
                dp = point_distance(np.column_stack([gx.ravel(), gy.ravel()]), poly)
                block = d[ja:jb, i0:i1]
                np.minimum(block, dp.reshape(block.shape), out=block)
        self.dist_obstacle = d
        self.free = self.dist_obstacle >= clearance - res / math.sqrt(2.0)
        self._graph = None

    def index(self, x: float, y: float) -> tuple[int, int]:
        """(i, j) of the cell nearest to (x, y), clamped to the grid."""
        i = min(max(round((x - self.x0) / self.res), 0), self.nx - 1)
        j = min(max(round((y - self.y0) / self.res), 0), self.ny - 1)
        return i, j

    def _build_graph(self):
        ny, nx = self.ny, self.nx
        idx = np.arange(ny * nx).reshape(ny, nx)
        flat = self.free.ravel()
        rows, cols, wts = [], [], []
        for dj, di in ((0, 1), (1, 0), (1, 1), (1, -1)):
            a = idx[: ny - dj, max(0, -di) : nx - max(0, di)].ravel()
            b = idx[dj:, max(0, di) : nx + min(0, di) or None].ravel()
            keep = flat[a] & flat[b]
            rows.append(a[keep])
            cols.append(b[keep])
            wts.append(np.full(int(keep.sum()), self.res * math.hypot(di, dj)))
        r, c, w = np.concatenate(rows), np.concatenate(cols), np.concatenate(wts)
        return coo_matrix((w, (r, c)), shape=(ny * nx, ny * nx)).tocsr()

    def heuristic(self, target_xy) -> HolonomicHeuristic:
        """Shortest grid distances (m) from every cell to the target's cell."""
        ti, tj = self.index(*target_xy)
        if not self.free[tj, ti]:  # the target itself is known to be valid
            self.free[tj, ti] = True
            self._graph = None
        if self._graph is None:
            self._graph = self._build_graph()
        dist = dijkstra(self._graph, directed=False, indices=tj * self.nx + ti)
        return HolonomicHeuristic(self, dist.reshape(self.ny, self.nx))


class HolonomicHeuristic:
    """Shortest rear-axle distance (m) to one target around obstacles; inf if cut off."""

    def __init__(self, grid: HolonomicGrid, dist: np.ndarray) -> None:
        self.grid = grid
        self.dist = dist

    def __call__(self, x: float, y: float) -> float:
        i, j = self.grid.index(x, y)
        return float(self.dist[j, i])

    def obstacle_distance(self, x: float, y: float) -> float:
        """Lower bound of the distance (m) from (x, y) to obstacles and the map edge."""
        g = self.grid
        i, j = g.index(x, y)
        return float(g.dist_obstacle[j, i]) - g.res / math.sqrt(2.0)
