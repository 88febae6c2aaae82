"""The diagnosis hybrids (parknss.sim.hybrid): half chain, half truth."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.scenes import arc_scene
from parknss.config import SHIPPED_CHAIN
from parknss.errors import ConfigError
from parknss.plant import Commands
from parknss.sim.closed_loop import ClosedLoopConfig, execute
from parknss.sim.hybrid import make_hybrid
from parknss.sim.plants import make_plant


def commands(n: int = 400) -> list[Commands]:
    """Park, then drive: a torque pulse, a steering sweep, a brake ramp and a hold."""
    out = []
    for k in range(n):
        gear = 0 if k < 20 else 1
        torque = 30.0 if 40 <= k < 140 else 0.0
        decel = -min(0.02 * max(k - 200, 0), 1.2)
        out.append(Commands(gear, torque, decel, 300.0 * np.sin(k / 60.0)))
    return out


def test_nss_hybrid_feeds_the_truths_actuals_to_the_chains_nss():
    hyb = make_hybrid("nss", seed=3)
    ref = make_plant("reference", seed=3)
    chain = make_plant("chain").plant
    nss = chain.rt.nss
    hyb.reset()
    ref.reset()
    x, prev = None, 0.0
    for cmd in commands():
        y = hyb.step(cmd)
        ref.step(cmd)
        t = ref.vehicle.last_truth
        # steering does not read the speed: the truth's own actuator, sample for sample
        assert y.steer == t.steer
        u = np.array([y.gear, y.torque, y.brake_pressure, y.steer], float)
        us = nss.scale_u(u)
        x = nss.initial_state(np.zeros(2), u) if x is None else x
        vx, yaw, _, _ = nss.readout(x, us)
        assert (y.vx, y.yaw_rate) == pytest.approx((vx, yaw), abs=1e-12)
        x = nss.advance(x, us)
        if hyb.plant.envelope.held(y.brake_pressure, nss.vx(x)):
            x = nss.initial_state(np.zeros(2), u)
        assert hyb.motion[0] == pytest.approx(0.5 * (prev + vx), abs=1e-12)  # as the chain's
        prev = vx


def test_actuators_hybrid_uses_the_chains_brake_and_the_truths_body():
    # the paper chain: its brake reads only its command (models/plant's reads |vx| too)
    hyb = make_hybrid("actuators", chain_path=SHIPPED_CHAIN, seed=3)
    chain = make_plant("chain", chain_path=SHIPPED_CHAIN)
    hyb.reset()
    chain.reset()
    moved = 0.0
    for cmd in commands():
        hyb.step(cmd)
        yc = chain.step(cmd)
        t = hyb.plant.vehicle.last_truth
        # the shipped brake submodel reads only its command: the chain's pressure exactly
        assert t.brake_pressure == pytest.approx(yc.brake_pressure, abs=1e-12)
        assert hyb.motion[0] == pytest.approx(0.5 * (moved + t.vx), abs=1e-12)
        moved = t.vx
    assert hyb.plant.vehicle.long.vx == 0.0  # the truth's body holds under the brake


def test_unknown_hybrid_is_one_line():
    with pytest.raises(ConfigError, match="unknown hybrid"):
        make_hybrid("both")


@pytest.mark.parametrize("kind", ["nss", "actuators"])
def test_hybrids_park_the_arc_scene(kind):
    scene, traj = arc_scene()
    out = execute(scene, traj, make_hybrid(kind, seed=7), ClosedLoopConfig(plant_seed=7))
    assert out.completed, out.reason
    assert out.goal_error_cm < 30.0
