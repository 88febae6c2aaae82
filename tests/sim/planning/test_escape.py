"""The multi-stroke slot escape (parknss.sim.planning.escape) on synthetic tight slots."""

import math

import numpy as np
import pytest

from parknss.config import CONFIG_DIR
from parknss.sim import geometry
from parknss.sim.planning import escape as esc
from parknss.vehicle import load_vehicle_geometry

MARGIN = 0.10


def _slot(geom, slack: float, curb_gap: float = 0.2):
    """A parallel slot for ``geom`` at the origin (rear axle, heading 0): two parked
    boxes as wide as the car, ``slack`` m longer than the car plus both margins, shared
    out 40/60 behind/ahead, and a curb ``curb_gap`` m below the car."""
    half = geom.width / 2
    rear = -geom.rear_overhang - MARGIN - 0.4 * slack
    front = geom.length - geom.rear_overhang + MARGIN + 0.6 * slack
    box = lambda x0, x1, y0, y1: np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])  # noqa: E731
    return [
        box(rear - 4.5, rear, -half, half),
        box(front, front + 4.5, -half, half),
        box(rear - 4.5, front + 4.5, -half - curb_gap - 0.3, -half - curb_gap),
    ]


def _move(obstacles, angle, shift, mirror):
    c, s = math.cos(angle), math.sin(angle)
    out = []
    for o in obstacles:
        p = o * np.array([1.0, -1.0]) if mirror else o
        p = p @ np.array([[c, s], [-s, c]]) + np.asarray(shift)
        out.append(p[::-1].copy() if mirror else p)
    return out


@pytest.fixture(scope="module")
def car():
    return load_vehicle_geometry(CONFIG_DIR / "tpcap_vehicle.yaml")


@pytest.fixture(scope="module")
def slot_escape(car):
    obstacles = _slot(car, 0.9)
    return obstacles, esc.escape((0.0, 0.0, 0.0), obstacles, car, MARGIN)


def test_escape_leaves_a_tight_slot_keeping_the_margin(car, slot_escape):
    obstacles, res = slot_escape
    assert res.found, res.reason
    assert res.side == 1  # the curb is below: out to the left
    assert 2 <= len(res.strokes) <= 20
    kmax = 1.0 / car.min_turning_radius()
    prev = np.zeros(3)
    for i, s in enumerate(res.strokes):
        assert np.allclose(s.poses[0], prev, atol=1e-12)  # continuous
        prev = s.poses[-1]
        if i:
            assert s.direction == -res.strokes[i - 1].direction  # each stroke a cusp
        assert np.all(np.abs(s.kappa) <= kmax * (1 + 1e-12))  # within the lock
        # driven as recorded: each step is the arc of the curvature at its start
        step = np.diff(s.poses[:, 2])
        ds = s.direction * np.hypot(*np.diff(s.poses[:, :2], axis=0).T)
        assert np.allclose(step, s.kappa[1:] * ds, atol=1e-9)
    dense = geometry.densify(np.concatenate([s.poses for s in res.strokes]), 0.005,
                             math.radians(0.1))
    assert geometry.clearance(dense, car, obstacles).min() >= MARGIN
    # out: the end clears margin + exit_gap_m, above the parked boxes' tops
    cfg = esc.EscapeConfig()
    assert geometry.clearance([res.end], car, obstacles)[0] >= MARGIN + cfg.exit_gap_m - 1e-9


def test_escape_moves_with_the_scene(car, slot_escape):
    obstacles, res = slot_escape
    angle, shift = math.radians(37.0), (123.4, -56.7)
    for mirror in (False, True):
        moved = _move(obstacles, angle, shift, mirror)
        sign = -1.0 if mirror else 1.0
        pose = (shift[0], shift[1], angle)
        got = esc.escape(pose, moved, car, MARGIN)
        assert got.found and len(got.strokes) == len(res.strokes)
        assert got.side == sign * res.side
        ex, ey, eth = res.end
        c, s = math.cos(angle), math.sin(angle)
        want = (shift[0] + c * ex - s * sign * ey, shift[1] + s * ex + c * sign * ey,
                angle + sign * eth)
        assert np.allclose(got.end, want, atol=1e-6)


