"""The APS-driven campaign generator, checked on a few trials (the full 16 in benchmarks/)."""

import json

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from parknss.config import CONFIG_DIR
from parknss.errors import ConfigError
from parknss.reference.campaign import LENGTH_RANGE_S, generate_trial
from parknss.reference.params import ReferenceVehicleParams, load_vehicle_params
from parknss.reference.vehicle import TRUTH_CHANNELS
from parknss.signals import DT, REQUIRED_CHANNELS, kmh_to_ms, moving_mask

P0 = ReferenceVehicleParams()


@pytest.fixture(scope="module")
def park_in():
    return generate_trial("park_in_left", 1, seed=0, params=P0)


@pytest.fixture(scope="module")
def park_out():
    return generate_trial("park_out_right", 2, seed=0, params=P0)


def reversals(gear: np.ndarray) -> int:
    nz = gear[gear != 0]
    return int(np.sum(nz[1:] != nz[:-1]))


def ratio_fit(tr, wheelbase: float) -> float:
    """Least-squares steering ratio of ω = vx/L·tan(δ/i) on the moving region (logged)."""
    m = moving_mask(tr["vx"])
    w, v, s = tr["yaw_rate"][m], tr["vx"][m], np.radians(tr["steer"][m])
    res = minimize_scalar(
        lambda i: np.sum((w - v / wheelbase * np.tan(s / i)) ** 2),
        bounds=(5, 30),
        method="bounded",
    )
    return float(res.x)


def test_trial_has_schema_and_truth_channels(park_in):
    tr = park_in
    assert tr.id == "park_in_left_r1" and tr.maneuver == "park_in_left" and tr.repetition == 1
    for name in (*REQUIRED_CHANNELS, *TRUTH_CHANNELS):
        assert name in tr.channels, name
        assert tr[name].shape == (tr.n,) and np.all(np.isfinite(tr[name]))
    np.testing.assert_allclose(np.diff(tr["t"]), DT, atol=1e-12)
    assert set(np.unique(tr["gear"])) <= {-1.0, 0.0, 1.0}
    assert np.all(tr["decel_cmd"] <= 0.0) and np.all(tr["torque_cmd"] >= 0.0)
    prov = json.loads(tr.provenance)
    assert prov["generator"] == "parknss.reference.campaign" and prov["synthetic"] is True
    assert prov["vehicle_params_digest"] == P0.digest()


def test_lengths_and_shape_of_the_classes(park_in, park_out):
    lo, hi = LENGTH_RANGE_S
    for tr in (park_in, park_out):
        assert lo <= tr.duration_s <= hi
    assert 8 <= reversals(park_in["gear"]) <= 10  # multi-segment with reversals
    assert reversals(park_out["gear"]) == 0  # single segment
    assert np.all(park_out["gear"][park_out["gear"] != 0] == 1)  # leaves forward


def test_every_gear_change_happens_at_standstill_without_neutral(park_in, park_out):
    for tr in (park_in, park_out):
        g, v = tr["gear"], tr["truth_vx"]
        ks = np.flatnonzero(np.diff(g) != 0) + 1
        assert len(ks) >= 2
        for k in ks:
            assert v[k - 1] == 0.0 and v[k] == 0.0  # truly at rest
            assert tr["decel_cmd"][k - 1] < 0.0  # shifted under a stop-and-hold request
        # between the first engagement and the final park the gear never visits 0
        inner = g[ks[0] : ks[-1]]
        assert np.all(inner != 0)


def test_motion_follows_the_gear_and_stays_at_parking_speed(park_in, park_out):
    for tr in (park_in, park_out):
        v, g = tr["truth_vx"], tr["gear"]
        assert np.all(v * g >= 0.0)  # forward in D, backward in R
        assert np.all(v[g == 0] == 0.0)  # park only at rest
        assert np.max(np.abs(v)) <= kmh_to_ms(3.5)
        assert np.max(np.abs(v)) >= kmh_to_ms(2.0)
    assert np.min(park_in["truth_vx"]) < 0.0 < np.max(park_in["truth_vx"])


def test_steering_also_moves_at_standstill(park_in):
    still = park_in["truth_vx"][1:] == 0.0
    rate = np.abs(np.diff(park_in["truth_steer"])) / DT
    assert np.sum(still & (rate > 100.0)) * DT > 2.0  # seconds of steering at rest
    assert np.max(np.abs(park_in["steer"])) > 0.9 * P0.geometry.steer_lock_deg


def test_autohold_pressure_appears_at_launch_without_command(park_in):
    no_cmd = (park_in["decel_cmd"] == 0.0) & (park_in["truth_vx"] == 0.0)
    assert np.any(park_in["brake_pressure"][no_cmd] >= P0.autohold.hold_bar - 1)


def test_generation_is_seeded(park_in):
    again = generate_trial("park_in_left", 1, seed=0, params=P0)
    for name in park_in.channels:
        np.testing.assert_array_equal(again[name], park_in[name])
    other = generate_trial("park_in_left", 1, seed=1, params=P0)
    assert other.n != park_in.n or not np.array_equal(other["steer"], park_in["steer"])


def test_yaw_prior_and_ratio_fit_on_a_trial(park_out):
    fit = ratio_fit(park_out, P0.geometry.wheelbase)
    assert 11.8 <= fit <= 12.4


def test_the_campaign_follows_the_vehicle_yaml():
    alt = load_vehicle_params(CONFIG_DIR / "reference_vehicle_alt.yaml")
    assert alt.geometry.wheelbase == 2.8 and alt.geometry.steer_ratio == 14.0
    assert alt.body.mass_kg == P0.body.mass_kg + 300.0
    tr = generate_trial("park_out_right", 2, seed=0, params=alt)
    assert tr.vehicle_id == "reference-alt"
    assert 13.7 <= ratio_fit(tr, alt.geometry.wheelbase) <= 14.4
    assert json.loads(tr.provenance)["vehicle_params_digest"] == alt.digest()


def test_unknown_class_is_rejected():
    with pytest.raises(ConfigError, match="park_sideways"):
        generate_trial("park_sideways", 1)


def test_the_default_campaign_has_the_papers_shape():
    """The full 16 trials (about 3 s): classes, lengths, reversals, yaw prior, ratio fit."""
    from parknss.data.trial import MANEUVER_CLASSES
    from parknss.reference.campaign import generate_campaign
    from parknss.vehicle import VehicleGeometry, yaw_rate_ref

    camp = generate_campaign(seed=0)
    assert camp.meta["synthetic"] is True and len(camp) == 16
    assert list(camp.by_class()) == list(MANEUVER_CLASSES)
    assert all([t.repetition for t in ts] == [1, 2, 3, 4] for ts in camp.by_class().values())
    assert all(LENGTH_RANGE_S[0] <= t.duration_s <= LENGTH_RANGE_S[1] for t in camp)
    assert 60 <= sum(reversals(t["gear"]) for t in camp) <= 90
    geom = VehicleGeometry.from_dict(camp.meta["vehicle_geometry"])
    w, ref = [], []
    for t in camp:
        m = moving_mask(t["vx"])
        w.append(t["yaw_rate"][m])
        ref.append(yaw_rate_ref(t["vx"][m], t["steer"][m], geom))
    w, ref = np.concatenate(w), np.concatenate(ref)
    assert 1.0 - np.sum((w - ref) ** 2) / np.sum((w - w.mean()) ** 2) >= 0.99
