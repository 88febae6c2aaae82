"""The holonomic heuristic's Dijkstra: the plain-Python loop gives the same floats as
SciPy's csgraph on the planner's own grids (scenes of the default grid) and on random
masks."""

import math

import numpy as np
import pytest

from parknss.sim.planning import holonomic
from parknss.sim.planning.holonomic import HolonomicGrid, grid_dijkstra
from parknss.sim.planning.hybrid_astar import HybridAStar, PlanningConfig
from parknss.sim.scenarios import grid_scene
from parknss.vehicle import VehicleGeometry


def _both(free: np.ndarray, res: float, source: tuple[int, int]) -> np.ndarray:
    """The plain-Python distances, asserted bit-identical to SciPy's csgraph."""
    ours = grid_dijkstra(free, res, source, backend="python")
    assert np.array_equal(ours, grid_dijkstra(free, res, source, backend="scipy"))
    return ours


def _planner_grids(monkeypatch, scene) -> list[tuple[np.ndarray, float, tuple[int, int]]]:
    """The (free mask, resolution, target cell) of every heuristic the planner builds."""
    seen = []
    original = HolonomicGrid.heuristic

    def spy(self, target_xy):
        ti, tj = self.index(*target_xy)
        seen.append((self.free.copy(), self.res, (tj, ti)))
        return original(self, target_xy)

    monkeypatch.setattr(holonomic.HolonomicGrid, "heuristic", spy)
    HybridAStar(PlanningConfig(time_budget_s=30.0), VehicleGeometry()).plan(scene)
    return seen


@pytest.mark.parametrize("cell", [26, 0, 2, 28])
def test_the_same_distances_as_scipy_on_the_planners_grids(monkeypatch, cell):
    grids = _planner_grids(monkeypatch, grid_scene(cell))
    assert len(grids) == 2  # a heuristic to the goal and one to the start
    for free, res, target in grids:
        assert free.size <= holonomic.PYTHON_DIJKSTRA_MAX_CELLS  # planned without SciPy
        ours = _both(free, res, target)  # bit for bit, inf where cut off
        # a good part reachable (the region also covers cells outside the map and obstacles)
        assert np.isfinite(ours).sum() > 0.25 * free.size


def test_the_same_distances_as_scipy_on_random_masks():
    rng = np.random.default_rng(7)
    for _ in range(30):
        ny, nx = rng.integers(1, 40, size=2)
        free = rng.random((ny, nx)) > rng.uniform(0.0, 0.6)
        res = float(rng.choice([0.1, 0.25, 0.3, 1.0 / 3.0]))
        source = (int(rng.integers(ny)), int(rng.integers(nx)))
        free[source] = True
        _both(free, res, source)


def test_a_walled_off_region_is_unreachable():
    free = np.ones((5, 9), dtype=bool)
    free[:, 4] = False  # a wall across the grid
    dist = _both(free, 0.5, (2, 0))
    assert np.all(np.isinf(dist[:, 4:]))
    assert dist[2, 0] == 0.0 and dist[2, 3] == 1.5 and dist[0, 2] == 2 * 0.5 * math.sqrt(2)


def test_the_source_counts_as_free_and_unknown_backends_are_refused():
    free = np.zeros((3, 3), dtype=bool)
    free[1, 2] = True
    dist = _both(free, 1.0, (1, 1))  # a blocked source still reaches its free neighbours
    assert dist[1, 1] == 0.0 and dist[1, 2] == 1.0 and np.isinf(dist[0, 0])
    assert np.array_equal(grid_dijkstra(free, 1.0, (1, 1)), dist)  # auto: python
    with pytest.raises(ValueError):
        grid_dijkstra(free, 1.0, (1, 1), backend="networkx")


@pytest.mark.parametrize("noise", [0.0, 1e-12, -1e-12])
def test_the_lattice_does_not_move_with_float_noise_in_the_bounds(noise):
    """A moved scene's bounds equal the original's up to float noise: the cells (anchored
    at the corner rounded to ANCHOR_DIGITS) and so every lookup are the same, also for
    the goal lying half-way between two cell centres (TPCAP case 16: it fell either side)."""
    res = 0.25
    ref = HolonomicGrid([], (-8.0, -7.9, 6.1, 8.0), 0.5, res, 5.0)
    grid = HolonomicGrid([], (-8.0 + noise, -7.9 - noise, 6.1 + noise, 8.0 - noise), 0.5, res, 5.0)
    assert (grid.x0, grid.y0) == (ref.x0, ref.y0)
    assert grid.index(0.0, 0.0) == ref.index(0.0, 0.0)
    assert (0.0 - ref.x0) / res == 31.5  # the origin on a rounding boundary
    h, h_ref = grid.heuristic((0.0, 0.0)), ref.heuristic((0.0, 0.0))
    for x, y in [(3.0 + 1e-13, -2.0), (-5.0, 4.0 - 1e-13), (0.3, -0.7)]:
        assert h(x, y) == h_ref(x, y)
