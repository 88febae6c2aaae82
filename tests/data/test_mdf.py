"""MDF4 logs: channel search, 100 Hz resampling (linear / hold), crop, units, errors."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import yaml
from asammdf import MDF, Signal

from parknss.cli import main
from parknss.config import CONFIG_DIR
from parknss.data.io import import_folder, read_campaign, read_trial, write_trial
from parknss.data.mapping import ChannelMapping, ChannelSource, MdfOptions, load_mapping
from parknss.errors import ConfigError, DataError, ParknssError
from parknss.signals import DEG_PER_RAD, KMH_PER_MS, REQUIRED_CHANNELS

EXAMPLE = CONFIG_DIR / "mapping_mdf_example.yaml"
GEAR_TEXT = {"val_0": 0, "text_0": b"P", "val_1": 1, "text_1": b"R", "val_2": 2, "text_2": b"N"}
GEAR_TEXT |= {"val_3": 3, "text_3": b"D", "default": b""}
GEAR_EVENTS = ((0.0, 0), (1.234, 1), (3.0, 3), (4.005, 2))  # (time s, code): P, R, D, N
GEAR_CHANGES_S = (1.24, 3.0, 4.01)  # first grid time at/after each change


# Analytic signals in schema units (what the reader must recover), t in s.
def vx(t):
    return 1.5 * np.sin(2.0 * np.pi * t / 6.0)


def yaw(t):
    return 0.3 * np.sin(2.0 * np.pi * t / 4.0)


RAMPS: dict[str, Callable] = {  # linear in t: interpolation reproduces them exactly
    "ax": lambda t: 0.5 * t - 1.0,
    "ay": lambda t: -0.25 * t + 0.5,
    "brake_pressure": lambda t: t + 5.0,  # bar; logged in MPa
    "decel_cmd": lambda t: -2.0 + 0.1 * t,
    "torque": lambda t: 50.0 + 10.0 * t,
    "torque_cmd": lambda t: 55.0 + 10.0 * t,
    "steer_cmd": lambda t: 20.0 * t,
}


def steer(t):
    return 100.0 * np.sin(2.0 * np.pi * t / 5.0)


def _times(start: float, rate_hz: float, end: float) -> np.ndarray:
    """Sample times from ``start`` at ``rate_hz`` up to ``end`` (inclusive), s."""
    n = int(np.floor((end - start) * rate_hz + 1e-9)) + 1
    return start + np.arange(n) / rate_hz


def _sig(values, t, name: str, unit: str = "", **kw) -> Signal:
    return Signal(np.asarray(values), np.asarray(t, dtype=np.float64), name=name, unit=unit, **kw)


def field_log(path: Path, *, overrides: dict[str, list[Signal]] | None = None) -> Path:
    """A logger's MDF4 in the layout of configs/mapping_mdf_example.yaml.

    Groups (index: rate): 0 ESP 50 Hz, 1 IMU 200 Hz from t=0.237 s (starts late),
    2 BRK 50 Hz up to 5.5 s (ends early), 3 MOT 100 Hz off the grid (+5 ms), 4 STR
    100 Hz, 5 a second StrWhlAng at 10 Hz (a decoy), 6 GearPos int8 with P/R/N/D text
    at event times. ``overrides`` replaces a group's signals by name (ESP, IMU, ...).
    """
    t50, t200 = _times(0.0, 50, 6.0), _times(0.237, 200, 6.0)
    tb, tm, ts = _times(0.0, 50, 5.5), _times(0.005, 100, 5.995), _times(0.0, 100, 6.0)
    tg = np.array([e[0] for e in GEAR_EVENTS])
    groups = {
        "ESP": [
            _sig(vx(t50) * KMH_PER_MS, t50, "ESP.VehSpd", "km/h"),
            _sig(yaw(t50) * DEG_PER_RAD, t50, "ESP.YawRate", "deg/s"),
        ],
        "IMU": [
            _sig(RAMPS["ax"](t200), t200, "AccX", "m/s^2"),
            _sig(RAMPS["ay"](t200), t200, "AccY", "m/s^2"),
        ],
        "BRK": [
            _sig(RAMPS["brake_pressure"](tb) / 10.0, tb, "BRK.BrkPrs", "MPa"),
            _sig(RAMPS["decel_cmd"](tb), tb, "BRK.DecelReq", "m/s^2"),
        ],
        "MOT": [
            _sig(RAMPS["torque"](tm), tm, "MotTrq", "Nm"),
            _sig(RAMPS["torque_cmd"](tm), tm, "MotTrqReq", "Nm"),
        ],
        "STR": [
            _sig(steer(ts), ts, "StrWhlAng", "deg"),
            _sig(RAMPS["steer_cmd"](ts), ts, "StrWhlAngReq", "deg"),
        ],
        "STR2": [_sig(np.full(61, 999.0), _times(0.0, 10, 6.0), "StrWhlAng", "deg")],
        "GEAR": [
            _sig(
                np.array([e[1] for e in GEAR_EVENTS], dtype=np.int8),
                tg,
                "GearPos",
                conversion=GEAR_TEXT,
            )
        ],
    }
    groups.update(overrides or {})
    mdf = MDF(version="4.10")
    for name, signals in groups.items():
        mdf.append(signals, comment=name)
    mdf.save(path, overwrite=True)
    mdf.close()
    return path


@pytest.fixture(scope="module")
def field(tmp_path_factory) -> tuple[Path, object]:
    path = field_log(tmp_path_factory.mktemp("mdf") / "park_in_left_r1.mf4")
    return path, read_trial(path, EXAMPLE)


# ------------------------------------------------------------------------ reading


def test_channels_of_any_rate_land_on_one_100hz_grid_over_the_common_span(field):
    _, tr = field
    t = tr["t"]
    # IMU starts at 0.237 s -> first grid time 0.24 s; BRK ends at 5.5 s -> last 5.50 s.
    k = np.arange(24, 551)
    np.testing.assert_array_equal(t, k / 100.0)
    prov = json.loads(tr.provenance)
    assert prov["format"] == "mdf4" and prov["resampled_hz"] == 100.0
    assert prov["span_s"][0] == pytest.approx(0.237) and prov["span_s"][1] == pytest.approx(5.5)
    assert "AccX" in prov["start_limited_by"] and "BRK." in prov["end_limited_by"]
    assert prov["log_span_s"] == pytest.approx([0.0, 6.0])
    assert set(tr.channels) == set(REQUIRED_CHANNELS)


def test_continuous_channels_are_linear_interpolations_of_the_analytic_signal(field):
    _, tr = field
    t = tr["t"]
    for name, f in RAMPS.items():  # 200 Hz, 50 Hz and off-grid 100 Hz ramps: exact
        np.testing.assert_allclose(tr[name], f(t), rtol=0, atol=1e-9, err_msg=name)
    # 50 Hz sines: linear interpolation error <= dt^2/8 * max|f''|
    bound_vx = 0.02**2 / 8 * 1.5 * (2 * np.pi / 6) ** 2
    bound_yaw = 0.02**2 / 8 * 0.3 * (2 * np.pi / 4) ** 2
    assert np.abs(tr["vx"] - vx(t)).max() <= bound_vx + 1e-12
    assert np.abs(tr["yaw_rate"] - yaw(t)).max() <= bound_yaw + 1e-12
    assert np.abs(tr["vx"] - vx(t)).max() > 1e-7  # it really was resampled
    # steer from group 4 (100 Hz, on the grid), not the 10 Hz decoy of group 5
    np.testing.assert_allclose(tr["steer"], steer(t), rtol=0, atol=1e-9)


def test_units_are_converted_kmh_degs_mpa(field):
    path, tr = field
    t = tr["t"]
    with MDF(path) as mdf:  # the file holds km/h, deg/s, MPa
        assert mdf.get("ESP.VehSpd").unit == "km/h" and mdf.get("BRK.BrkPrs").unit == "MPa"
        assert mdf.get("ESP.VehSpd").samples.max() > 5.0
    assert np.abs(tr["vx"]).max() == pytest.approx(1.5, abs=1e-3)  # m/s
    assert np.abs(tr["yaw_rate"]).max() == pytest.approx(0.3, abs=1e-3)  # rad/s
    np.testing.assert_allclose(tr["brake_pressure"], t + 5.0, atol=1e-9)  # bar


def test_gear_is_held_never_interpolated(field):
    _, tr = field
    g, t = tr["gear"], tr["t"]
    assert set(np.unique(g)) <= {-1.0, 0.0, 1.0}
    changes = np.flatnonzero(np.diff(g)) + 1
    np.testing.assert_allclose(t[changes], GEAR_CHANGES_S, atol=1e-12)
    np.testing.assert_array_equal(g[changes], [-1.0, 1.0, 0.0])
    assert g[0] == 0.0 and np.all(g[(t >= 1.24) & (t < 3.0)] == -1.0)


def test_integer_channel_is_held_and_a_float_gear_too(tmp_path):
    path = field_log(
        tmp_path / "park_in_left_r1.mf4",
        overrides={
            "GEAR": [_sig([0.0, -1.0, 1.0, 0.0], [e[0] for e in GEAR_EVENTS], "GearPos")],
        },
    )
    m = load_mapping(EXAMPLE).model_copy(update={"gear_values": None})
    tr = read_trial(path, m)  # float-typed gear: held all the same (schema integer channel)
    changes = np.flatnonzero(np.diff(tr["gear"])) + 1
    np.testing.assert_allclose(tr["t"][changes], GEAR_CHANGES_S, atol=1e-12)
    assert set(np.unique(tr["gear"])) == {-1.0, 0.0, 1.0}


def test_file_units_are_used_without_a_mapping_unit_and_mapping_units_win(field, tmp_path):
    path, ref = field
    doc = yaml.safe_load(EXAMPLE.read_text())
    for src in doc["channels"].values():
        src.pop("unit", None)
    m = ChannelMapping.model_validate(doc)
    tr = read_trial(path, m)  # km/h, deg/s, MPa taken from the MDF channels
    for name in REQUIRED_CHANNELS:
        np.testing.assert_allclose(tr[name], ref[name], rtol=0, atol=1e-12, err_msg=name)
    no_file_units = m.model_copy(update={"mdf": MdfOptions(match="wildcard", use_file_units=False)})
    with pytest.raises(DataError, match=r"channel 'yaw_rate'.*plausible range"):
        read_trial(path, no_file_units)  # deg/s read as rad/s


def test_channel_search_modes_and_groups(field):
    path, ref = field
    base = load_mapping(EXAMPLE)
    ch = dict(base.channels)
    ch["vx"] = ChannelSource(column=r"^ESP\.Veh.pd$", unit="km/h")
    regex = {k: v for k, v in ch.items() if k in ("vx",)}
    m = base.model_copy(update={"mdf": MdfOptions(match="regex"), "channels": {**ch, **regex}})
    # regex applies to every column, so the wildcard patterns now fail: map the rest plainly
    plain = {
        k: ChannelSource(column=f"{v.column.lstrip('*')}$", unit=v.unit, group=v.group)
        for k, v in ch.items()
        if k != "vx"
    }
    m = m.model_copy(update={"channels": {**plain, "vx": ch["vx"]}})
    tr = read_trial(path, m)
    np.testing.assert_allclose(tr["vx"], ref["vx"], atol=1e-12)
    ci = base.model_copy(update={"mdf": MdfOptions(match="wildcard", case_insensitive=True)})
    ci = ci.model_copy(
        update={"channels": {**ch, "vx": ChannelSource(column="*vehspd", unit="km/h")}}
    )
    np.testing.assert_allclose(read_trial(path, ci)["vx"], ref["vx"], atol=1e-12)
    no_group = {**base.channels, "steer": ChannelSource(column="*StrWhlAng", unit="deg")}
    with pytest.raises(DataError) as exc:
        read_trial(path, base.model_copy(update={"channels": no_group}))
    msg = str(exc.value)
    assert "channel 'steer'" in msg and "matches 2 channels" in msg, msg
    assert "(group 4)" in msg and "(group 5)" in msg and "give 'group'" in msg, msg


def test_round_trip_of_a_bundled_trial_through_mdf4_is_exact(tmp_path):
    trial = read_campaign("campaigns/default")[0]
    for suffix in (".mf4", ".mdf"):
        path = write_trial(trial, tmp_path / f"x{suffix}")
        with MDF(path) as mdf:  # a real MDF4 file with schema units
            assert mdf.version.startswith("4.") and mdf.get("vx").unit == "m/s"
        back = read_trial(path)
        assert (back.id, back.maneuver, back.repetition) == (
            trial.id,
            trial.maneuver,
            trial.repetition,
        )
        assert back.vehicle_id == trial.vehicle_id and back.provenance == trial.provenance
        assert set(back.channels) == set(trial.channels)  # truth_* kept
        for name in trial.channels:
            np.testing.assert_allclose(back[name], trial[name], rtol=0, atol=1e-9, err_msg=name)


def test_import_folder_of_mf4_and_cli(field, tmp_path, capsys):
    path, ref = field
    src = tmp_path / "logs"
    src.mkdir()
    for name in ("park_in_left_r1.mf4", "park_out_right_r2.mf4"):
        (src / name).write_bytes(path.read_bytes())
    camp = import_folder(src, EXAMPLE)
    assert camp.ids == ["park_in_left_r1", "park_out_right_r2"]
    assert camp.meta["vehicle_id"] == "my_car"
    np.testing.assert_array_equal(camp[0]["vx"], ref["vx"])
    out = tmp_path / "camp"
    assert main(["campaign", "import", str(src), "--out", str(out), "--mapping", str(EXAMPLE)]) == 0
    assert len(read_campaign(out)) == 2
    assert "imported 2 trials" in capsys.readouterr().err


def test_linear_interpolation_of_gear_is_a_config_error(tmp_path):
    p = tmp_path / "m.yaml"
    p.write_text("channels: {gear: {column: Gear, interpolation: linear}}\n")
    with pytest.raises(ConfigError, match="channel 'gear': an integer channel is never"):
        load_mapping(p)


# ------------------------------------------------------------------- malformed logs


def _missing_channel(src: Path) -> Path:
    field_log(src / "park_in_left_r1.mf4", overrides={"IMU": [_sig([0.0, 1.0], [0, 6], "AccX")]})
    return EXAMPLE


def _ambiguous(src: Path) -> Path:
    field_log(src / "park_in_left_r1.mf4")
    doc = yaml.safe_load(EXAMPLE.read_text())
    del doc["channels"]["steer"]["group"]
    m = src.parent / "mapping.yaml"
    m.write_text(yaml.safe_dump(doc))
    return m


def _non_monotonic(src: Path) -> Path:
    t = _times(0.0, 50, 6.0)
    t[100], t[101] = t[101], t[100]
    esp = [
        _sig(vx(t) * KMH_PER_MS, t, "ESP.VehSpd", "km/h"),
        _sig(yaw(t) * DEG_PER_RAD, t, "ESP.YawRate", "deg/s"),
    ]
    field_log(src / "park_in_left_r1.mf4", overrides={"ESP": esp})
    return EXAMPLE


def _truncated(src: Path) -> Path:
    p = field_log(src / "park_in_left_r1.mf4")
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 2])
    return EXAMPLE


def _not_mdf(src: Path) -> Path:
    (src / "park_in_left_r1.mf4").write_bytes(b"MDF     garbage" * 40)
    return EXAMPLE


def _no_common_span(src: Path) -> Path:
    late = _times(6.5, 200, 8.0)
    imu = [
        _sig(RAMPS["ax"](late), late, "AccX", "m/s^2"),
        _sig(RAMPS["ay"](late), late, "AccY", "m/s^2"),
    ]
    field_log(src / "park_in_left_r1.mf4", overrides={"IMU": imu})
    return EXAMPLE


def _unknown_file_unit(src: Path) -> Path:
    t = _times(0.237, 200, 6.0)
    imu = [_sig(RAMPS["ax"](t), t, "AccX", "furlong/s^2"), _sig(RAMPS["ay"](t), t, "AccY", "m/s^2")]
    field_log(src / "park_in_left_r1.mf4", overrides={"IMU": imu})
    return EXAMPLE


def _gear_label(src: Path) -> Path:
    field_log(src / "park_in_left_r1.mf4")
    doc = yaml.safe_load(EXAMPLE.read_text())
    doc["gear_values"] = {"P": 0, "R": -1, "D": 1}  # N missing
    m = src.parent / "mapping.yaml"
    m.write_text(yaml.safe_dump(doc))
    return m


def _can_mapping(src: Path) -> Path:
    field_log(src / "park_in_left_r1.mf4")
    doc = yaml.safe_load(EXAMPLE.read_text())
    doc["channels"]["vx"] = {"message": "ESP", "signal": "VehSpd"}
    m = src.parent / "mapping.yaml"
    m.write_text(yaml.safe_dump(doc))
    return m


MALFORMED: dict[str, tuple[Callable[[Path], Path], tuple[str, ...]]] = {
    "missing_channel": (
        _missing_channel,
        ("channel 'ay': no MDF channel matches the wildcard pattern '*AccY'",),
    ),
    "ambiguous": (_ambiguous, ("channel 'steer': '*StrWhlAng' matches 2 channels",)),
    "non_monotonic": (
        _non_monotonic,
        ("channel 'vx' (MDF channel 'ESP.VehSpd'): non-monotonic time stamps",),
    ),
    "truncated": (_truncated, ("not a readable MDF file, corrupt or truncated",)),
    "not_mdf": (_not_mdf, ("not a readable MDF file",)),
    "no_common_span": (
        _no_common_span,
        ("channel 'ax' (MDF channel 'AccX'): starts at", "no common time span"),
    ),
    "unknown_file_unit": (
        _unknown_file_unit,
        ("channel 'ax' (MDF channel 'AccX'): unit 'furlong/s^2' in the file",),
    ),
    "gear_label": (_gear_label, ("channel 'gear'", "value 'N' at t=4.005 s is not in gear_values")),
    "can_mapping": (_can_mapping, ("channel 'vx': the mapping gives a CAN message 'ESP'",)),
}


@pytest.mark.parametrize("kind", sorted(MALFORMED))
def test_malformed_mdf_gives_one_clear_line(kind, tmp_path, capsys):
    case, fragments = MALFORMED[kind]
    src = tmp_path / "logs"
    src.mkdir()
    mapping = case(src)
    with pytest.raises(ParknssError) as exc:  # the library
        import_folder(src, mapping=mapping)
    msg = str(exc.value)
    assert "\n" not in msg and "park_in_left_r1.mf4" in msg, msg
    for frag in fragments:
        assert frag in msg, msg
    out = tmp_path / "camp"  # the CLI
    assert main(["campaign", "import", str(src), "--out", str(out), "--mapping", str(mapping)]) == 2
    captured = capsys.readouterr()
    assert captured.err == f"parknss: error: {msg}\n", captured.err
    assert captured.out == "" and not (out / "campaign.json").exists()
