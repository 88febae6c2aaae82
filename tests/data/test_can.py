"""CAN logs (.blf, .asc) with a DBC: decoding, zero-order hold on 100 Hz, units, errors."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import can
import cantools
import numpy as np
import pytest
import yaml

from helpers.candrive import (
    EPOCH,
    EXAMPLE,
    GEAR_CHANGES_S,
    SIGNALS,
    frame_times,
    frames,
    setup_logs,
    vehicle_dbc,
    write_log,
)
from parknss.cli import main
from parknss.data.describe import describe_campaign
from parknss.data.io import import_folder, read_campaign, read_trial, write_trial
from parknss.data.mapping import load_mapping, resolve_dbc
from parknss.errors import ConfigError, DataError, ParknssError
from parknss.signals import REQUIRED_CHANNELS


@pytest.fixture(scope="module", params=[".blf", ".asc"])
def drive(request, tmp_path_factory):
    folder = tmp_path_factory.mktemp("can") / "logs"
    mapping = setup_logs(folder, request.param)
    return read_trial(folder / f"park_in_left_r1{request.param}", mapping)


def _held(name: str, t: np.ndarray) -> np.ndarray:
    """The value of the last frame at or before each t (what a ZOH must give), schema units."""
    msg, sig, f, factor = SIGNALS[name]
    ft = frame_times(msg)
    db = vehicle_dbc()
    m = db.get_message_by_name(msg)
    quantized = np.array(
        [
            m.decode(m.encode({s.name: 0.0 for s in m.signals} | {sig: f(x) * factor}))[sig]
            for x in ft
        ]
    )
    idx = np.searchsorted(ft, t + 1e-6, side="right") - 1
    return quantized[idx] / factor


# ------------------------------------------------------------------------ reading


def test_signals_are_decoded_and_held_on_the_100hz_grid(drive):
    tr = drive
    t = tr["t"]
    # BRK's first frame at 0.237 s: every signal received once from 0.24 s; BRK's last
    # frame (0.237 + 115 * 0.05 = 5.987 s) ends it: nothing is held past a signal's end.
    np.testing.assert_array_equal(t, np.arange(24, 599) / 100.0)
    assert set(tr.channels) == set(REQUIRED_CHANNELS)
    for name in SIGNALS:
        np.testing.assert_allclose(tr[name], _held(name, t), rtol=0, atol=1e-9, err_msg=name)
    # held, not interpolated: only values that were sent (MOT frames are 5 ms off the grid)
    for name in ("torque", "ax", "brake_pressure"):
        sent = _held(name, frame_times(SIGNALS[name][0]) + 1e-9)
        assert set(np.round(tr[name], 9)) <= set(np.round(sent, 9)), name
    prov = json.loads(tr.provenance)
    assert "'BRK'" in prov["start_limited_by"] and prov["span_s"][0] == pytest.approx(0.237)
    assert "'BRK'" in prov["end_limited_by"] and prov["span_s"][1] == pytest.approx(5.987)
    assert prov["dbc"].endswith("vehicle.dbc") and prov["format"] in ("blf", "asc")


def test_units_converted_from_the_dbc_and_the_mapping(drive):
    t = drive["t"]
    # km/h (mapping), deg/s (DBC), MPa (DBC) -> m/s, rad/s, bar
    np.testing.assert_allclose(drive["vx"], 1.5 * np.sin(2 * np.pi * t / 6), atol=0.02)
    np.testing.assert_allclose(drive["yaw_rate"], 0.3 * np.sin(2 * np.pi * t / 4), atol=0.01)
    np.testing.assert_allclose(drive["brake_pressure"], t + 5.0, atol=0.05 + 0.01)
    assert np.abs(drive["vx"]).max() < 1.51  # not km/h


def test_gear_labels_are_held_and_mapped(drive):
    g, t = drive["gear"], drive["t"]
    assert set(np.unique(g)) <= {-1.0, 0.0, 1.0}
    changes = np.flatnonzero(np.diff(g)) + 1
    np.testing.assert_allclose(t[changes], GEAR_CHANGES_S, atol=1e-12)  # 3.0 s exactly too
    np.testing.assert_array_equal(g[changes], [-1.0, 1.0, 0.0])
    assert g[-1] == 0.0  # the last event (4.005 s) is held to the end, not a crop


def test_bus_channel_filter_and_start_at_zero(tmp_path):
    db = vehicle_dbc()
    msgs = frames(db)
    noise = [
        can.Message(
            timestamp=m.timestamp,
            arbitration_id=m.arbitration_id,
            is_extended_id=m.is_extended_id,
            data=bytes(8),
            channel=1,
        )
        for m in msgs
        if m.arbitration_id == 0x100
    ]
    both = sorted(msgs + noise, key=lambda m: m.timestamp)
    mapping = setup_logs(tmp_path / "logs", ".blf", both)
    doc = yaml.safe_load(mapping.read_text())
    doc["can"]["bus_channel"] = 0
    doc["time"] = {"start_at_zero": True}
    mapping.write_text(yaml.safe_dump(doc))
    tr = read_trial(tmp_path / "logs" / "park_in_left_r1.blf", mapping)
    assert tr["t"][0] == 0.0 and tr["t"][-1] == pytest.approx(5.74)
    assert np.abs(tr["vx"]).max() > 1.4  # channel 1's zero frames were not mixed in


def test_import_folder_of_blf_and_asc_and_cli(tmp_path, capsys):
    src = tmp_path / "logs"
    mapping = setup_logs(src, ".blf")
    write_log(src / "park_out_left_r2.asc", frames(vehicle_dbc()))
    camp = import_folder(src, mapping)
    assert camp.ids == ["park_in_left_r1", "park_out_left_r2"]
    np.testing.assert_allclose(camp[0]["steer"], camp[1]["steer"], atol=1e-9)  # same drive
    out = tmp_path / "camp"
    assert main(["campaign", "import", str(src), "--out", str(out), "--mapping", str(mapping)]) == 0
    assert len(read_campaign(out)) == 2 and "imported 2 trials" in capsys.readouterr().err


def test_can_logs_are_not_written(tmp_path):
    tr = read_campaign("campaigns/default")[0]
    with pytest.raises(DataError, match=r"x\.blf: parknss reads \.blf logs but does not write"):
        write_trial(tr, tmp_path / "x.blf")


def test_dbc_path_is_found_beside_the_mapping_else_beside_the_log(tmp_path):
    m = load_mapping(EXAMPLE)  # configs/vehicle.dbc does not exist: kept relative
    assert m.can.dbc == "vehicle.dbc"
    (tmp_path / "vehicle.dbc").write_text(vehicle_dbc().as_dbc_string())
    local = tmp_path / "m.yaml"
    local.write_text(EXAMPLE.read_text())
    assert load_mapping(local).can.dbc == str(tmp_path / "vehicle.dbc")  # beside the mapping
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / "vehicle.dbc").write_text(vehicle_dbc().as_dbc_string())
    found = resolve_dbc(m, logs / "park_in_left_r1.blf")  # beside the log
    assert found.can.dbc == str(logs / "vehicle.dbc")


def test_a_short_frame_is_masked_and_counted(tmp_path):
    mapping = _short_frame(tmp_path / "logs")
    tr = read_trial(tmp_path / "logs" / "park_in_left_r1.blf", mapping)
    prov = json.loads(tr.provenance)
    assert prov["short_frames"] == {"steer_cmd#0": 1}
    assert tr.n == 575  # the other frames of the message still carry the signal
    camp = import_folder(tmp_path / "logs", mapping)  # describe names them
    summary = describe_campaign(camp)
    assert summary.short_frames == {"park_in_left_r1": {"steer_cmd#0": 1}}
    assert ("frames shorter than the DBC length (masked): park_in_left_r1: steer_cmd#0 1"
            in summary.table())


# ------------------------------------------------------------------- malformed logs


def _edit_mapping(mapping: Path, edit: Callable[[dict], None]) -> Path:
    doc = yaml.safe_load(mapping.read_text())
    edit(doc)
    mapping.write_text(yaml.safe_dump(doc))
    return mapping


def _missing_dbc(src: Path) -> Path:
    m = setup_logs(src)
    (src.parent / "vehicle.dbc").unlink()
    return m


def _no_dbc(src: Path) -> Path:
    return _edit_mapping(setup_logs(src), lambda d: d.pop("can"))


def _bad_dbc(src: Path) -> Path:
    m = setup_logs(src)
    (src.parent / "vehicle.dbc").write_text("BO_ this is not a DBC\n")
    return m


def _unknown_message(src: Path) -> Path:
    return _edit_mapping(setup_logs(src), lambda d: d["channels"]["ax"].update(message="IMU2"))


def _unknown_signal(src: Path) -> Path:
    return _edit_mapping(setup_logs(src), lambda d: d["channels"]["ay"].update(signal="AccZ"))


def _no_frames(src: Path) -> Path:
    msgs = [m for m in frames(vehicle_dbc()) if m.arbitration_id != 0x150]
    return setup_logs(src, ".blf", msgs)


def _non_monotonic(src: Path) -> Path:
    msgs = frames(vehicle_dbc())
    k = next(i for i, m in enumerate(msgs) if m.arbitration_id == 0x100 and m.timestamp > EPOCH + 2)
    msgs[k].timestamp -= 0.5
    return setup_logs(src, ".blf", msgs)


def _truncated_blf(src: Path) -> Path:
    m = setup_logs(src, ".blf")
    p = src / "park_in_left_r1.blf"
    p.write_bytes(p.read_bytes()[:-100])
    return m


def _truncated_asc(src: Path) -> Path:
    m = setup_logs(src, ".asc")
    p = src / "park_in_left_r1.asc"
    text = p.read_text()
    p.write_text(text[: len(text) // 2])
    return m


def _garbage_blf(src: Path) -> Path:
    m = setup_logs(src, ".blf")
    (src / "park_in_left_r1.blf").write_bytes(b"\x00garbage" * 50)
    return m


def _unmapped(src: Path) -> Path:
    return _edit_mapping(setup_logs(src), lambda d: d["channels"].pop("ay"))


def _short_frame(src: Path) -> Path:
    msgs = frames(vehicle_dbc())
    k = next(i for i, m in enumerate(msgs) if m.arbitration_id == 0x150 and m.timestamp > EPOCH + 1)
    msgs[k] = can.Message(
        timestamp=msgs[k].timestamp,
        arbitration_id=0x150,
        is_extended_id=False,
        data=b"\x01\x02",
        channel=0,
    )
    return setup_logs(src, ".blf", msgs)


def _column_mapping(src: Path) -> Path:
    return _edit_mapping(setup_logs(src), lambda d: d["channels"].update(vx={"column": "VehSpd"}))


# (case, file named in the message, fragments)
MALFORMED: dict[str, tuple[Callable[[Path], Path], str, tuple[str, ...]]] = {
    "missing_dbc": (
        _missing_dbc,
        "park_in_left_r1.blf",
        ("DBC file vehicle.dbc not found (can.dbc in the mapping; looked for",),
    ),
    "no_dbc": (_no_dbc, "park_in_left_r1.blf", ("a CAN log needs a DBC: set can.dbc",)),
    "bad_dbc": (_bad_dbc, "park_in_left_r1.blf", ("vehicle.dbc: not readable",)),
    "unknown_message": (
        _unknown_message,
        "park_in_left_r1.blf",
        ("channel 'ax' (message 'IMU2', signal 'AccX'): message not in the DBC vehicle.dbc",),
    ),
    "unknown_signal": (
        _unknown_signal,
        "park_in_left_r1.blf",
        ("channel 'ay' (message 'IMU', signal 'AccZ'): signal not in message 'IMU'",),
    ),
    "no_frames": (
        _no_frames,
        "park_in_left_r1.blf",
        (
            "channel 'steer_cmd' (message 'STR', signal 'StrWhlAngReq'): no frames of the "
            "message (id 0x150)",
        ),
    ),
    "non_monotonic": (
        _non_monotonic,
        "park_in_left_r1.blf",
        ("channel 'vx' (message 'ESP', signal 'VehSpd'): non-monotonic time stamps",),
    ),
    "truncated_blf": (_truncated_blf, "park_in_left_r1.blf", ("truncated .blf log",)),
    "truncated_asc": (_truncated_asc, "park_in_left_r1.asc", ("truncated .asc log",)),
    "garbage_blf": (_garbage_blf, "park_in_left_r1.blf", ("not a readable .blf log",)),
    "unmapped": (_unmapped, "park_in_left_r1.blf", ("channel 'ay': not mapped",)),
}


@pytest.mark.parametrize("kind", sorted(MALFORMED))
def test_malformed_can_log_gives_one_clear_line(kind, tmp_path, capsys):
    case, fname, fragments = MALFORMED[kind]
    src = tmp_path / "logs"
    mapping = case(src)
    with pytest.raises(ParknssError) as exc:  # the library
        import_folder(src, mapping=mapping)
    msg = str(exc.value)
    assert "\n" not in msg and fname in msg, msg
    for frag in fragments:
        assert frag in msg, msg
    out = tmp_path / "camp"  # the CLI
    assert main(["campaign", "import", str(src), "--out", str(out), "--mapping", str(mapping)]) == 2
    captured = capsys.readouterr()
    assert captured.err == f"parknss: error: {msg}\n", captured.err
    assert captured.out == "" and not (out / "campaign.json").exists()


def test_dbc_built_here_round_trips_through_cantools(tmp_path):
    p = tmp_path / "v.dbc"
    p.write_text(vehicle_dbc().as_dbc_string())
    db = cantools.database.load_file(p)
    gear = db.get_message_by_name("GEAR")
    assert str(gear.decode(gear.encode({"GearPos": "R"}))["GearPos"]) == "R"


def test_can_sources_in_the_mapping_are_checked(tmp_path):
    p = tmp_path / "m.yaml"
    p.write_text("channels: {vx: {message: ESP}}\n")
    with pytest.raises(ConfigError, match=r"channels\.vx.*needs both 'message' and 'signal'"):
        load_mapping(p)
    p.write_text("channels: {vx: {column: VehSpd, message: ESP, signal: VehSpd}}\n")
    with pytest.raises(ConfigError, match=r"channels\.vx.*not both"):
        load_mapping(p)
    csv = write_trial(read_campaign("campaigns/default")[0], tmp_path / "park_in_left_r1.csv")
    with pytest.raises(DataError, match=r"channel 'gear': the mapping gives a CAN message 'GEAR'"):
        read_trial(csv, EXAMPLE)  # a CAN mapping on a CSV log


def test_a_validity_signal_gates_a_channel(tmp_path):
    src = tmp_path / "logs"
    mapping = setup_logs(src, ".blf")
    doc = yaml.safe_load(mapping.read_text())
    doc["channels"]["vx"]["valid_if"] = {"message": "GEAR", "signal": "GearPos",
                                         "equals": ["R", "D"]}
    mapping.write_text(yaml.safe_dump(doc))
    trial = read_trial(src / "park_in_left_r1.blf", mapping)
    # valid from the change to R (1.234 s) to the change to N (4.005 s); the gear
    # channel itself is not gated
    assert trial["t"][0] == pytest.approx(1.24) and trial["t"][-1] == pytest.approx(4.0)
    assert json.loads(trial.provenance)["masked_samples"]


def test_a_dbc_signal_without_a_unit_needs_the_mappings_unit(tmp_path, capsys):
    src = tmp_path / "logs"
    mapping = setup_logs(src, ".blf")
    db = vehicle_dbc()
    db.get_message_by_name("BRK").get_signal_by_name("BrkPrs").unit = None
    (tmp_path / "vehicle.dbc").write_text(db.as_dbc_string())
    with pytest.raises(DataError, match=r"channel 'brake_pressure' \(message 'BRK', signal "
                                        r"'BrkPrs'\): the DBC gives the signal no unit; state "
                                        r"it in the mapping \(channels.brake_pressure.unit"):
        read_trial(src / "park_in_left_r1.blf", mapping)
    doc = yaml.safe_load(mapping.read_text())
    doc["channels"]["brake_pressure"]["unit"] = "MPa"
    mapping.write_text(yaml.safe_dump(doc))
    trial = read_trial(src / "park_in_left_r1.blf", mapping)
    assert 10.0 < trial["brake_pressure"].max() < 11.5  # t + 5 bar, converted from MPa
