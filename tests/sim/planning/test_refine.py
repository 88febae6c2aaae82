"""The optimisation-based refinement (H-OBCA style): exact ends, dynamics, bounds, margin,
determinism, fallbacks and malformed input."""

import math
from dataclasses import replace

import numpy as np
import pytest
from pydantic import ValidationError

from parknss.errors import ParknssError, PlanningError
from parknss.sim import geometry
from parknss.sim.planning.hybrid_astar import HybridAStar, load_planning_config, verify_trajectory
from parknss.sim.planning.refine import refine
from parknss.sim.planning.refine_obca import body_box, dual_warm_start, halfspaces
from parknss.sim.planning.refine_problem import heading_change
from parknss.sim.planning.refine_profile import (
    least_intervals,
    trapezoid,
    trapezoid_at_time,
    warm_start,
)
from parknss.sim.scenarios import Obstacle, Scene, grid_scene
from parknss.sim.trajectory import Segment, Trajectory
from parknss.vehicle import VehicleGeometry

GEOM = VehicleGeometry()


def _with_refine(cfg, **changes):
    return cfg.model_copy(update={"refine": cfg.refine.model_copy(update=changes)})


@pytest.fixture(scope="module")
def planned():
    """A perpendicular cell with a cusp: scene, coarse path, refinement, config."""
    cfg = load_planning_config()
    scene = grid_scene(14)
    coarse = HybridAStar(cfg, GEOM).plan(scene).trajectory
    assert coarse is not None and coarse.cusps >= 1
    return scene, coarse, refine(scene, coarse, GEOM, cfg), cfg


def test_refined_path_meets_start_goal_and_cusps_exactly(planned):
    scene, coarse, res, _ = planned
    assert res.ok and res.reason == "solved" and res.trajectory.source == "refined"
    traj = res.trajectory
    assert len(traj.segments) == len(coarse.segments)
    for seg, ref in zip(traj.segments, coarse.segments, strict=True):
        assert seg.direction == ref.direction
        assert np.array_equal(seg.poses[0], ref.poses[0])
        assert np.array_equal(seg.poses[-1], ref.poses[-1])
    assert np.allclose(traj.segments[0].poses[0], scene.start, atol=1e-12)
    end = traj.segments[-1].poses[-1]
    assert np.allclose(end[:2], scene.goal[:2], atol=1e-9)
    assert abs(math.remainder(end[2] - scene.goal[2], 2 * math.pi)) < 1e-9


def _integrate(p0, v0, v1, d0, d1, dt, direction, steps=20):
    """RK4 of the kinematic bicycle with speed and road-wheel angle linear in time."""

    def f(p, tau):
        v = v0 + (v1 - v0) * tau / dt
        d = d0 + (d1 - d0) * tau / dt
        s = direction * v
        return np.array([s * math.cos(p[2]), s * math.sin(p[2]), s * math.tan(d) / GEOM.wheelbase])

    p, h = np.array(p0, dtype=float), dt / steps
    for i in range(steps):
        t = i * h
        k1 = f(p, t)
        k2 = f(p + h / 2 * k1, t + h / 2)
        k3 = f(p + h / 2 * k2, t + h / 2)
        k4 = f(p + h * k3, t + h)
        p = p + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return p


def test_refined_samples_follow_the_kinematic_bicycle(planned):
    _, _, res, _ = planned
    worst_xy = worst_th = 0.0
    for seg in res.trajectory.segments:
        delta = np.radians(seg.steer / GEOM.steer_ratio)
        last = len(seg.poses) - 2  # includes the snap onto the exact end pose
        for i in [*range(0, last, 4), last]:
            dt = seg.t[i + 1] - seg.t[i]
            assert dt > 0
            p = _integrate(
                seg.poses[i],
                seg.speed[i],
                seg.speed[i + 1],
                delta[i],
                delta[i + 1],
                dt,
                seg.direction,
            )
            worst_xy = max(worst_xy, float(np.hypot(*(p[:2] - seg.poses[i + 1, :2]))))
            worst_th = max(worst_th, abs(p[2] - seg.poses[i + 1, 2]))
    # samples are 5 cm apart; speed/steer linear between them is the model's assumption;
    # the solver meets the end pose to 2 mm / 0.1 deg and the last sample is snapped on it
    print(f"worst {worst_xy * 1000:.2f} mm, {math.degrees(worst_th):.3f} deg")
    assert worst_xy < 5e-3 and worst_th < math.radians(0.3)


