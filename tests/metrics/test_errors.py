"""Open-loop error metrics on hand-built predictions with known MSEs in the paper's units."""

from __future__ import annotations

import math

import numpy as np
import pytest

from parknss.data.trial import Trial
from parknss.errors import DataError
from parknss.metrics.errors import open_loop_errors, per_trial_errors
from parknss.signals import DT, ms_to_kmh, rad_to_deg


def _trial(tid, vx, gear, yaw, truth=False):
    n = len(vx)
    ch = {
        "t": np.arange(n) * DT,
        "gear": np.asarray(gear, float),
        "vx": np.asarray(vx, float),
        "yaw_rate": np.asarray(yaw, float),
        "ax": np.zeros(n),
        "ay": np.linspace(-1, 1, n),
    }
    if truth:
        for k in ("vx", "yaw_rate", "ax", "ay"):
            ch["truth_" + k] = ch[k] + 0.01
    return Trial(tid, "park_in_left", 1, ch)


# blind zone 0.5 km/h = 0.1389 m/s: samples 0, 1 of A and 0 of B are not moving
A = _trial("a", [0.0, 0.1, 0.5, -0.5, -1.0, 0.2], [0, 1, 1, -1, -1, 1], [0, 0, 0.1, -0.1, 0.2, 0])
B = _trial("b", [0.05, -0.3, -0.3, 0.8], [-1, -1, -1, 1], [0, 0.05, 0.05, -0.2])
EV = {"a": np.array([1.0, 2.0, 0.1, 0.2, 0.3, 0.4]), "b": np.array([3.0, -0.1, 0.5, 0.2])}
EW = {"a": np.array([0.5, 0.5, 0.01, -0.02, 0.03, 0.04]), "b": np.array([1.0, 0.02, 0.0, 0.01])}
EA = {"a": np.full(6, 0.5), "b": np.full(4, -1.0)}


def _preds(trials=(A, B)):
    return {
        tr.id: {
            "vx": tr["vx"] + EV[tr.id],
            "yaw_rate": tr["yaw_rate"] + EW[tr.id],
            "ax": tr["ax"] + EA[tr.id],
            "ay": tr["ay"].copy(),
        }
        for tr in trials
    }


def _kmh2(e):
    return float(np.mean(ms_to_kmh(np.asarray(e)) ** 2))


def _degs2(e):
    return float(np.mean(rad_to_deg(np.asarray(e)) ** 2))


def test_pooled_mses_in_paper_units():
    r = open_loop_errors(_preds(), [A, B], horizon=3)
    mv_a, mv_b = [2, 3, 4, 5], [1, 2, 3]
    ev = np.concatenate([EV["a"][mv_a], EV["b"][mv_b]])
    ew = np.concatenate([EW["a"][mv_a], EW["b"][mv_b]])
    assert r.vx_mse_moving_kmh2 == pytest.approx(_kmh2(ev), rel=1e-12)
    assert r.yaw_mse_moving_degs2 == pytest.approx(_degs2(ew), rel=1e-12)
    # e.g. the single-trial value by hand: 0.1, 0.2, 0.3, 0.4 m/s -> 0.075 (m/s)² · 12.96
    assert per_trial_errors(_preds(), [A])["a"].vx_mse_moving_kmh2 == pytest.approx(0.972)
    # reverse: moving and gear -1 -> A[3], A[4], B[1], B[2]
    rv = np.array([EV["a"][3], EV["a"][4], EV["b"][1], EV["b"][2]])
    assert r.vx_mse_reverse_kmh2 == pytest.approx(_kmh2(rv), rel=1e-12)
    rw = np.array([EW["a"][3], EW["a"][4], EW["b"][1], EW["b"][2]])
    assert r.yaw_mse_reverse_degs2 == pytest.approx(_degs2(rw), rel=1e-12)
    # full: every sample, the blind-zone errors included
    all_v = np.concatenate([EV["a"], EV["b"]])
    assert r.vx_mse_full_kmh2 == pytest.approx(_kmh2(all_v), rel=1e-12)
    assert r.yaw_mse_full_degs2 == pytest.approx(_degs2(np.concatenate([EW["a"], EW["b"]])))
    # accelerations in (m/s²)²
    assert r.ax_mse_moving_ms2 == pytest.approx((4 * 0.25 + 3 * 1.0) / 7)
    assert r.ax_mse_full_ms2 == pytest.approx((6 * 0.25 + 4 * 1.0) / 10)
    assert r.ay_mse_moving_ms2 == 0.0
    # horizon 3: within = moving & index < 3 -> A[2], B[1], B[2]; beyond the rest
    wi = np.array([EV["a"][2], EV["b"][1], EV["b"][2]])
    be = np.array([EV["a"][3], EV["a"][4], EV["a"][5], EV["b"][3]])
    assert r.vx_mse_within_kmh2 == pytest.approx(_kmh2(wi), rel=1e-12)
    assert r.vx_mse_beyond_kmh2 == pytest.approx(_kmh2(be), rel=1e-12)
    assert r.counts == {"full": 10, "moving": 7, "reverse": 4, "within": 3, "beyond": 4}
    assert r.trials == ["a", "b"] and r.reference == "logged" and r.horizon == 3


