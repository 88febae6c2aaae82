"""The holonomic-with-obstacles heuristic of Hybrid A*: rear-axle distances on a grid.

A car whose footprint clears every obstacle by the margin has its rear axle at least
W/2 + margin from every obstacle (the disc of radius W/2 around the rear axle lies inside
the footprint). So the rear axle moves in the set {d >= W/2 + margin}; grid cells whose
centre is within res/√2 of that set are *free*, and a cell unreachable on the 8-connected
grid is unreachable for the car. Shortest grid distances to a target (Dijkstra on the
8-connected free cells, :func:`grid_dijkstra`: plain Python on a scene's grid, SciPy's
csgraph on large ones) are the heuristic, and a target the start
cannot reach means "goal unreachable" before any search.
"""

from __future__ import annotations

import heapq
import math

import numpy as np

from parknss.sim.geometry import point_distance
from parknss.sim.planning.collision_field import CHUNK_POINTS

ANCHOR_DIGITS = 9
"""Decimal digits (m) the grid's corner is rounded to before the cells are laid out: far
below any resolution, far above float noise (a rigid motion's last bits, ~1e-12 m)."""


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
        # the cells are anchored at the corner rounded to ANCHOR_DIGITS: a moved scene's
        # corner differs in the last bits, which moved the lattice across a lookup's
        # rounding boundary (TPCAP case 16: the goal half-way between two centres)
        ax, ay = round(xmin, ANCHOR_DIGITS), round(ymin, ANCHOR_DIGITS)
        self.x0, self.y0 = ax + 0.5 * res, ay + 0.5 * res
        self.nx = max(1, math.floor((xmax - ax) / res))
        self.ny = max(1, math.floor((ymax - ay) / res))
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

    def index(self, x: float, y: float) -> tuple[int, int]:
        """(i, j) of the cell nearest to (x, y), clamped to the grid."""
        i = min(max(round((x - self.x0) / self.res), 0), self.nx - 1)
        j = min(max(round((y - self.y0) / self.res), 0), self.ny - 1)
        return i, j

    def heuristic(self, target_xy) -> HolonomicHeuristic:
        """Shortest grid distances (m) from every cell to the target's cell."""
        ti, tj = self.index(*target_xy)
        self.free[tj, ti] = True  # the target itself is known to be valid
        return HolonomicHeuristic(self, grid_dijkstra(self.free, self.res, (tj, ti)))


PYTHON_DIJKSTRA_MAX_CELLS = 30_000
"""Grids up to this many cells use the plain-Python Dijkstra, larger ones SciPy's csgraph.

Both return the same floats; the choice is speed only. The Python loop costs about 3 µs a
cell, importing scipy.sparse.csgraph 0.15-0.3 s once (measured on the loaded 2-core build
machine): a plan builds two heuristics, so below about 3·10⁴ cells the loop is cheaper,
and the grid of a parking scene (about 10⁴ cells) starts without SciPy."""


def grid_dijkstra(
    free: np.ndarray, res: float, source: tuple[int, int], backend: str = "auto"
) -> np.ndarray:
    """Shortest distances (m) from cell ``source`` = (j, i) over the free cells of ``free``
    (ny, nx), 8-connected: a side step costs ``res``, a diagonal ``res·√2`` (both ends
    free; the source counts as free); (ny, nx), inf where cut off.

    ``backend``: "python" (a binary heap, :func:`_python_dijkstra`), "scipy" (csgraph on
    a CSR graph) or "auto" (python up to :data:`PYTHON_DIJKSTRA_MAX_CELLS` cells). Each
    distance is the least left-to-right float sum over the paths to a cell, whatever the
    order of settling, so both give the same floats bit for bit
    (``tests/sim/planning/test_holonomic.py``).
    """
    if backend == "auto":
        backend = "python" if free.size <= PYTHON_DIJKSTRA_MAX_CELLS else "scipy"
    if backend == "python":
        return _python_dijkstra(free, res, source)
    if backend == "scipy":
        return _scipy_dijkstra(free, res, source)
    raise ValueError(f"unknown Dijkstra backend {backend!r}")


def _python_dijkstra(free: np.ndarray, res: float, source: tuple[int, int]) -> np.ndarray:
    ny, nx = free.shape
    n = ny * nx
    ok = free.ravel().tolist()
    dist = [math.inf] * n
    steps = [(di, dj * nx + di, res * math.hypot(di, dj)) for dj in (-1, 0, 1)
             for di in (-1, 0, 1) if di or dj]
    src = source[0] * nx + source[1]
    dist[src] = 0.0
    heap = [(0.0, src)]
    pop, push = heapq.heappop, heapq.heappush
    while heap:
        d, u = pop(heap)
        if d > dist[u]:
            continue
        i = u % nx
        for di, off, w in steps:
            v = u + off
            if v < 0 or v >= n or not 0 <= i + di < nx or not ok[v]:
                continue
            nd = d + w
            if nd < dist[v]:
                dist[v] = nd
                push(heap, (nd, v))
    return np.array(dist).reshape(ny, nx)


def _scipy_dijkstra(free: np.ndarray, res: float, source: tuple[int, int]) -> np.ndarray:
    from scipy.sparse import coo_matrix  # 0.15-0.3 s to import: only for large grids
    from scipy.sparse.csgraph import dijkstra

    ny, nx = free.shape
    idx = np.arange(ny * nx).reshape(ny, nx)
    flat = free.ravel().copy()
    flat[source[0] * nx + source[1]] = True
    rows, cols, wts = [], [], []
    for dj, di in ((0, 1), (1, 0), (1, 1), (1, -1)):
        a = idx[: ny - dj, max(0, -di) : nx - max(0, di)].ravel()
        b = idx[dj:, max(0, di) : nx + min(0, di)].ravel()
        keep = flat[a] & flat[b]
        rows.append(a[keep])
        cols.append(b[keep])
        wts.append(np.full(int(keep.sum()), res * math.hypot(di, dj)))
    r, c, w = np.concatenate(rows), np.concatenate(cols), np.concatenate(wts)
    graph = coo_matrix((w, (r, c)), shape=(ny * nx, ny * nx)).tocsr()
    dist = dijkstra(graph, directed=False, indices=source[0] * nx + source[1])
    return dist.reshape(ny, nx)


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