def test_refined_profile_respects_bounds_and_stops_at_segment_ends(planned):
    _, _, res, cfg = planned
    rc = cfg.refine
    for seg in res.trajectory.segments:
        assert seg.speed[0] == 0.0 and seg.speed[-1] == 0.0
        assert np.all(seg.speed >= 0.0) and np.all(seg.speed <= rc.speed_max_ms + 1e-6)
        assert np.all(np.abs(seg.steer) <= GEOM.steer_lock_deg + 1e-6)
        assert seg.t[0] == 0.0 and np.all(np.diff(seg.t) > 0)
        dt = np.diff(seg.t)
        assert np.all(np.abs(np.diff(seg.speed)) <= rc.accel_max_ms2 * dt + 1e-6)
        assert np.all(np.abs(np.diff(seg.steer)) <= rc.steer_rate_max_dps * dt + 1e-4)
        step = np.hypot(*np.diff(seg.poses[:, :2], axis=0).T)
        assert np.all(step <= rc.output_step_m + 1e-9)


def test_refined_path_passes_the_dense_check_with_the_margin(planned):
    scene, _, res, cfg = planned
    passed, clr = verify_trajectory(res.trajectory, scene, GEOM, cfg)
    assert passed and clr >= cfg.safety_margin_m
    assert res.min_clearance_m == pytest.approx(clr)


def test_refinement_is_deterministic(planned):
    scene, coarse, res, cfg = planned
    again = refine(scene, coarse, GEOM, cfg)
    for a, b in zip(res.trajectory.segments, again.trajectory.segments, strict=True):
        for f in ("poses", "speed", "steer", "t"):
            assert np.array_equal(getattr(a, f), getattr(b, f))


def _assert_fallback(res, coarse):
    assert res.ok is False and res.reason
    traj = res.trajectory
    assert traj.source == "coarse_fallback"
    for seg, ref in zip(traj.segments, coarse.segments, strict=True):
        assert np.array_equal(seg.poses, ref.poses)
        assert seg.speed[0] == 0.0 and seg.speed[-1] == 0.0 and np.all(seg.speed >= 0)
        assert np.all(np.diff(seg.t) > 0)


def test_tiny_budgets_fall_back_to_the_coarse_path(planned):
    scene, coarse, _, cfg = planned
    res = refine(scene, coarse, GEOM, _with_refine(cfg, max_iter=1))
    _assert_fallback(res, coarse)
    assert "Maximum_Iterations_Exceeded" in res.reason
    res = refine(scene, coarse, GEOM, _with_refine(cfg, cpu_time_s=1e-4))
    _assert_fallback(res, coarse)
    assert "CPU" in res.reason or "CpuTime" in res.reason


def test_a_coarse_path_through_an_obstacle_falls_back(planned):
    scene, coarse, _, cfg = planned
    # a wall across the whole lane between the start and the bay
    ymax = scene.bounds[3]
    wall = geometry.rectangle(-3.5, 0.5 * ymax + 0.5, 0.3, ymax + 1.0)
    blocked = replace(scene, obstacles=(*scene.obstacles, Obstacle("barrier", wall)))
    assert not verify_trajectory(coarse, blocked, GEOM, cfg)[0]
    res = refine(blocked, coarse, GEOM, _with_refine(cfg, max_iter=60))
    _assert_fallback(res, coarse)


def test_malformed_input_raises_one_line_errors(planned):
    scene, coarse, _, cfg = planned
    with pytest.raises(PlanningError) as err:
        refine(scene, Trajectory([]), GEOM, cfg)
    assert "\n" not in str(err.value)
    bad = coarse.segments[0].poses.copy()
    bad[3, 1] = np.nan
    nan_traj = Trajectory([Segment(bad, coarse.segments[0].direction)])
    with pytest.raises(ParknssError) as err:
        refine(scene, nan_traj, GEOM, cfg)
    assert "non-finite" in str(err.value) and "\n" not in str(err.value)


