"""Per-channel normalisation: clipped min-max (paper §II), min-max, z-score, JSON."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from helpers.synth import make_campaign, make_trial, tiny_config
from parknss.data.normalize import Normalizer
from parknss.errors import CheckpointError, DataError
from parknss.nss.model import NORMALIZED
from parknss.nss.train import fit

CAMP = make_campaign(150, reps=1)
NAMES = ("gear", "torque", "vx", "yaw_rate", "ax")


def _pooled(trials, name):
    return np.concatenate([tr[name] for tr in trials])


def test_clipped_maps_percentiles_to_unit_range():
    norm = Normalizer.fit(CAMP, NAMES, "clipped", (0.5, 99.5))
    for nm in NAMES[1:]:
        x = _pooled(CAMP, nm)
        lo, hi = np.percentile(x, [0.5, 99.5])
        assert norm.transform(nm, lo) == pytest.approx(-1.0, abs=1e-12)
        assert norm.transform(nm, hi) == pytest.approx(1.0, abs=1e-12)
        s = norm.transform(nm, x)
        assert s.min() == pytest.approx(-1.0, abs=1e-12) and s.max() == pytest.approx(
            1.0, abs=1e-12
        )
        # the clipped tails land exactly on the bounds, without clip they go beyond
        assert np.mean(np.abs(s) >= 1.0 - 1e-12) > 0.004
        assert np.abs(norm.transform(nm, x, clip=False)).max() >= 1.0
    # other percentiles
    n2 = Normalizer.fit(CAMP, ("torque",), "clipped", (10.0, 90.0))
    lo, hi = np.percentile(_pooled(CAMP, "torque"), [10, 90])
    assert n2.transform("torque", np.array([lo, hi])) == pytest.approx([-1.0, 1.0])


def test_gear_is_passed_through():
    for kind in ("clipped", "minmax", "zscore"):
        norm = Normalizer.fit(CAMP, NAMES, kind)
        g = np.array([-1.0, 0.0, 1.0])
        assert np.array_equal(norm.transform("gear", g), g)


def test_minmax_and_zscore():
    mm = Normalizer.fit(CAMP, NAMES, "minmax")
    zs = Normalizer.fit(CAMP, NAMES, "zscore")
    for nm in NAMES[1:]:
        x = _pooled(CAMP, nm)
        s = mm.transform(nm, x)
        assert s.min() == pytest.approx(-1.0, abs=1e-12) and s.max() == pytest.approx(
            1.0, abs=1e-12
        )
        assert mm.transform(nm, 2 * x.max() - x.min()) == pytest.approx(3.0)  # no clip
        z = zs.transform(nm, x)
        assert z.mean() == pytest.approx(0.0, abs=1e-12) and z.std() == pytest.approx(1.0)


@pytest.mark.parametrize("kind", ["clipped", "minmax", "zscore"])
def test_transform_inverse_round_trip(kind):
    norm = Normalizer.fit(CAMP, NAMES, kind)
    for nm in NAMES:
        x = _pooled(CAMP, nm)
        np.testing.assert_allclose(norm.inverse(nm, norm.transform(nm, x, clip=False)), x,
                                   rtol=0, atol=1e-12)  # fmt: skip
        t = torch.as_tensor(x)
        torch.testing.assert_close(norm.inverse(nm, norm.transform(nm, t, clip=False)), t)
        # numpy and torch give the same numbers, clip included
        np.testing.assert_array_equal(norm.transform(nm, t).numpy(), norm.transform(nm, x))
    arr = np.stack([_pooled(CAMP, nm) for nm in NAMES], axis=-1)
    cols = norm.transform_array(NAMES, arr)
    assert np.array_equal(cols[:, 2], norm.transform("vx", arr[:, 2]))


def test_json_round_trip_and_refusals():
    norm = Normalizer.fit(CAMP, NAMES, "clipped")
    assert Normalizer.from_json(norm.to_json()) == norm
    doc = norm.to_json()
    doc["format"] = "x"
    with pytest.raises(CheckpointError):
        Normalizer.from_json(doc)
    doc = norm.to_json()
    del doc["channels"]["vx"]["scale"]
    with pytest.raises(CheckpointError):
        Normalizer.from_json(doc)
    with pytest.raises(DataError, match="no channel 'steer'"):
        norm.transform("steer", 1.0)


def test_fit_refusals():
    flat = make_trial(100)
    flat.channels["torque"] = np.full(100, 3.0)
    with pytest.raises(DataError, match="no spread"):
        Normalizer.fit([flat], ("torque",))
    nan = make_trial(100)
    nan.channels["vx"] = nan["vx"].copy()
    nan.channels["vx"][5] = np.nan
    with pytest.raises(DataError, match="non-finite"):
        Normalizer.fit([nan], ("vx",))
    with pytest.raises(DataError):
        Normalizer.fit(CAMP, NAMES, "robust")
    with pytest.raises(DataError):
        Normalizer.fit([], NAMES)


def test_fit_uses_training_trials_only():
    train = list(CAMP)[:3]
    wild = make_trial(150, seed=9, repetition=9)
    wild.channels["torque"] = wild["torque"] * 50.0  # a validation trial far outside
    wild.channels["vx"] = wild["vx"] * 3.0
    cfg = tiny_config(train={"epochs": 1})
    res = fit(train, [wild], cfg, progress=False)
    assert res.model.normalizer == Normalizer.fit(train, NORMALIZED, "clipped", (0.5, 99.5))
    assert res.model.normalizer != Normalizer.fit([*train, wild], NORMALIZED)
