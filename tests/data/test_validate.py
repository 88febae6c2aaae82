"""validate_trial: every rule fails with one line naming the source, the channel and the problem."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from helpers.kinematic import kinematic_trial
from parknss.config import CONFIG_DIR
from parknss.data.trial import Trial
from parknss.data.validate import (
    ValidationConfig,
    load_validation_config,
    validate_trial,
)
from parknss.errors import ConfigError, DataError
from parknss.signals import DEG_PER_RAD, REQUIRED_CHANNELS

SRC = "logs/t3.csv"


def _with(trial: Trial, **changes) -> Trial:
    ch = {k: v.copy() for k, v in trial.channels.items()}
    for k, v in changes.items():
        if v is None:
            del ch[k]
        else:
            ch[k] = v
    return Trial(trial.id, trial.maneuver, trial.repetition, ch, trial.vehicle_id)


def _error(trial: Trial) -> str:
    with pytest.raises(DataError) as exc:
        validate_trial(trial, SRC)
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(f"{SRC}: ")
    return msg


@pytest.fixture(scope="module")
def good() -> Trial:
    return kinematic_trial()


def test_valid_trial_passes_unchanged_as_float64(good):
    ints = _with(good, gear=good["gear"].astype(np.int8))
    out = validate_trial(ints, SRC)
    assert out["gear"].dtype == np.float64
    for name, arr in good.channels.items():
        np.testing.assert_array_equal(out[name], arr)
    assert (out.id, out.maneuver, out.repetition) == (good.id, good.maneuver, good.repetition)


def test_nan_names_count_and_first_time(good):
    vx = good["vx"].copy()
    vx[[321, 400, 2999]] = np.nan
    assert _error(_with(good, vx=vx)) == (f"{SRC}: channel 'vx': 3 NaN values (first at t=3.21 s)")


def test_infinite_values(good):
    ax = good["ax"].copy()
    ax[50] = np.inf
    assert "channel 'ax': 1 infinite values (first at t=0.50 s)" in _error(_with(good, ax=ax))


def test_nan_in_truth_channel_is_an_error(good):
    tv = good["truth_vx"].copy()
    tv[10] = np.nan
    assert "channel 'truth_vx': 1 NaN values" in _error(_with(good, truth_vx=tv))


def test_missing_channels_listed(good):
    msg = _error(_with(good, ay=None, yaw_rate=None))
    assert msg.startswith(f"{SRC}: channel 'yaw_rate': missing")
    assert "2 required channels missing: yaw_rate, ay" in msg


def test_wrong_rate_reports_hz(good):
    t50 = good["t"] * 2.0
    msg = _error(_with(good, t=t50))
    assert "channel 't': sample rate 50 Hz" in msg and "expected 100 Hz" in msg


def test_rate_within_tolerance_passes_outside_fails(good):
    jitter = np.random.default_rng(0).uniform(-0.4e-3, 0.4e-3, good.n)
    validate_trial(_with(good, t=good["t"] + jitter), SRC)
    cfg = load_validation_config().model_copy(update={"dt_tolerance_s": 0.2e-3})
    with pytest.raises(DataError, match="channel 't'"):
        validate_trial(_with(good, t=good["t"] + jitter), SRC, cfg)


def test_time_going_backwards(good):
    t = good["t"].copy()
    t[1500:] -= 0.5
    msg = _error(_with(good, t=t))
    assert "channel 't': time goes backwards at 1 steps (first from t=14.99 s to t=14.50 s)" in msg


def test_duplicate_timestamps(good):
    t = good["t"].copy()
    t[700] = t[699]
    assert "channel 't': 1 duplicate timestamps (first at t=6.99 s)" in _error(_with(good, t=t))


def test_gap_in_time(good):
    t = good["t"].copy()
    t[1000:] += 0.25
    msg = _error(_with(good, t=t))
    assert "channel 't': 1 gaps in time (first of 0.26 s after t=9.99 s" in msg


def test_irregular_short_step(good):
    t = good["t"].copy()
    t[1000] -= 0.005
    assert "irregular sampling" in _error(_with(good, t=t))


def test_gear_outside_set(good):
    g = good["gear"].copy()
    g[2000:2010] = 2.0
    msg = _error(_with(good, gear=g))
    assert "channel 'gear': value 2 at t=20.00 s not in {-1, 0, 1} (10 samples outside)" in msg


def test_non_integer_gear(good):
    g = good["gear"].copy()
    g[5] = 0.5
    assert "channel 'gear': value 0.5" in _error(_with(good, gear=g))


def test_plausible_range(good):
    yaw = good["yaw_rate"] * DEG_PER_RAD  # deg/s passed off as rad/s
    msg = _error(_with(good, yaw_rate=yaw))
    assert "channel 'yaw_rate':" in msg and "outside the plausible range [-3, 3] rad/s" in msg
    k = int(np.argmax(np.abs(yaw)))
    assert f"worst {yaw[k]:.6g} at t={good['t'][k]:.2f} s" in msg


def test_unequal_lengths(good):
    assert "channel 'steer': 2999 samples, but channel 't' has 3000" in _error(
        _with(good, steer=good["steer"][:-1])
    )


def test_too_short(good):
    short = Trial("x_r1", "x", 1, {k: v[:50] for k, v in good.channels.items()})
    assert "only 50 samples (0.50 s), at least 100 required" in _error(short)


def test_non_numeric_dtype(good):
    text = good["torque"].astype(str).astype(object)
    assert "channel 'torque': not numeric (dtype object)" in _error(_with(good, torque=text))


def test_not_a_vector(good):
    two = np.stack([good["ax"], good["ax"]], axis=1)
    assert "channel 'ax': expected a 1-D vector, got shape (3000, 2)" in _error(_with(good, ax=two))


def test_metadata_rules(good):
    bad_rate = Trial(good.id, good.maneuver, 1, good.channels, sample_rate_hz=50.0)
    assert "sample rate 50 Hz in the metadata" in _error(bad_rate)
    bad_rep = Trial(good.id, good.maneuver, 0, good.channels)
    assert "repetition 0 must be >= 1" in _error(bad_rep)


def test_absolute_time_hint(good):
    msg = _error(_with(good, t=good["t"] + 1.7e9))
    assert "channel 't'" in msg and "start_at_zero" in msg


def test_validation_config_file_matches_defaults(tmp_path):
    shipped = yaml.safe_load((CONFIG_DIR / "data.yaml").read_text())["validation"]
    assert ValidationConfig(**shipped) == load_validation_config()
    assert set(load_validation_config().ranges) == set(REQUIRED_CHANNELS)  # one per channel
    bad = tmp_path / "data.yaml"
    bad.write_text("validation: {min_samples: 1}\n")
    with pytest.raises(ConfigError, match=r"field validation.min_samples"):
        load_validation_config(bad)
    bad.write_text("validation: {min_sample: 5}\n")
    with pytest.raises(ConfigError, match="min_sample"):
        load_validation_config(bad)
