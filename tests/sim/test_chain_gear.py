"""The chain plant's gear channel: driven through the Plant protocol with random requests
and commands, its engaged gear never changes while |vx| > 0.1 km/h (the shift-by-wire
rule, parknss.actuators.shift)."""

from __future__ import annotations

import numpy as np
import pytest

from parknss.plant import Commands, Plant
from parknss.signals import kmh_to_ms


@pytest.fixture(scope="module")
def chain_plant():
    from parknss.sim.plants import make_plant

    return make_plant("chain")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_chain_plant_never_shifts_while_rolling(chain_plant, seed):
    """Random gear requests and commands through the Plant protocol: the engaged gear
    changes only at |vx| <= 0.1 km/h (vx of the sample the rule reads, which the
    sample's output reports)."""
    assert isinstance(chain_plant, Plant)
    rng = np.random.default_rng(seed)
    y = chain_plant.reset(gear=1)
    rule = chain_plant.plant.rt.shift
    refused0, prev, changes = rule.refused, y.gear, 0
    for k in range(900):
        if k % 150 == 0:  # alternate driving off and braking to a stop, any gear request
            gear = int(rng.integers(-1, 2))
            drive = (k // 150) % 2 == 0
            torque = float(rng.uniform(20, 60)) if drive else 0.0
            decel = 0.0 if drive else float(rng.uniform(-0.8, -0.4))
        y = chain_plant.step(Commands(gear, torque, decel, float(rng.uniform(-200, 200))))
        if y.gear != prev:
            changes += 1
            assert abs(y.vx) <= kmh_to_ms(0.1) + 1e-12, (k, y)
        prev = y.gear
    assert changes >= 1 and rule.refused > refused0  # the property was exercised
