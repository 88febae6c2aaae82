"""Plants of the closed loop: pose integration, the ideal kinematic plant and its command
interface, the reference plant wrapper and the chain plant's checkpoint error; every plant
is a :class:`parknss.plant.Plant`."""

from __future__ import annotations

import math

import numpy as np
import pytest

from parknss.errors import CheckpointError, ConfigError, ParknssError
from parknss.plant import Commands, Plant, PlantOutput
from parknss.signals import BLIND_ZONE_MS
from parknss.sim.control.interface import CommandInterface, Request
from parknss.sim.plants import (
    ChainPlant,
    KinematicInterface,
    KinematicPlant,
    PoseIntegrator,
    ReferencePlant,
    SimPlant,
    integrate_poses,
    make_plant,
    parse_plants,
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
        plant.speed_target = speed
        out = plant.step(Commands(gear, 0.0, 0.0, steer))
        poses.append(integ.step(*plant.motion))
    return out, np.array(poses)


@pytest.mark.parametrize("gear,speed,steer", [(1, 0.6, 250.0), (-1, -0.4, -400.0)])
def test_kinematic_plant_follows_an_arc_of_the_bicycle_radius(gear, speed, steer):
    geom = VehicleGeometry()
    plant = KinematicPlant(geom)
    assert isinstance(plant, SimPlant) and isinstance(plant, Plant)
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


def _kin(plant: KinematicPlant, gear: int, target: float, steer: float):
    plant.speed_target = target
    return plant.step(Commands(gear, 0.0, 0.0, steer))


def test_kinematic_plant_moves_only_in_the_engaged_gear():
    plant = KinematicPlant()
    out = _kin(plant, -1, 0.5, 0.0)  # target disagrees with the gear
    assert out.vx == 0.0 and plant.motion == (0.0, 0.0)
    out = _kin(plant, 0, 0.5, 0.0)  # park
    assert out.vx == 0.0
    out = _kin(plant, 1, 0.5, 900.0)
    assert out.vx == 0.5 and out.steer == 400.0  # steering clamped to the lock
    assert out.ax == pytest.approx(0.5 / plant.dt)
    with pytest.raises(ParknssError, match="not finite"):
        _kin(plant, 1, 0.1, float("nan"))
    with pytest.raises(ParknssError, match="speed target is not finite"):
        _kin(plant, 1, float("inf"), 0.0)
    assert plant.reset() == PlantOutput(0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert plant.speed_target == 0.0


def test_kinematic_interface_hands_the_plant_the_interface_speed_target():
    """The adapter is the production interface: same commands, and the plant's speed
    target is the interface's own (0 while it holds, gear x speed once it drives)."""
    plant = KinematicPlant()
    iface = plant.command_interface()
    assert isinstance(iface, KinematicInterface)
    ref = CommandInterface()
    y = plant.reset()
    targets = []
    for k in range(200):
        req = Request(1, 0.0 if k < 20 else 0.5, 30.0, 0.0)
        cmd = iface.step(req, y)
        assert cmd == ref.step(req, y)
        assert plant.speed_target == iface.speed_target == ref.speed_target
        targets.append(plant.speed_target)
        y = plant.step(cmd)
    assert targets[0] == 0.0 and targets[-1] == 0.5 and y.vx == 0.5 and y.gear == 1
    assert isinstance(ReferencePlant(seed=0).command_interface(), CommandInterface)


def test_reference_plant_moves_the_pose_with_its_truth():
    plant = ReferencePlant(seed=3)
    assert isinstance(plant, SimPlant) and isinstance(plant, Plant)
    out = plant.reset()
    assert out.gear == 0 and abs(out.vx) < BLIND_ZONE_MS  # at rest: blind-zone spikes only
    integ = PoseIntegrator((0.0, 0.0, 0.0), plant.dt)
    prev_truth = 0.0
    for _ in range(300):  # drive, no brake: creep plus torque pulls it forward
        out = plant.step(Commands(1, 60.0, 0.0, 0.0))
        truth = plant.vehicle.last_truth.vx
        assert plant.motion[0] == pytest.approx(0.5 * (prev_truth + truth))
        prev_truth = truth
        integ.step(*plant.motion)
    assert out.gear == 1 and prev_truth > 0.3
    assert integ.x > 0.2 and abs(integ.y) < 1e-3


def test_chain_plant_without_a_checkpoint_is_one_clear_error(tmp_path):
    with pytest.raises(CheckpointError):
        ChainPlant(tmp_path / "no_chain")
    with pytest.raises(CheckpointError):
        make_plant("chain", chain_path=tmp_path / "no_chain")


def test_make_plant_kinds():
    assert make_plant("kinematic").name == "kinematic"
    assert make_plant("reference").name == "reference"
    with pytest.raises(ConfigError, match="unknown plant"):
        make_plant("bicycle")
    assert parse_plants("chain, kinematic,chain") == ["chain", "kinematic"]
    with pytest.raises(ConfigError, match="unknown plant"):
        parse_plants("kinematic,bicycle")
