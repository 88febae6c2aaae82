"""campaign describe: channel flags (all-zero, constant, out of range, sentinel, clipped),
the parking-speed domain, workflows, and campaigns lacking channels."""

from __future__ import annotations

import json

import numpy as np
import pytest

from helpers.kinematic import V_REVERSE, kinematic_trial
from helpers.synth import drop
from parknss.cli import main
from parknss.data.describe import (
    DescribeConfig,
    channel_flags,
    describe_campaign,
    load_describe_config,
)
from parknss.data.trial import Campaign, Trial
from parknss.errors import DataError
from parknss.signals import DEG_PER_RAD, DT, REQUIRED_CHANNELS

CFG = DescribeConfig()


def with_channels(**changes) -> Trial:
    tr = kinematic_trial()
    return Trial(tr.id, tr.maneuver, 1, {**tr.channels, **changes})


def flags_of(tr: Trial, cfg: DescribeConfig = CFG) -> dict[tuple[str, str], object]:
    s = describe_campaign(Campaign([tr]), config=cfg)
    return {(f.channel, f.kind): f for f in s.trials[0].flags}


def test_a_clean_trial_has_no_flags_and_the_yaml_matches_the_defaults():
    assert flags_of(kinematic_trial()) == {}
    assert load_describe_config() == DescribeConfig()


def test_all_zero_and_constant_channels():
    n = kinematic_trial().n
    flags = flags_of(with_channels(ay=np.zeros(n), steer_cmd=np.full(n, 12.5)))
    assert set(flags) == {("ay", "all_zero"), ("steer_cmd", "constant")}
    assert flags["ay", "all_zero"].samples == n
    assert flags["steer_cmd", "constant"].value == 12.5
    # a gear held in one position is normal driving; a gear at 0 throughout is flagged
    assert flags_of(with_channels(gear=np.ones(n))) == {}
    assert set(flags_of(with_channels(gear=np.zeros(n)))) == {("gear", "all_zero")}
    loose = DescribeConfig(constant_tolerance=1.0)
    wobble = 12.5 + 0.1 * np.sin(np.arange(n))
    assert ("steer_cmd", "constant") in flags_of(with_channels(steer_cmd=wobble), loose)
    assert ("steer_cmd", "constant") not in flags_of(with_channels(steer_cmd=wobble))


def test_sentinel_value_repeated_far_from_the_rest():
    tr = kinematic_trial()
    yaw = tr["yaw_rate"].copy()
    code = 40.96 / DEG_PER_RAD  # a yaw-rate signal's largest raw value, in rad/s
    yaw[1000:1050] = code
    flags = flags_of(with_channels(yaw_rate=yaw))
    f = flags["yaw_rate", "sentinel"]
    assert set(flags) == {("yaw_rate", "sentinel")}  # not also "clipped"
    assert f.value == code and f.side == "max" and f.samples == 50
    assert f.longest_run_s == pytest.approx(50 * DT)
    assert "sentinel-like" in f.detail
    # config-driven: a longer required run turns it into nothing (runs are 50 samples)
    strict = DescribeConfig(sentinel_min_run=60, clip_min_run=60)
    assert flags_of(with_channels(yaw_rate=yaw), strict) == {}
    # a value not far from the rest is no sentinel; held 0.5 s at the max, it is clipping
    near = flags_of(with_channels(yaw_rate=yaw), DescribeConfig(sentinel_gap_ratio=50.0))
    assert set(near) == {("yaw_rate", "clipped")} and near["yaw_rate", "clipped"].samples == 50


def test_invalid_value_code_beyond_the_plausible_range():
    steer = kinematic_trial()["steer"].copy()
    steer[200:220] = 3276.7  # 0x7FFF * 0.1 deg: "signal not available"
    flags = flags_of(with_channels(steer=steer))
    assert flags["steer", "out_of_range"].samples == 20
    assert flags["steer", "out_of_range"].value == 3276.7
    assert flags["steer", "sentinel"].value == 3276.7


def test_clipped_signal_pinned_at_its_extremes():
    tr = kinematic_trial()
    vx = np.clip(tr["vx"], -0.6, 0.5)  # the arcs peak at -0.8 and +0.7 m/s
    s = describe_campaign(Campaign([with_channels(vx=vx)]))
    clipped = s.trials[0].flags
    assert {(f.channel, f.kind, f.side, f.value) for f in clipped} == {
        ("vx", "clipped", "max", 0.5),
        ("vx", "clipped", "min", -0.6),
    }
    top = next(f for f in clipped if f.side == "max")
    assert top.samples == int(np.sum(vx == 0.5)) and top.longest_run_s >= CFG.clip_min_run * DT
    # a signal resting at 0 is not clipped, and only the configured channels are checked
    steer_pos = np.maximum(tr["steer"], 0.0)
    assert flags_of(with_channels(steer=steer_pos)) == {}
    torque = np.minimum(tr["torque"], 50.0)
    assert flags_of(with_channels(torque=torque)) == {}
    assert ("torque", "clipped") in flags_of(
        with_channels(torque=torque), DescribeConfig(clip_channels=("torque",))
    )


