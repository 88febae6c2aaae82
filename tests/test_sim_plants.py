"""Plants of the closed loop: pose integration, the ideal kinematic plant, the reference
plant wrapper and the chain plant's availability error."""

from __future__ import annotations

import math
import sys

import numpy as np
import pytest

from parknss.errors import ConfigError, ParknssError
from parknss.plant import Commands
from parknss.signals import BLIND_ZONE_MS
from parknss.sim.plants import (
    Actuation,
    ChainPlant,
    KinematicPlant,
    PoseIntegrator,
    ReferencePlant,
    SimPlant,
    integrate_poses,
    make_plant,
)
from parknss.vehicle import VehicleGeometry, curvature


def test_pose_integration_is_exact_on_a_circle():
    v, w, dt, n = 0.8, 0.15, 0.01, 2000
    integ = PoseIntegrator((1.0, -2.0, 0.3), dt)
    for _ in range(n):
        integ.step(v, w)
    t, r = n * dt, v / w
    # closed form of a circle through (1, -2) with initial heading 0.3
    x = 1.0 + r * (math.sin(0.3 + w * t) - math.sin(0.3))
    y = -2.0 - r * (math.cos(0.3 + w * t) - math.cos(0.3))
    assert integ.x == pytest.approx(x, abs=1e-9)
    assert integ.y == pytest.approx(y, abs=1e-9)
    assert integ.heading == pytest.approx(0.3 + w * t, abs=1e-12)


def test_pose_integration_straight_and_reverse():
    poses = integrate_poses((0.0, 0.0, math.pi / 2), np.full(100, -0.5), np.zeros(100))
    assert poses[-1] == pytest.approx([0.0, -0.5, math.pi / 2], abs=1e-12)


def _drive(plant, gear, speed, steer, n):
    integ = PoseIntegrator((0.0, 0.0, 0.0), plant.dt)
    out, poses = None, []
    for _ in range(n):
        out = plant.advance(Actuation(Commands(gear, 0.0, 0.0, steer), speed))
        poses.append(integ.step(*plant.motion))
    return out, np.array(poses)


@pytest.mark.parametrize("gear,speed,steer", [(1, 0.6, 250.0), (-1, -0.4, -400.0)])
def test_kinematic_plant_follows_an_arc_of_the_bicycle_radius(gear, speed, steer):
    geom = VehicleGeometry()
    plant = KinematicPlant(geom)
    assert isinstance(plant, SimPlant)
    out, poses = _drive(plant, gear, speed, steer, 1500)
    radius = 1.0 / float(curvature(steer, geom))  # signed: left turn positive
    centre = np.array([0.0, radius])
    dist = np.hypot(poses[:, 0] - centre[0], poses[:, 1] - centre[1])
    assert np.max(np.abs(dist - abs(radius))) < 1e-9
    assert out.vx == speed and out.steer == steer and out.gear == gear
    assert out.yaw_rate == pytest.approx(speed / radius, rel=1e-12)
    assert out.ay == pytest.approx(speed * out.yaw_rate, rel=1e-12)
    # reversing with a left lock turns clockwise in heading (speed < 0)
    assert np.sign(poses[-1, 2]) == np.sign(speed / radius)


def test_kinematic_plant_moves_only_in_the_engaged_gear():
    plant = KinematicPlant()
    out = plant.advance(Actuation(Commands(-1, 0.0, 0.0, 0.0), 0.5))  # target disagrees
    assert out.vx == 0.0 and plant.motion == (0.0, 0.0)
    out = plant.advance(Actuation(Commands(0, 0.0, 0.0, 0.0), 0.5))  # park
    assert out.vx == 0.0
    out = plant.advance(Actuation(Commands(1, 0.0, 0.0, 900.0), 0.5))
    assert out.vx == 0.5 and out.steer == 400.0  # steering clamped to the lock
    assert out.ax == pytest.approx(0.5 / plant.dt)
    with pytest.raises(ParknssError, match="not finite"):
        plant.advance(Actuation(Commands(1, 0.0, 0.0, float("nan")), 0.1))


def test_reference_plant_moves_the_pose_with_its_truth():
    plant = ReferencePlant(seed=3)
    assert isinstance(plant, SimPlant)
    out = plant.reset()
    assert out.gear == 0 and abs(out.vx) < BLIND_ZONE_MS  # at rest: blind-zone spikes only
    integ = PoseIntegrator((0.0, 0.0, 0.0), plant.dt)
    prev_truth = 0.0
    for _ in range(300):  # drive, no brake: creep plus torque pulls it forward
        out = plant.advance(Actuation(Commands(1, 60.0, 0.0, 0.0), 0.0))
        truth = plant.vehicle.last_truth.vx
        assert plant.motion[0] == pytest.approx(0.5 * (prev_truth + truth))
        prev_truth = truth
        integ.step(*plant.motion)
    assert out.gear == 1 and prev_truth > 0.3
    assert integ.x > 0.2 and abs(integ.y) < 1e-3


def test_chain_plant_unavailable_is_one_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "parknss.chain", None)  # import raises ImportError
    with pytest.raises(ParknssError, match="chain plant unavailable"):
        ChainPlant()
    with pytest.raises(ParknssError, match="chain plant unavailable"):
        make_plant("chain")


def test_make_plant_kinds():
    assert make_plant("kinematic").name == "kinematic"
    assert make_plant("reference").name == "reference"
    with pytest.raises(ConfigError, match="unknown plant"):
        make_plant("bicycle")
