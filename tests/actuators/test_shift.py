"""The gear rule equals the reference's GearSelector sample for sample."""

from __future__ import annotations

import numpy as np

from parknss.actuators.shift import ShiftByWire
from parknss.reference.actuators import GearSelector
from parknss.reference.params import GearParams
from parknss.signals import DT


def test_rule_equals_the_reference_gear_selector():
    rng = np.random.default_rng(0)
    ref = GearSelector(GearParams(), DT)
    rule = ShiftByWire(GearParams().max_shift_speed_kmh, GearParams().shift_time_s)
    req = np.repeat(rng.integers(-1, 2, 60), 40)
    vx = np.repeat(rng.choice([0.0, 0.01, 0.5, -0.2], 80), 30)
    for q, v in zip(req, vx, strict=True):
        assert rule.step(float(q), float(v)) == ref.step(int(q), float(v))
        assert rule.shifting == ref.shifting


def test_shift_waits_the_shift_time_at_standstill():
    rule = ShiftByWire(0.1, 0.25)
    gears = [rule.step(1.0, 0.0) for _ in range(30)]
    assert gears.index(1.0) == 24  # the 25th sample at rest engages (0.25 s)
    assert rule.step(-1.0, 1.0) == 1.0 and rule.refused == 1
