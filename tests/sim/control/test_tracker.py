"""Predictive steering tracker: the spatial MPC, the path projection and tracking accuracy
on the ideal kinematic plant."""

from __future__ import annotations

import math

import numpy as np
import pytest

from helpers.scenes import arc_scene, straight_segment
from parknss.sim.closed_loop import ClosedLoopConfig, execute
from parknss.sim.control.mpc import MpcConfig, PreviewMpc, discretise, first_move_gains
from parknss.sim.control.path import PathReference
from parknss.sim.plants import KinematicPlant, integrate_poses
from parknss.sim.trajectory import Segment
from parknss.vehicle import VehicleGeometry


def test_discretisation_matches_a_fine_euler_integration():
    lam, ds = 0.12, 0.05
    a, b, e = discretise(lam, ds)
    cont = np.array([[0, 1, 0], [0, 0, 1], [0, 0, -1 / lam]], float)
    x0, u, r = np.array([0.1, -0.05, 0.02]), 0.15, 0.08
    x, n = x0.copy(), 20000
    for _ in range(n):
        x = x + ds / n * (cont @ x + np.array([0.0, 0.0, u / lam]) + np.array([0.0, -r, 0.0]))
    assert a @ x0 + b * u + e * r == pytest.approx(x, abs=1e-6)


@pytest.mark.parametrize("lam", [0.005, 0.05, 0.3])
def test_mpc_holds_an_arc_exactly(lam):
    cfg = MpcConfig()
    g_x, g_r = first_move_gains(lam, cfg)
    k = 0.17
    assert g_x @ np.array([0.0, 0.0, k]) + g_r @ np.full(cfg.horizon, k) == pytest.approx(k)


def test_mpc_closed_loop_removes_an_offset():
    mpc = PreviewMpc()
    lam = mpc.lag_distance(0.6)
    a, b, _ = discretise(lam, mpc.cfg.ds_m)
    x = np.array([0.2, 0.0, 0.0])  # 20 cm to the left of a straight path
    zeros = np.zeros(mpc.cfg.horizon)
    for _ in range(200):  # 10 m of travel
        u = min(max(mpc.command(x, zeros, 0.6), -0.217), 0.217)  # the lock, as the tracker
        x = a @ x + b * u
    assert abs(x[0]) < 2e-3 and abs(x[1]) < 2e-3


def test_projection_forward_reverse_and_past_the_end():
    geom = VehicleGeometry()
    fwd = PathReference(straight_segment(1), geom)
    p = fwd.project(1.0, 0.1, 0.05, 0, 1.0)
    assert (p.s, p.e_y, p.e_phi) == pytest.approx((1.0, 0.1, 0.05))
    rev = PathReference(straight_segment(-1), geom)
    p = rev.project(-1.0, 0.1, 0.05, 0, 1.0)  # left of +x is right of the travel direction
    assert (p.s, p.e_y, p.e_phi) == pytest.approx((1.0, -0.1, 0.05))
    p = fwd.project(5.2, 0.0, 0.0, len(fwd.s) - 1, 1.0)
    assert p.s == pytest.approx(5.2)
    assert fwd.length == pytest.approx(5.0)


def test_tracker_keeps_straight_and_arc_within_centimetres():
    scene, traj = arc_scene()
    out = execute(scene, traj, KinematicPlant(), ClosedLoopConfig())
    assert out.completed and out.reason == "completed"
    moving = np.abs(out.series["vx"]) > 1e-3
    assert np.nanmax(np.abs(out.series["lateral_error"][moving])) < 0.02
    assert out.goal_error_cm < 3.0 and out.heading_error_deg < 1.0
    # distance-indexed speed: never above the approach profile to the segment end
    togo = np.where(out.series["segment"] == 0, 4.0, 9.0) - out.series["progress"]
    cap = np.sqrt(2 * 0.35 * np.maximum(togo, 0.0)) + 0.005
    assert np.all(np.abs(out.series["vx"]) <= np.maximum(cap, 0.2))
    assert np.max(np.abs(out.series["vx"])) <= 0.75 + 1e-9
    assert out.gear_changes == 3  # park -> drive -> reverse -> park


def test_speed_cap_slows_before_steering_changes():
    geom = VehicleGeometry()
    steps = np.full(100, 0.05)
    straight = integrate_poses((0.0, 0.0, 0.0), steps, np.zeros(100), dt=1.0)
    arc = integrate_poses(tuple(straight[-1]), steps, steps * 0.2, dt=1.0)
    seg = Segment(np.vstack([straight, arc[1:]]), 1)
    ref = PathReference(seg, geom, steer_rate_dps=400.0, smooth_m=0.3, lookahead_m=0.4)
    at_kink = ref.at(5.0, ref.v_steer)
    assert ref.at(1.0, ref.v_steer) > 10.0 and at_kink < 0.5
    # a ~375 deg steering step smoothed over 0.3 m, driven at <= 400 deg/s
    assert at_kink == pytest.approx(
        400.0 / (math.degrees(math.atan(0.2 * 3.0)) * 12.1 / 0.3), rel=0.2
    )


def test_request_does_not_ramp_on_behind_a_car_that_overshot():
    """A plant faster than the request (the learned chain launching in reverse on TPCAP 13)
    gets a request that holds instead of ramping up, so the interface's feed-forward of the
    request's acceleration does not push against the speed feedback."""
    from helpers.scenes import straight_segment
    from parknss.plant import PlantOutput
    from parknss.sim.control.tracker import DRIVE, Tracker
    from parknss.sim.trajectory import Trajectory

    for d in (1, -1):
        tr = Tracker(Trajectory([straight_segment(d, 8.0)], source="test"))
        tr.phase, tr.v_ref = DRIVE, 0.0

        def out(vx, d=d, tr=tr):
            return PlantOutput(d, 0.0, 0.0, tr.steer, vx, 0.0, 0.0, 0.0)

        x = 0.0
        for _ in range(50):  # the car follows the ramp: the request rises 0.4 m/s² x 10 ms
            req = tr.step((x, 0.0, 0.0), out(d * tr.v_ref), True)
            x += d * req.speed * tr.dt
        assert req.speed == pytest.approx(0.2, abs=1e-9) and req.accel == pytest.approx(0.4)
        held = req.speed
        for _ in range(30):  # the car runs away at 0.6 m/s: the request holds
            req = tr.step((x, 0.0, 0.0), out(d * 0.6), False)
            x += d * 0.6 * tr.dt
            assert req.speed == pytest.approx(held) and req.accel <= 0.0
        for _ in range(5):  # back below the request: it ramps on
            req = tr.step((x, 0.0, 0.0), out(d * 0.1), False)
        assert req.speed > held and req.accel == pytest.approx(0.4)