def test_reversed_strokes_drive_back_into_the_slot(car, slot_escape):
    _, res = slot_escape
    back = esc.reversed_strokes(res.strokes)
    assert np.allclose(back[0].poses[0], res.end) and np.allclose(back[-1].poses[-1], 0.0)
    assert [s.direction for s in back] == [-s.direction for s in reversed(res.strokes)]
    for s in back:  # driven backwards, each step is still the arc of its curvature
        step = np.diff(s.poses[:, 2])
        ds = s.direction * np.hypot(*np.diff(s.poses[:, :2], axis=0).T)
        assert np.allclose(step, s.kappa[1:] * ds, atol=1e-9)
    whole = esc.stroke_segments(back, car, stop_to_steer=False)
    assert len(whole) == len(res.strokes) and all(s.steer is not None for s in whole)
    # stop_to_steer: cut where the curvature changes, each piece at one steering angle
    segs = esc.stroke_segments(back, car)
    assert len(segs) == sum(len(s.breaks) + 1 for s in back) > len(back)
    for seg in segs:
        assert np.ptp(seg.steer) < 1e-9
        kappa = np.tan(np.radians(seg.steer[0] / car.steer_ratio)) / car.wheelbase
        dth = seg.poses[-1, 2] - seg.poses[0, 2]
        assert math.isclose(dth, kappa * seg.direction * seg.length, rel_tol=1e-5)  # chords


def test_boxed_in_and_stalled_slots(car):
    # 2 cm of slack: boxed in, and the shuffle gains too little: it stops, no strokes
    tight = _slot(car, 0.02)
    assert esc.is_boxed((0.0, 0.0, 0.0), tight, car, MARGIN, esc.EscapeConfig())
    res = esc.escape((0.0, 0.0, 0.0), tight, car, MARGIN)
    assert not res.found and res.reason.startswith("stalled") and not res.strokes
    # a goal inside the margin is the search's to refuse, not boxed in
    assert not esc.is_boxed((0.0, 0.0, 0.0), tight, car, 0.3, esc.EscapeConfig())
    # roomy: not boxed in
    assert not esc.is_boxed((0.0, 0.0, 0.0), _slot(car, 1.5), car, MARGIN, esc.EscapeConfig())


def test_no_open_side(car):
    half = car.width / 2 + 0.105  # 5 mm beyond the margin either side
    walls = [np.array([[-3.0, half], [6.0, half], [6.0, half + 0.3], [-3.0, half + 0.3]]),
             np.array([[-3.0, -half - 0.3], [6.0, -half - 0.3], [6.0, -half], [-3.0, -half]])]
    assert esc.open_side((0.0, 0.0, 0.0), walls, car, MARGIN) == (0, 0.0)
    assert esc.escape((0.0, 0.0, 0.0), walls, car, MARGIN).reason == "no open side"


def test_plan_scene_escapes_a_boxed_goal_and_ends_on_it(car):
    """plan_scene: a goal boxed in (here by a raised ``boxed_run_m``) is escaped first,
    the search runs to the escape's end and the escape is driven back in, reversed."""
    from parknss.config import override
    from parknss.sim.closed_loop import load_closed_loop_config
    from parknss.sim.planner import plan_scene
    from parknss.sim.planning.hybrid_astar import load_planning_config
    from parknss.sim.scenarios import Obstacle, Scene

    obstacles = _slot(car, 0.9)
    scene = Scene((-12.0, -4.0, 14.0, 10.0), tuple(Obstacle("car", o) for o in obstacles),
                  (6.0, 3.0, 0.0), (0.0, 0.0, 0.0))
    loop = override(load_closed_loop_config(), {"plan_margin_m": MARGIN, "steer_reserve": 0.0},
                    source="test")
    cfg = override(load_planning_config(), {"escape": {"boxed_run_m": 1.5}}, source="test")
    plan = plan_scene(scene, loop, cfg, car)
    assert plan.trajectory is not None, plan.reason
    assert plan.escape_strokes >= 2 and plan.escape_reason.startswith("goal boxed in")
    traj = plan.trajectory
    assert np.allclose(traj.segments[0].poses[0], scene.start, atol=1e-6)
    assert np.allclose(traj.segments[-1].poses[-1], scene.goal, atol=1e-9)  # exactly in
    for a, b in zip(traj.segments, traj.segments[1:], strict=False):
        assert np.allclose(a.poses[-1], b.poses[0], atol=1e-6)
    assert traj.cusps >= plan.escape_strokes - 1
    dense = np.concatenate([geometry.densify(s.poses, 0.01, math.radians(0.25))
                            for s in traj.segments])
    assert geometry.clearance(dense, car, obstacles).min() >= MARGIN - 1e-6
    assert plan.min_clearance_m >= MARGIN - 1e-9
    # disabled: the search alone (the slot is roomy enough for it)
    off = override(cfg, {"escape": {"enabled": False}}, source="test")
    assert plan_scene(scene, loop, off, car, refine=False).escape_strokes == 0
