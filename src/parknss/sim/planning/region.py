"""The search region of a plan and the memory its grids need, checked before allocation.

Hybrid A* builds three grids: the distance field of the collision check
(``field_resolution_m``, 8 bytes a node), the holonomic heuristic grid with its graph
and two Dijkstra fields (``holonomic_resolution_m``, about 320 bytes a cell, measured
with scipy's CSR graph). They cover the *search region*, not the whole map: the bounding
box of start and goal grown by ``region_margin_m`` on every side, within the map. Far
obstacles cost nothing (only those within reach of the region enter). When a search
fails after its trees reached a cropped edge of the region (or the heuristic found no
corridor inside it), the planner grows the margin (doubling) and searches again, up to
the whole map.

Before any grid is allocated :func:`check_grid_memory` estimates its memory and refuses
a region beyond ``max_grid_memory_mb`` with :class:`GridMemoryError`, one line with the
size and the fix. A map the size of the small scenes (36-cell grid, TPCAP) lies inside
the default margin, so its region is the whole map.
"""

from __future__ import annotations

import math

from parknss.errors import PlanningError

FIELD_BYTES_PER_NODE = 8.0
"""The distance field: one float64 per node (temporaries are processed in chunks)."""
HOLONOMIC_BYTES_PER_CELL = 320.0
"""The heuristic grid: distances, free mask, the 8-connected CSR graph (built from COO,
symmetrised by scipy's Dijkstra) and two distance fields; measured 308 bytes a cell. (Grids
up to 30,000 cells run the plain-Python Dijkstra instead: 48 bytes a cell at its peak.)"""


class GridMemoryError(PlanningError):
    """The planner's grids over the search region would exceed ``max_grid_memory_mb``."""


Bounds = tuple[float, float, float, float]


def search_region(scene, margin: float) -> Bounds:
    """The bounding box of start and goal grown by ``margin`` m, within the map (m)."""
    xmin, ymin, xmax, ymax = (float(v) for v in scene.bounds)
    sx, sy = float(scene.start[0]), float(scene.start[1])
    gx, gy = float(scene.goal[0]), float(scene.goal[1])
    return (
        max(xmin, min(sx, gx) - margin),
        max(ymin, min(sy, gy) - margin),
        min(xmax, max(sx, gx) + margin),
        min(ymax, max(sy, gy) + margin),
    )


def grid_memory_bytes(region: Bounds, field_res: float, holo_res: float) -> float:
    """Estimated bytes of the distance field and the heuristic grid over ``region``
    (a float: ``inf`` for a region too large to count, never an overflow)."""
    w = float(region[2]) - float(region[0])
    h = float(region[3]) - float(region[1])
    nodes = (w / field_res + 5.0) * (h / field_res + 5.0)
    cells = max(1.0, w / holo_res) * max(1.0, h / holo_res)
    total = FIELD_BYTES_PER_NODE * nodes + HOLONOMIC_BYTES_PER_CELL * cells
    return total if math.isfinite(total) else math.inf


def check_grid_memory(region: Bounds, field_res: float, holo_res: float, limit_mb: float):
    """Raise :class:`GridMemoryError` when the grids over ``region`` exceed ``limit_mb``."""
    need = grid_memory_bytes(region, field_res, holo_res)
    if need <= limit_mb * 2**20:
        return need
    w, h = region[2] - region[0], region[3] - region[1]
    size = "more than can be counted" if not math.isfinite(need) else f"{need / 2**30:.3g} GiB"
    extent = f"{w:.4g} m x {h:.4g} m"
    raise GridMemoryError(
        f"the planner's grids over a {extent} search region need {size}, beyond "
        f"max_grid_memory_mb {limit_mb:g} of the planning config; put start and goal "
        f"closer together, coarsen field_resolution_m / holonomic_resolution_m, or "
        f"raise max_grid_memory_mb"
    )


def cropped_edges(region: Bounds, bounds: Bounds) -> tuple[bool, bool, bool, bool]:
    """Which sides of ``region`` (xmin, ymin, xmax, ymax) lie inside the map."""
    return (
        region[0] > bounds[0],
        region[1] > bounds[1],
        region[2] < bounds[2],
        region[3] < bounds[3],
    )


def near_cropped_edge(xy, region: Bounds, bounds: Bounds, distance: float) -> bool:
    """True when a point of ``xy`` (N, 2) lies within ``distance`` m of a cropped side."""
    crop = cropped_edges(region, bounds)
    if not any(crop) or not len(xy):
        return False
    x, y = xy[:, 0], xy[:, 1]
    gaps = (x - region[0], y - region[1], region[2] - x, region[3] - y)
    return any(c and bool((g <= distance).any()) for c, g in zip(crop, gaps, strict=True))