def test_channel_flags_directly_and_config_validation():
    x = np.r_[np.linspace(-1.0, 1.0, 200), np.full(30, 1.0)]
    assert [f.kind for f in channel_flags("ax", x, CFG, {})] == ["clipped"]
    assert channel_flags("ax", x, DescribeConfig(clip_channels=()), {}) == []
    with pytest.raises(ValueError, match="speed"):
        DescribeConfig(clip_channels=("speed",))


def test_parking_speed_domain():
    fast = with_channels(vx=kinematic_trial()["vx"] * 10.0)  # 8 m/s = 28.8 km/h reverse peak
    s = describe_campaign(Campaign([kinematic_trial(), fast]))
    assert [t.outside_parking_domain for t in s.trials] == [False, True]
    doc = s.to_json()
    assert doc["outside_parking_domain"] == [fast.id] and doc["parking_speed_max_kmh"] == 20.0
    assert "1 trial(s) outside" in s.table()
    wide = describe_campaign(Campaign([fast]), config=DescribeConfig(parking_speed_max_kmh=40.0))
    assert wide.outside_parking_domain == [] and "all 1 trials inside" in wide.table()


def test_campaign_without_steer_and_commands():
    camp = drop(Campaign([kinematic_trial()], name="nosteer"), ("torque_cmd", "steer"))
    s = describe_campaign(camp)
    doc = json.loads(json.dumps(s.to_json(), allow_nan=False))
    assert doc["yaw_r2"] is None and doc["steer_ratio_fit"] is None
    assert doc["unavailable"]["yaw_r2"] == "needs vx, steer, yaw_rate; the campaign lacks steer"
    assert doc["direction_changes"] == 1 and doc["reversals_at_standstill"] is True
    assert doc["trials"][0]["max_speed_kmh"] == pytest.approx(V_REVERSE * 3.6, abs=1e-3)
    assert doc["absent_channels"] == ["torque_cmd", "steer"]
    assert doc["channels"] == [c for c in REQUIRED_CHANNELS if c not in ("torque_cmd", "steer")]
    assert doc["workflows"]["nss"] == {
        "ok": False,
        "missing": ["steer"],
        "needs": ["gear", "torque", "brake_pressure", "steer", "vx", "yaw_rate", "ax", "ay"],
        "reason": "lacks steer",
    }
    assert doc["workflows"]["actuators"]["missing"] == ["torque_cmd", "steer"]
    table = s.table()
    assert "absent: torque_cmd, steer" in table and "yaw R²" in table
    assert "n/a (needs vx, steer, yaw_rate; the campaign lacks steer)" in table
    assert "nss          no" in table


def test_campaign_without_vx_or_gear():
    camp = drop(Campaign([kinematic_trial()]), ("vx", "gear"))
    s = describe_campaign(camp)
    t = s.to_json()["trials"][0]
    for key in (
        "direction_changes",
        "blind_zone_fraction",
        "max_speed_kmh",
        "reversals_while_moving",
        "outside_parking_domain",
    ):
        assert t[key] is None
    doc = s.to_json()
    assert doc["blind_zone_fraction"] is None and doc["moving_samples"] is None
    assert doc["reversals_at_standstill"] is None and doc["direction_changes"] is None
    assert set(doc["unavailable"]) >= {"max_speed_kmh", "direction_changes", "yaw_r2"}
    assert "n/a" in s.table() and "parking-speed domain (max |vx| <= 20 km/h): n/a" in s.table()
    json.dumps(doc, allow_nan=False)


def test_inconsistent_campaign_is_refused():
    a = kinematic_trial()
    b = drop(Campaign([kinematic_trial(trial_id="park_out_left_r1")]), ("ay",))[0]
    with pytest.raises(DataError, match="trial 'park_out_left_r1' lacks ay"):
        describe_campaign(Campaign([a, b]))


def test_describe_cli_json_on_a_campaign_without_commands(monkeypatch, capsys):
    camp = drop(
        Campaign([kinematic_trial(), kinematic_trial(trial_id="park_out_left_r1")], name="cmdless"),
        ("torque_cmd", "decel_cmd", "steer_cmd"),
    )
    monkeypatch.setattr("parknss.data.io.read_campaign", lambda path: camp)
    assert main(["campaign", "describe", "somewhere", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["workflows"]["nss"]["ok"] is True
    assert doc["workflows"]["actuators"]["reason"] == "lacks torque_cmd, decel_cmd, steer_cmd"
    assert doc["yaw_r2"] == pytest.approx(1.0, abs=1e-9)
    assert doc["folds"]["stratified"] is False  # 2 trials cannot make 4 folds
    assert main(["campaign", "describe", "somewhere"]) == 0
    text = capsys.readouterr().out
    assert "actuators    no   lacks torque_cmd, decel_cmd, steer_cmd" in text
    assert "channel flags: none" in text
