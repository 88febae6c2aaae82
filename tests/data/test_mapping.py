"""The mapping vocabulary and the time rules: transforms, absent channels, sentinels, gaps,
crop windows, resampling of every table format, unlabelled trials, and their refusals."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from helpers.kinematic import kinematic_trial
from parknss.cli import main
from parknss.data.io import import_folder, read_campaign, read_trial, read_trials, write_campaign
from parknss.data.mapping import ChannelMapping, load_mapping
from parknss.data.trial import UNLABELLED, Trial
from parknss.errors import ConfigError, DataError
from parknss.signals import (
    DEG_PER_RAD,
    KMH_PER_MS,
    REQUIRED_CHANNELS,
    canonical_unit,
    convert_to_schema,
)

COMMANDS = ("torque_cmd", "decel_cmd", "steer_cmd")


def _write(path: Path, cols: dict[str, np.ndarray | list]) -> Path:
    """A plain CSV log (no parknss metadata), full precision."""
    pd.DataFrame(cols).to_csv(path, index=False, float_format="%.17g")
    return path


def _mapping(path: Path, doc: dict) -> Path:
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _schema_cols(tr: Trial, drop: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    return {c: tr[c] for c in REQUIRED_CHANNELS if c not in drop}


# ------------------------------------------------------------------ units


@pytest.mark.parametrize(
    ("spelling", "canon"),
    [("Bar", "bar"), ("Deg", "deg"), ("kph", "km/h"), ("KM/H", "km/h"), ("deg/s", "deg/s"),
     ("°/s", "deg/s"), ("rad/s", "rad/s"), ("g", "g"), ("G", "g"), ("m/s^2", "m/s^2"),
     ("m/s²", "m/s^2"), ("m/s2", "m/s^2"), ("Nm", "N*m"), ("N m", "N*m"), ("µs", "us"),
     ("ms", "ms"), ("MPa", "MPa"), ("psi", "psi"), ("", "-")],
)
def test_unit_spellings_are_case_insensitive_aliases(spelling, canon):
    assert canonical_unit(spelling) == canon


def test_unit_conversions_known_values():
    assert convert_to_schema(np.array([36.0]), "KPH", "vx")[0] == pytest.approx(10.0)
    assert convert_to_schema(np.array([180.0]), "Deg/s", "yaw_rate")[0] == pytest.approx(np.pi)
    assert convert_to_schema(np.array([1.0]), "Bar", "brake_pressure")[0] == 1.0
    assert convert_to_schema(np.array([1.0]), "psi", "brake_pressure")[0] == pytest.approx(
        0.0689475729
    )
    assert convert_to_schema(np.array([2.0e6]), "us", "t")[0] == pytest.approx(2.0)
    assert canonical_unit("furlong") is None


# ------------------------------------------------------------------ absent, constant


def test_absent_commands_are_left_out_and_survive_the_campaign_round_trip(trial, tmp_path):
    logs = tmp_path / "logs"
    logs.mkdir()
    _write(logs / "park_in_left_r1.csv", _schema_cols(trial, COMMANDS))
    m = _mapping(tmp_path / "m.yaml", {"channels": {c: "absent" for c in COMMANDS}})
    camp = import_folder(logs, m)
    tr = camp[0]
    assert not set(COMMANDS) & set(tr.channels)
    assert camp.meta["absent_channels"] == list(COMMANDS)
    back = read_campaign(write_campaign(camp, tmp_path / "camp"))
    assert set(back[0].channels) == set(tr.channels)
    np.testing.assert_array_equal(back[0]["vx"], trial["vx"])


def test_a_missing_channel_not_declared_absent_is_one_line_naming_the_fix(trial, tmp_path):
    _write(tmp_path / "park_in_left_r1.csv", _schema_cols(trial, COMMANDS))
    with pytest.raises(DataError) as exc:
        read_trial(tmp_path / "park_in_left_r1.csv")
    msg = str(exc.value)
    assert "channel 'torque_cmd': missing (3 channels missing" in msg
    assert "declare it 'torque_cmd: absent'" in msg and "\n" not in msg


def test_constant_channel_in_its_unit(trial, tmp_path):
    f = _write(tmp_path / "park_in_left_r1.csv", _schema_cols(trial, ("decel_cmd",)))
    m = ChannelMapping.model_validate({"channels": {"decel_cmd": {"constant": -0.1, "unit": "g"}}})
    tr = read_trial(f, m)
    np.testing.assert_allclose(tr["decel_cmd"], -0.980665)


# ------------------------------------------------------------------ transforms


def test_raw_counts_unsigned_speed_gear_letters_wheel_mean_and_angle_sum(trial, tmp_path):
    """The transforms a real car needs, each recovering the schema signal exactly."""
    letters = np.where(trial["gear"] < 0, "R", np.where(trial["gear"] > 0, "D", "P"))
    speed_kmh = np.abs(trial["vx"]) * KMH_PER_MS
    wheel_offsets = (-0.02, 0.01, 0.03, -0.02)  # the mean of the four is the vehicle speed
    steer_coarse = np.round(trial["steer"] / 10.0) * 10.0
    cols = {
        "time_ms": trial["t"] * 1000.0,
        "Gear": letters,
        "BrkPrsRaw": trial["brake_pressure"] / 0.05 + 100.0,  # counts: 0.05 bar/count, offset
        "StrCoarse": steer_coarse,
        "StrFine": trial["steer"] - steer_coarse,
        **{f"WhlSpd{i}": speed_kmh + o for i, o in enumerate(wheel_offsets)},
        **{c: trial[c] for c in ("torque_cmd", "torque", "decel_cmd", "steer_cmd", "ax", "ay")},
        "YawRateCW": -trial["yaw_rate"] * DEG_PER_RAD,
    }
    f = _write(tmp_path / "park_in_left_r1.csv", cols)
    doc = {
        "time": {"column": "time_ms", "unit": "MS"},
        "channels": {
            "gear": {"column": "Gear", "values": {"P": 0, "R": -1, "N": 0, "D": 1}},
            "brake_pressure": {"column": "BrkPrsRaw", "scale": 0.05, "offset": -5.0,
                               "unit": "Bar"},
            "steer": {"sources": [{"column": "StrCoarse"}, {"column": "StrFine"}],
                      "combine": "sum", "unit": "Deg"},
            "vx": {"sources": [{"column": f"WhlSpd{i}"} for i in range(4)], "combine": "mean",
                   "unit": "kph", "sign_from_gear": True},
            "yaw_rate": {"column": "YawRateCW", "unit": "deg/s", "invert": True},
        },
    }
    tr = read_trial(f, _mapping(tmp_path / "m.yaml", doc))
    for name in REQUIRED_CHANNELS:
        np.testing.assert_allclose(tr[name], trial[name], rtol=0, atol=1e-9, err_msg=name)


def test_clip_is_a_counted_clamp(trial, tmp_path):
    f = _write(tmp_path / "park_in_left_r1.csv", _schema_cols(trial))
    m = ChannelMapping.model_validate({"channels": {"steer": {"column": "steer",
                                                              "clip": [-300, 300]}}})
    tr = read_trial(f, m)
    assert tr["steer"].max() == 300.0 and tr["steer"].min() == -300.0
    n = int(np.count_nonzero(np.abs(trial["steer"]) > 300.0))
    assert n > 0 and json.loads(tr.provenance)["clipped_samples"] == {"steer": n}


# ------------------------------------------------------------------ invalid samples


def _with_startup_sentinels(trial: Trial, n: int = 150) -> dict[str, np.ndarray]:
    cols = _schema_cols(trial)
    steer = trial["steer"].copy()
    steer[:n] = 3276.7  # the sensor's start-up value, like the Kona's steering angle
    cols["steer"] = steer
    return cols


def test_startup_sentinels_unmasked_fail_the_range_check_naming_the_channel(trial, tmp_path):
    f = _write(tmp_path / "park_in_left_r1.csv", _with_startup_sentinels(trial))
    with pytest.raises(DataError, match=r"channel 'steer': 150 values outside the plausible"):
        read_trial(f)


def test_masked_startup_sentinels_crop_the_start(trial, tmp_path):
    f = _write(tmp_path / "park_in_left_r1.csv", _with_startup_sentinels(trial))
    m = ChannelMapping.model_validate({"channels": {"steer": {"column": "steer",
                                                              "invalid": [3276.7]}}})
    tr = read_trial(f, m)
    assert tr["t"][0] == pytest.approx(1.50)  # the first valid steering sample
    np.testing.assert_allclose(tr["steer"], trial["steer"][150:], atol=1e-9)
    prov = json.loads(tr.provenance)
    assert prov["masked_samples"] == {"channel 'steer'": 150}
    assert prov["start_limited_by"] == "channel 'steer'"


def test_an_interior_sentinel_is_bridged_when_short_and_a_gap_when_long(trial, tmp_path):
    cols = _schema_cols(trial)
    short = cols["yaw_rate"].copy()
    short[1000:1010] = 40.96  # 0.1 s of sentinel
    f = _write(tmp_path / "park_in_left_r1.csv", {**cols, "yaw_rate": short})
    m = {"channels": {"yaw_rate": {"column": "yaw_rate", "invalid": [40.96]}}}
    tr = read_trial(f, ChannelMapping.model_validate(m))
    assert tr.n == trial.n  # linear interpolation over the masked 0.1 s
    lin = np.interp(trial["t"][1000:1010], trial["t"][[999, 1010]], trial["yaw_rate"][[999, 1010]])
    np.testing.assert_allclose(tr["yaw_rate"][1000:1010], lin, atol=1e-12)
    long = cols["yaw_rate"].copy()
    long[1000:1100] = 40.96  # 1 s: longer than resample.max_gap_s
    f2 = _write(tmp_path / "park_in_left_r2.csv", {**cols, "yaw_rate": long})
    with pytest.raises(DataError) as exc:
        read_trial(f2, ChannelMapping.model_validate(m))
    msg = str(exc.value)
    assert "channel 'yaw_rate': no sample for 1.010 s from t=9.990 s" in msg
    assert "resample.on_gap: split" in msg and "channels.yaw_rate.max_gap_s" in msg
    split = {**m, "resample": {"on_gap": "split", "min_segment_s": 1.0}}
    parts = read_trials(f2, ChannelMapping.model_validate(split))
    assert [p.id for p in parts] == ["park_in_left_r2_s1", "park_in_left_r2_s2"]
    assert parts[0]["t"][-1] == pytest.approx(9.99) and parts[1]["t"][0] == pytest.approx(11.0)
    with pytest.raises(DataError, match="splits into 2 trials"):
        read_trial(f2, ChannelMapping.model_validate(split))


def test_crop_on_invalid_keeps_the_longest_clean_stretch(trial, tmp_path):
    cols = _schema_cols(trial)
    ay = cols["ay"].copy()
    ay[800] = np.nan  # one bad sample at 8 s (an empty field); the longer part is after it
    f = _write(tmp_path / "park_in_left_r1.csv", {**cols, "ay": ay})
    with pytest.raises(DataError, match=r"channel 'ay': empty value at line 802"):
        read_trial(f)
    m = {"channels": {"ay": {"column": "ay", "invalid": [""], "on_invalid": "crop"}}}
    tr = read_trial(f, ChannelMapping.model_validate(m))
    assert tr["t"][0] == pytest.approx(8.01) and tr["t"][-1] == pytest.approx(trial["t"][-1])


def test_nan_listed_as_invalid_is_masked(trial, tmp_path):
    cols = _schema_cols(trial)
    ax = cols["ax"].copy()
    ax[500] = np.nan
    pd.DataFrame({**cols, "ax": ax}).to_parquet(tmp_path / "park_in_left_r1.parquet")
    with pytest.raises(DataError, match=r"channel 'ax': 1 NaN values .*channels.ax.invalid"):
        read_trial(tmp_path / "park_in_left_r1.parquet")
    m = {"channels": {"ax": {"column": "ax", "invalid": [".nan"]}}}
    tr = read_trial(tmp_path / "park_in_left_r1.parquet", ChannelMapping.model_validate(m))
    assert tr.n == trial.n and np.isfinite(tr["ax"]).all()


def test_valid_range_masks_like_a_sentinel(trial, tmp_path):
    f = _write(tmp_path / "park_in_left_r1.csv", _with_startup_sentinels(trial, 20))
    m = ChannelMapping.model_validate({"channels": {"steer": {"column": "steer",
                                                              "valid_range": [-780, 780]}}})
    assert read_trial(f, m)["t"][0] == pytest.approx(0.20)


# ------------------------------------------------------------------ time


def test_jittered_97hz_clock_in_ms_is_resampled_onto_the_100hz_grid(tmp_path):
    rng = np.random.default_rng(0)
    dt = 1.0 / 97.0
    t = np.arange(round(30.0 / dt)) * dt
    t = t + rng.uniform(-0.01, 0.01, len(t)) * dt  # 1 % clock jitter
    ref = kinematic_trial()

    def at(name):  # the smooth reference signals at the jittered times
        return np.interp(t, ref["t"], ref[name])

    cols = {"t": t * 1000.0, **{c: at(c) for c in REQUIRED_CHANNELS if c != "t"}}
    cols["gear"] = np.round(cols["gear"])
    f = _write(tmp_path / "park_in_left_r1.csv", cols)
    tr = read_trial(f, ChannelMapping.model_validate({"time": {"unit": "ms"}}))
    prov = json.loads(tr.provenance)
    assert prov["resampled"] is True and prov["source_rate_hz"] == pytest.approx(97.0, rel=0.01)
    np.testing.assert_allclose(np.diff(tr["t"]), 0.01, atol=1e-12)
    k = np.round(tr["t"] * 100).astype(int)
    for name in ("vx", "steer", "yaw_rate"):  # piecewise-linear error of a smooth signal
        scale = np.abs(ref[name]).max()
        assert np.abs(tr[name] - ref[name][k]).max() < 2e-3 * scale, name
    assert set(np.unique(tr["gear"])) <= {-1.0, 0.0, 1.0}  # held, never interpolated


def test_a_log_at_100hz_is_taken_row_for_row(trial, tmp_path):
    f = _write(tmp_path / "park_in_left_r1.csv", _schema_cols(trial))
    tr = read_trial(f)
    assert json.loads(tr.provenance)["resampled"] is False
    for name in REQUIRED_CHANNELS:
        np.testing.assert_array_equal(tr[name], trial[name])


def test_50hz_parquet_and_us_time_are_resampled(trial, tmp_path):
    cols = {c: trial[c][::2] for c in REQUIRED_CHANNELS}
    cols["t"] = cols["t"] * 1.0e6
    pd.DataFrame(cols).to_parquet(tmp_path / "park_in_left_r1.parquet")
    tr = read_trial(tmp_path / "park_in_left_r1.parquet",
                    ChannelMapping.model_validate({"time": {"unit": "µs"}}))
    assert tr.n == trial.n - 1  # 0 .. 29.98 s
    np.testing.assert_allclose(tr["vx"], trial["vx"][: tr.n], atol=2e-4)


def test_crop_window_in_mapping_and_manifest(trial, tmp_path):
    logs = tmp_path / "logs"
    logs.mkdir()
    _write(logs / "a.csv", _schema_cols(trial))
    _write(logs / "b.csv", _schema_cols(trial))
    (logs / "manifest.csv").write_text(
        "file,class,repetition,start_s,end_s\na.csv,park_in_left,1,2.5,20\nb.csv,,,,\n"
    )
    camp = import_folder(logs)
    a, b = camp["park_in_left_r1"], camp["b"]
    assert a["t"][0] == pytest.approx(2.5) and a["t"][-1] == pytest.approx(20.0)
    assert b.n == trial.n and b.maneuver == UNLABELLED
    m = ChannelMapping.model_validate({"time": {"crop": [1.0, 3.0], "start_at_zero": True}})
    tr = read_trial(logs / "a.csv", m)
    assert tr["t"][0] == 0.0 and tr.n == 201


# ------------------------------------------------------------------ unlabelled


def test_unlabelled_files_import_with_their_stems(trial, tmp_path, capsys):
    logs = tmp_path / "logs"
    logs.mkdir()
    for name in ("drive 2023-01-12.csv", "recording_0042.csv"):
        _write(logs / name, _schema_cols(trial))
    camp = import_folder(logs)
    assert camp.ids == ["drive_2023-01-12", "recording_0042"]
    assert [tr.maneuver for tr in camp] == [UNLABELLED] * 2
    assert [tr.repetition for tr in camp] == [1, 2]
    assert camp.meta["unlabelled_trials"] == 2
    assert main(["campaign", "import", str(logs), "--out", str(tmp_path / "c")]) == 0


# ------------------------------------------------------------------ refusals


@pytest.mark.parametrize(
    ("channels", "expected"),
    [
        ({"vx": {"column": "a", "message": "M", "signal": "S"}}, "not both"),
        ({"vx": {"column": "a", "absent": True}}, "give one of"),
        ({"vx": {"sources": [{"column": "a"}, {"column": "b"}]}}, "need 'combine"),
        ({"vx": {"column": "a", "clip": [2, 1]}}, "'clip' needs [lo, hi]"),
        ({"vx": {"column": "a", "scale": 0}}, "'scale' must be"),
        ({"vx": {"column": "a", "unit": "furlong"}}, "unknown unit 'furlong'"),
        ({"gear": {"column": "g", "unit": "km/h"}}, "gear takes no unit"),
        ({"gear": {"constant": 2}}, "constant 2 is not -1, 0 or 1"),
        ({"gear": "absent", "vx": {"column": "v", "sign_from_gear": True}}, "sign_from_gear"),
        ({"vx": {"column": "a", "on_invalid": "repair"}}, "on_invalid"),
        ({c: "absent" for c in REQUIRED_CHANNELS if c != "t"}, "every channel is declared"),
    ],
)
def test_mapping_refusals_are_one_line(channels, expected, tmp_path):
    m = _mapping(tmp_path / "m.yaml", {"channels": channels})
    with pytest.raises(ConfigError) as exc:
        load_mapping(m)
    assert expected in str(exc.value) and "\n" not in str(exc.value)


def test_unmapped_text_code_and_text_without_a_map_name_the_fix(trial, tmp_path):
    letters = np.where(trial["gear"] < 0, "R", np.where(trial["gear"] > 0, "S", "P"))
    f = _write(tmp_path / "park_in_left_r1.csv", {**_schema_cols(trial), "gear": letters})
    with pytest.raises(DataError, match=r"channel 'gear': non-numeric value 'P' at line 2"):
        read_trial(f)
    m = ChannelMapping.model_validate({"gear_values": {"P": 0, "R": -1, "D": 1}})
    with pytest.raises(DataError, match=r"value 'S' at line \d+ is not in gear_values \(P, R, D\)"):
        read_trial(f, m)
