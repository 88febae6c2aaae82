"""describe_campaign: kinematic checks against exactly kinematic data, counting rules."""

from __future__ import annotations

import json

import numpy as np
import pytest

from helpers.kinematic import V_REVERSE, kinematic_trial
from parknss.data.describe import (
    describe_campaign,
    direction_changes,
    reversal_indices,
    reversals_while_moving,
)
from parknss.data.trial import Campaign, Trial
from parknss.signals import BLIND_ZONE_KMH, KMH_PER_MS
from parknss.vehicle import VehicleGeometry


def test_yaw_r2_is_one_on_exactly_kinematic_data():
    camp = Campaign([kinematic_trial(), kinematic_trial(trial_id="park_out_left_r1")])
    s = describe_campaign(camp)
    assert s.wheelbase_m == 3.0 and s.nominal_steer_ratio == 12.1
    assert abs(s.yaw_r2 - 1.0) < 1e-9
    assert abs(s.steer_ratio_fit - 12.1) < 1e-3


def test_steer_ratio_fit_recovers_known_ratio():
    s = describe_campaign(Campaign([kinematic_trial(ratio=13.5)]))
    assert abs(s.steer_ratio_fit - 13.5) < 1e-3
    assert s.yaw_r2 < 0.999  # scored against the paper's 12.1, so no longer exact


def test_recorded_geometry_is_used():
    tr = kinematic_trial(ratio=14.0, wheelbase=2.8)
    geom = VehicleGeometry(wheelbase=2.8, steer_ratio=14.0).to_dict()
    s = describe_campaign(Campaign([tr], meta={"vehicle_geometry": geom}))
    assert s.wheelbase_m == 2.8 and abs(s.yaw_r2 - 1.0) < 1e-9
    assert abs(s.steer_ratio_fit - 14.0) < 1e-3
    wrong_l = describe_campaign(Campaign([tr]))  # paper wheelbase 3.0: ratio fit biased
    assert abs(wrong_l.steer_ratio_fit - 14.0) > 0.5


@pytest.mark.parametrize(
    ("gear", "changes"),
    [
        ([0, 0, -1, -1, 0, 1, 1, -1, -1, 0, 0, 1], 3),  # R->(N)->D, D->R, R->(N)->D
        ([1, 0, 0, 1, 1], 0),  # D->N->D is no change of direction
        ([0, 0, 0], 0),
        ([-1, 1, -1, 1, -1], 4),
    ],
)
def test_direction_change_counting(gear, changes):
    assert direction_changes(np.array(gear, dtype=float)) == changes


def test_reversal_indices_and_moving_reversals():
    gear = np.array([-1, -1, 0, 0, 1, 1, -1], dtype=float)
    starts, ends = reversal_indices(gear)
    assert starts.tolist() == [1, 5] and ends.tolist() == [4, 6]
    slow = 0.9 * BLIND_ZONE_KMH / KMH_PER_MS
    vx = np.array([-0.5, 0.0, 0.0, slow, 0.0, 0.3, 0.0])
    assert reversals_while_moving(gear, vx) == 1  # D->R at 0.3 m/s; neutral creep in zone
    vx[5] = 0.0
    assert reversals_while_moving(gear, vx) == 0


def test_trial_figures_and_json(tmp_path):
    tr = kinematic_trial()
    s = describe_campaign(Campaign([tr], name="mini"))
    doc = json.loads(json.dumps(s.to_json(), allow_nan=False))
    t0 = doc["trials"][0]
    assert set(t0) >= {
        "id",
        "class",
        "length_s",
        "direction_changes",
        "blind_zone_fraction",
        "max_speed_kmh",
    }
    assert t0["id"] == "park_in_left_r1" and t0["class"] == "park_in_left"
    assert t0["length_s"] == 30.0 and t0["direction_changes"] == 1
    assert t0["max_speed_kmh"] == pytest.approx(V_REVERSE * 3.6, abs=1e-3)
    blind = np.mean(np.abs(tr["vx"]) * 3.6 < 0.5)  # independent count
    assert t0["blind_zone_fraction"] == pytest.approx(blind, abs=1e-12)
    assert doc["direction_changes"] == 1 and doc["reversals_at_standstill"] is True
    assert {"yaw_r2", "steer_ratio_fit"} <= set(doc)
    table = s.table()
    assert "park_in_left_r1" in table and "all at standstill" in table


def test_reversal_while_moving_is_reported():
    tr = kinematic_trial()
    gear = np.where(tr["t"] < 6.0, -1.0, 1.0)  # shifted to D in the middle of the reverse arc
    bad = Trial(tr.id, tr.maneuver, 1, {**tr.channels, "gear": gear})
    s = describe_campaign(Campaign([bad]))
    assert s.to_json()["reversals_while_moving"] == 1
    assert s.to_json()["reversals_at_standstill"] is False
    assert "1 NOT at standstill" in s.table()


def test_no_motion_gives_undefined_checks():
    tr = kinematic_trial()
    still = Trial(tr.id, tr.maneuver, 1, {**tr.channels, "vx": np.zeros(tr.n)})
    doc = describe_campaign(Campaign([still])).to_json()
    assert doc["yaw_r2"] is None and doc["steer_ratio_fit"] is None
    assert doc["trials"][0]["blind_zone_fraction"] == 1.0
    json.dumps(doc, allow_nan=False)
