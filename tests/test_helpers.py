"""The shared test builders (tests/helpers/) are what their docstrings say: the gear-pattern
trials move in their gear's direction and fill the campaign's classes; the data tests'
kinematic trial is valid, exactly eq. 4, and changes gear at standstill; the kill helper
survives a child killed while it holds tqdm's lock and fails a hung child."""

from __future__ import annotations

import signal
import time

import numpy as np
import pytest

from helpers import kills
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


def test_a_child_killed_holding_the_tqdm_lock_does_not_block_the_next(monkeypatch):
    """tqdm's default lock is a semaphore shared across fork: a child killed inside it would
    leave it taken; run_killed gives each child its own, so the next child still builds a
    progress bar (the hang seen under pytest-xdist)."""
    from tqdm import tqdm

    tqdm.get_lock()  # the shared default lock exists before the forks, as in a test run
    monkeypatch.setattr(kills, "HANG_S", 20.0)

    def hold_forever():
        with tqdm.get_lock():
            time.sleep(60)

    def build_a_bar():
        with tqdm(total=1, disable=True) as bar:
            bar.update()

    assert kills.run_killed(hold_forever, after_s=0.5) == signal.SIGKILL
    t0 = time.monotonic()
    assert kills.run_killed(build_a_bar) == 0
    assert time.monotonic() - t0 < 10


def test_a_hung_child_fails_the_test_instead_of_the_run(monkeypatch):
    monkeypatch.setattr(kills, "HANG_S", 0.5)
    with pytest.raises(AssertionError, match="hung"):
        kills.run_killed(lambda: time.sleep(60))
