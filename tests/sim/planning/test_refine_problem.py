"""The segment program (refine_problem): built once per structure, a reused program solves
exactly as a freshly built one, and the cache is bounded by its config value."""

import numpy as np
import pytest

from parknss.sim.planning import refine_problem as rp
from parknss.sim.planning.hybrid_astar import HybridAStar, load_planning_config
from parknss.sim.planning.refine_obca import obstacle_terms
from parknss.sim.planning.refine_profile import warm_start
from parknss.sim.scenarios import grid_scene
from parknss.vehicle import VehicleGeometry

GEOM = VehicleGeometry()


def _with_refine(cfg, **changes):
    return cfg.model_copy(update={"refine": cfg.refine.model_copy(update=changes)})


@pytest.fixture(scope="module")
def segment():
    """The last gear segment (into the bay) of a perpendicular cell: its warm start, obstacle terms,
    map bounds, limits and the refine config."""
    cfg = load_planning_config()
    scene = grid_scene(14)
    seg = HybridAStar(cfg, GEOM).plan(scene).trajectory.segments[-1]
    rc = cfg.refine
    lim = rp.limits(rc, GEOM, cfg.safety_margin_m + rc.margin_buffer_m)
    ws = warm_start(seg, GEOM, rc.speed_max_ms, rc.accel_max_ms2, rc.steer_rate_max_dps,
                    rc.dt_target_s, rc.min_intervals, rc.max_intervals)
    terms = obstacle_terms(ws.poses, scene.obstacle_arrays(), GEOM,
                           lim.d_min + rc.broadphase_m, rc.broadphase_knots)
    assert terms, "the cell's first segment passes an obstacle"
    return ws, terms, scene.bounds, lim, rc


def _moved(ws, terms, bounds, shift):
    """The same segment translated by ``shift`` (m): same structure, other numbers."""
    dx, dy = shift
    poses = ws.poses + np.array([dx, dy, 0.0])
    ws2 = rp.WarmStart(poses, ws.speed, ws.delta, ws.h, ws.direction)
    terms2 = []
    for t in terms:
        b = t.b + t.A @ np.array([dx, dy])
        terms2.append(type(t)(t.poly + np.array([dx, dy]), t.A, b, t.knots, t.lam0, t.mu0))
    xmin, ymin, xmax, ymax = bounds
    return ws2, terms2, (xmin + dx, ymin + dy, xmax + dx, ymax + dy)


def _solve(ws, terms, bounds, lim, rc):
    return rp.solve_segment(ws, terms, bounds, GEOM, lim, rc, rc.cpu_time_s)


def _same(a, b, atol):
    assert a.success and b.success
    for f in ("poses", "speed", "delta", "accel", "rate"):
        assert np.allclose(getattr(a, f), getattr(b, f), rtol=0.0, atol=atol), f
    assert abs(a.h - b.h) <= atol


def test_a_reused_program_solves_as_a_freshly_built_one(segment):
    ws, terms, bounds, lim, rc = segment
    rp.clear_programs()
    first = _solve(ws, terms, bounds, lim, rc)  # builds the program
    assert len(rp._PROGRAMS) == 1
    ws2, terms2, bounds2 = _moved(ws, terms, bounds, (3.25, -1.5))
    reused = _solve(ws2, terms2, bounds2, lim, rc)  # same structure: the program reused
    assert len(rp._PROGRAMS) == 1
    rp.clear_programs()
    fresh = _solve(ws2, terms2, bounds2, lim, rc.model_copy(update={"program_cache_size": 0}))
    assert not rp._PROGRAMS
    _same(reused, fresh, atol=1e-12)
    # and the moved segment's solution is the first one moved (a real change of numbers)
    moved = first.poses + np.array([3.25, -1.5, 0.0])
    assert np.abs(reused.poses - moved).max() < 1e-6
    assert np.abs(reused.poses - first.poses).max() > 1.0


def test_the_program_cache_is_keyed_by_structure_and_bounded(segment):
    ws, terms, bounds, lim, rc = segment
    rp.clear_programs()
    _solve(ws, terms, bounds, lim, rc)
    _solve(ws, terms[:-1], bounds, lim, rc)  # one obstacle fewer: another structure
    assert len(rp._PROGRAMS) == 2
    small = rc.model_copy(update={"program_cache_size": 1})
    _solve(ws, terms, bounds, lim, small)
    assert len(rp._PROGRAMS) == 1
    tighter = rc.model_copy(update={"tol": rc.tol / 10})  # solver options are structure too
    key = rp.structure_key(len(ws.poses) - 1, ws.direction, terms, None, GEOM, lim, rc, 1.0)
    assert key != rp.structure_key(len(ws.poses) - 1, ws.direction, terms, None, GEOM, lim,
                                   tighter, 1.0)
    rp.clear_programs()


def test_one_program_solves_on_several_threads_at_once(segment):
    """The web page plans on worker threads: a shared program gives each thread its own
    answer, the same as solved alone."""
    from concurrent.futures import ThreadPoolExecutor

    ws, terms, bounds, lim, rc = segment
    rp.clear_programs()
    shifts = [(0.0, 0.0), (3.25, -1.5), (-2.0, 4.0), (1.0, 1.0)]
    cases = [_moved(ws, terms, bounds, s) for s in shifts]
    alone = [_solve(*c, lim, rc) for c in cases]
    with ThreadPoolExecutor(max_workers=4) as pool:
        together = list(pool.map(lambda c: _solve(*c, lim, rc), cases * 2))
    assert len(rp._PROGRAMS) == 1
    for i, sol in enumerate(together):
        _same(sol, alone[i % len(cases)], atol=1e-12)
    rp.clear_programs()