def test_no_horizon_and_empty_subsets_are_nan():
    r = open_loop_errors(_preds([A]), [A])
    assert math.isnan(r.vx_mse_within_kmh2) and math.isnan(r.vx_mse_beyond_kmh2)
    assert r.counts["within"] == r.counts["beyond"] == 0
    fwd = _trial("f", [0.5, 0.6], [1, 1], [0, 0])
    exact = {"f": {k: fwd[k].copy() for k in ("vx", "yaw_rate", "ax", "ay")}}
    rf = open_loop_errors(exact, [fwd])
    assert math.isnan(rf.vx_mse_reverse_kmh2) and rf.vx_mse_moving_kmh2 == 0.0
    js = rf.to_json()
    assert js["vx_mse_reverse_kmh2"] is None and js["vx_mse_moving_kmh2"] == 0.0


def test_blind_zone_threshold_is_configurable():
    r = open_loop_errors(_preds([A]), [A], blind_zone_kmh=2.0)  # 0.556 m/s
    assert r.counts["moving"] == 1  # only |vx| = 1.0
    assert r.vx_mse_moving_kmh2 == pytest.approx(_kmh2([0.3]))


def test_truth_reference_keeps_the_logged_masks():
    At = _trial("a", A["vx"], A["gear"], A["yaw_rate"], truth=True)
    p = _preds([At])
    r = open_loop_errors(p, [At], reference="truth")
    logged = open_loop_errors(p, [At])
    assert r.reference == "truth" and r.counts == logged.counts
    assert r.vx_mse_moving_kmh2 == pytest.approx(_kmh2(EV["a"][[2, 3, 4, 5]] - 0.01), rel=1e-12)
    with pytest.raises(DataError, match="ground-truth"):
        open_loop_errors(_preds([A]), [A], reference="truth")
    with pytest.raises(DataError, match="reference"):
        open_loop_errors(_preds([A]), [A], reference="model")


def test_missing_or_malformed_predictions():
    p = _preds()
    with pytest.raises(DataError, match="no prediction for trial b"):
        open_loop_errors({"a": p["a"]}, [A, B])
    bad = {"a": {k: v for k, v in p["a"].items() if k != "ay"}}
    with pytest.raises(DataError, match="no prediction of ay"):
        open_loop_errors(bad, [A])
    short = {"a": {**p["a"], "vx": p["a"]["vx"][:-1]}}
    with pytest.raises(DataError, match="shape"):
        open_loop_errors(short, [A])
    with pytest.raises(DataError):
        open_loop_errors(p, [])


def test_logged_and_truth_errors_gives_truth_only_when_every_trial_has_it():
    from helpers.synth import make_trial
    from parknss.metrics.errors import logged_and_truth_errors, open_loop_errors

    tr = make_trial(200)
    pred = {tr.id: {ch: tr[ch] + 0.01 for ch in ("vx", "yaw_rate", "ax", "ay")}}
    logged, truth = logged_and_truth_errors(pred, [tr])
    assert truth is None  # a trial without truth_* channels
    assert logged == open_loop_errors(pred, [tr]).to_json()
