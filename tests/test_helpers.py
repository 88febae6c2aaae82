"""The shared test builders (tests/helpers/) are what their docstrings say: the gear-pattern
trials move in their gear's direction and fill the campaign's classes; the data tests'
kinematic trial is valid, exactly eq. 4, and changes gear at standstill."""

from __future__ import annotations

import numpy as np

from helpers.kinematic import kinematic_trial
from helpers.synth import make_campaign, make_trial
from parknss.data.validate import validate_trial
from parknss.signals import KMH_PER_MS, REQUIRED_CHANNELS, moving_mask


def test_trial_direction_follows_gear():
    tr = make_trial(600)
    v, g = tr["vx"], tr["gear"]
    assert np.all(np.isfinite(v)) and np.any(moving_mask(v))
    fwd = (g > 0) & (np.abs(v) > 0.05)
    rev = (g < 0) & (np.abs(v) > 0.05)
    assert fwd.any() and rev.any()
    # away from the gear changes the car moves in the gear's direction
    assert np.mean(v[fwd] > 0) > 0.8 and np.mean(v[rev] < 0) > 0.8


def test_campaign_shape():
    c = make_campaign(120, reps=4)
    assert len(c) == 16 and [len(v) for v in c.by_class().values()] == [4, 4, 4, 4]


def test_synthetic_trial_is_valid_and_exactly_kinematic():
    tr = validate_trial(kinematic_trial(ratio=13.5, wheelbase=2.8), "synthetic")
    assert list(tr.channels)[: len(REQUIRED_CHANNELS)] == list(REQUIRED_CHANNELS)
    # eq. 4 by hand: omega = vx / L * tan(steer / i), steer in deg
    omega = tr["vx"] / 2.8 * np.tan(np.radians(tr["steer"] / 13.5))
    np.testing.assert_allclose(tr["yaw_rate"], omega, rtol=0, atol=1e-15)
    assert np.abs(tr["vx"]).max() * KMH_PER_MS < 3.0


def test_synthetic_trial_reverses_at_standstill():
    tr = kinematic_trial()
    k = np.flatnonzero(np.diff(tr["gear"]) != 0) + 1
    assert list(tr["gear"][k]) == [-1.0, 1.0]
    assert np.all(tr["vx"][k - 1] == 0.0) and np.all(tr["vx"][k] == 0.0)