def test_trapezoid_profile_is_rest_to_rest_and_consistent():
    arc = np.linspace(0.0, 3.0, 61)
    speed, t = trapezoid(arc, 0.8, 0.5)
    assert speed[0] == 0.0 and speed[-1] == 0.0 and speed.max() == pytest.approx(0.8)
    assert np.all(np.diff(t) > 0) and t[-1] == pytest.approx(3.0 / 0.8 + 0.8 / 0.5)
    s, v, total = trapezoid_at_time(t, 3.0, 0.8, 0.5)
    assert total == pytest.approx(t[-1]) and np.allclose(s, arc, atol=1e-9)
    assert np.allclose(v, speed, atol=1e-9)
    short, _ = trapezoid(np.linspace(0.0, 0.2, 5), 0.8, 0.5)  # triangular
    assert short.max() < 0.8


def test_heading_change_is_the_integral_of_the_bicycle_yaw_rate():
    v0, v1, d0, d1, h = 0.2, 0.7, -0.3, 0.5, 0.4
    tau = np.linspace(0.0, h, 20001)
    rate = (v0 + (v1 - v0) * tau / h) * np.tan(d0 + (d1 - d0) * tau / h) / GEOM.wheelbase
    exact = float(np.sum((rate[1:] + rate[:-1]) / 2 * np.diff(tau)))
    assert heading_change(v0, v1, d0, d1, h, GEOM.wheelbase) == pytest.approx(exact, abs=2e-4)


def test_dual_warm_start_is_the_exact_distance():
    rng = np.random.default_rng(0)
    poly = geometry.convex_polygon([[0.0, 0.0], [3.0, -0.5], [4.0, 1.0], [1.0, 2.5]])
    A, b = halfspaces(poly)
    poses = np.column_stack(
        [rng.uniform(-8, 10, 200), rng.uniform(-8, 10, 200), rng.uniform(-np.pi, np.pi, 200)]
    )
    fp = geometry.footprints(poses, GEOM)
    keep = ~geometry.intersects(fp, poly)
    poses = poses[keep]
    lam, mu = dual_warm_start(poses, poly, A, GEOM)
    assert np.all(lam >= 0) and np.all(mu >= 0)
    w = A.T @ lam  # (2, N)
    assert np.allclose(np.hypot(*w), 1.0)
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    assert np.allclose(mu[0] - mu[2] + c * w[0] + s * w[1], 0.0, atol=1e-9)
    assert np.allclose(mu[1] - mu[3] - s * w[0] + c * w[1], 0.0, atol=1e-9)
    dual = poses[:, 0] * w[0] + poses[:, 1] * w[1] - b @ lam - body_box(GEOM) @ mu
    exact = geometry.distance(geometry.footprints(poses, GEOM), poly)
    assert np.allclose(dual, exact, atol=1e-9)


def test_planning_config_has_a_strict_refine_section():
    cfg = load_planning_config()
    assert cfg.refine.speed_max_ms == pytest.approx(3.0 / 3.6, abs=1e-3)
    with pytest.raises(ValidationError):
        type(cfg.refine).model_validate({"no_such_field": 1})


def test_a_segment_longer_than_max_intervals_allow_gets_more_intervals():
    """TPCAP case 19's 37 m reverse: 40 steps of at most 1 s cannot last the 46.6 s it
    needs at 3 km/h, so IPOPT found the program infeasible. Such a segment now gets the
    least number of intervals that can last long enough; the others keep their N."""
    cfg = load_planning_config()
    rc = cfg.refine
    limits = (rc.speed_max_ms, rc.accel_max_ms2, rc.jerk_max_ms3, rc.dt_max_s)
    assert least_intervals(37.2, *limits) == 47
    assert least_intervals(31.0, *limits) <= rc.max_intervals  # TPCAP case 11: unchanged
    x = np.linspace(0.0, -45.0, 451)
    seg = Segment(np.column_stack([x, np.zeros_like(x), np.zeros_like(x)]), -1)
    floor = least_intervals(seg.length, *limits)
    assert floor > rc.max_intervals
    ws = warm_start(seg, GEOM, rc.speed_max_ms, rc.accel_max_ms2, rc.steer_rate_max_dps,
                    rc.dt_target_s, rc.min_intervals, rc.max_intervals, floor)
    assert len(ws.poses) - 1 == floor
    scene = Scene((-50.0, -5.0, 5.0, 5.0), (), (0.0, 0.0, 0.0), (-45.0, 0.0, 0.0))
    res = refine(scene, Trajectory([seg]), GEOM, cfg)
    assert res.ok, res.reason
    assert res.segments[0]["intervals"] == floor
    assert res.trajectory.segments[0].t[-1] >= 45.0 / rc.speed_max_ms
