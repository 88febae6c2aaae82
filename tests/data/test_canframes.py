"""CAN frame readers (.blf, .asc, candump .log, GVRET .csv, MDF4 bus logging), bus
de-duplication, read_can_series, the writers, malformed inputs, and the real logs."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import can
import numpy as np
import pytest
import yaml

from helpers.paths import CANEDGE, KONA
from parknss.cli import main
from parknss.data import canframes
from parknss.data.canframes import (
    FrameTable,
    drop_duplicate_buses,
    is_bus_logging_mdf,
    is_gvret_csv,
    log_kind,
    read_frames,
)
from parknss.data.canlog import CanRequest, read_can_series
from parknss.data.canwrite import (
    frames_from_signals,
    merge_frames,
    message_frames,
    on_buses,
    write_frames,
    write_mdf_bus_logging,
)
from parknss.data.dbc import DbcWarning, load_dbc
from parknss.data.mapping import CanOptions
from parknss.errors import DataError

SUFFIXES = (".blf", ".asc", ".log", ".csv", ".mf4")
EPOCH = 1_700_000_000.0

# The messages of configs/mapping_can_example.yaml, a Motorola signal, an extended id
# and a 64-byte CAN FD message; units km/h, deg/s, MPa, Nm, deg.
VEHICLE_DBC = """VERSION ""

NS_ :

BS_:

BU_: ECU

BO_ 256 ESP: 8 ECU
 SG_ VehSpd : 0|16@1- (0.01,0) [-327|327] "km/h" Vector__XXX
 SG_ YawRate : 16|16@1- (0.01,0) [-327|327] "deg/s" Vector__XXX

BO_ 288 IMU: 8 ECU
 SG_ AccX : 0|16@1- (0.001,0) [-32|32] "m/s^2" Vector__XXX
 SG_ AccY : 16|16@1- (0.001,0) [-32|32] "m/s^2" Vector__XXX

BO_ 304 BRK: 8 ECU
 SG_ BrkPrs : 0|16@1+ (0.001,0) [0|65] "MPa" Vector__XXX
 SG_ DecelReq : 16|16@1- (0.001,0) [-32|32] "m/s^2" Vector__XXX

BO_ 2566849856 MOT: 8 ECU
 SG_ MotTrq : 0|16@1- (0.1,0) [-3276|3276] "Nm" Vector__XXX
 SG_ MotTrqReq : 16|16@1- (0.1,0) [-3276|3276] "Nm" Vector__XXX

BO_ 336 STR: 8 ECU
 SG_ StrWhlAng : 7|16@0- (0.1,0) [-3276|3276] "deg" Vector__XXX
 SG_ StrWhlAngReq : 16|16@1- (0.1,0) [-3276|3276] "deg" Vector__XXX

BO_ 352 GEAR: 1 ECU
 SG_ GearPos : 0|8@1+ (1,0) [0|3] "" Vector__XXX

BO_ 368 FD64: 64 ECU
 SG_ Far : 480|16@1+ (1,0) [0|65535] "" Vector__XXX

VAL_ 352 GearPos 0 "P" 1 "R" 2 "N" 3 "D" ;
"""
CHANNELS = {  # schema channel: (message, signal)
    "vx": ("ESP", "VehSpd"),
    "yaw_rate": ("ESP", "YawRate"),
    "ax": ("IMU", "AccX"),
    "ay": ("IMU", "AccY"),
    "brake_pressure": ("BRK", "BrkPrs"),
    "decel_cmd": ("BRK", "DecelReq"),
    "torque": ("MOT", "MotTrq"),
    "torque_cmd": ("MOT", "MotTrqReq"),
    "steer": ("STR", "StrWhlAng"),
    "steer_cmd": ("STR", "StrWhlAngReq"),
    "gear": ("GEAR", "GearPos"),
}


@pytest.fixture(scope="module")
def dbc_path(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("dbc") / "vehicle.dbc"
    p.write_text(VEHICLE_DBC)
    return p


def drive(dbc: Path, seconds: float = 2.0, fd: bool = True) -> FrameTable:
    """Every message cyclically (GEAR on change), plus an unmapped filler id 0x7FF."""
    db = load_dbc(dbc).db
    t10, t20 = np.arange(0, seconds, 0.01), np.arange(0.005, seconds, 0.02)
    sched = {
        "ESP": {"VehSpd": (t20, 5 * np.sin(t20)), "YawRate": (t20, 10 * np.cos(t20))},
        "IMU": {"AccX": (t10, 0.5 * t10 - 1), "AccY": (t10, -0.25 * t10)},
        "BRK": {"BrkPrs": (t20, t20 + 1), "DecelReq": (t20, -1 + 0 * t20)},
        "MOT": {"MotTrq": (t10, 50 + 10 * t10), "MotTrqReq": (t10, 55 + 10 * t10)},
        "STR": {"StrWhlAng": (t10, -100 * np.sin(t10)), "StrWhlAngReq": (t10, 20 * t10)},
        "GEAR": {"GearPos": (np.array([0.001, 0.9]), np.array(["P", "D"], dtype=object))},
    }
    if fd:
        sched["FD64"] = {"Far": (np.array([0.5, 1.5]), np.array([1234.0, 4321.0]))}
    frames = frames_from_signals(db, sched)
    filler = message_frames(db.get_message_by_name("IMU"), np.arange(0, seconds, 0.05), {})
    n = len(filler)
    filler = replace(filler, id=np.full(n, 0x7FF, np.uint32), data=np.full((n, 8), 0xAB, np.uint8))
    out = merge_frames([filler, frames])
    return replace(out, t=out.t + EPOCH, t_first=out.t_first + EPOCH)


def _same(got: FrameTable, want: FrameTable, atol: float = 2e-6) -> None:
    assert len(got) == len(want)
    np.testing.assert_array_equal(got.id, want.id)
    np.testing.assert_array_equal(got.extended, want.extended)
    np.testing.assert_array_equal(got.bus, want.bus)
    np.testing.assert_array_equal(got.dlc, want.dlc)
    w = min(got.data.shape[1], want.data.shape[1])  # the wider one is zero beyond
    np.testing.assert_array_equal(got.data[:, :w], want.data[:, :w])
    assert not got.data[:, w:].any() and not want.data[:, w:].any()
    np.testing.assert_allclose(got.t - got.t_first, want.t - want.t_first, rtol=0, atol=atol)


# ------------------------------------------------------------------------ readers


@pytest.mark.parametrize("suffix", SUFFIXES)
def test_every_format_reads_back_what_was_written(suffix, dbc_path, tmp_path):
    frames = on_buses(drive(dbc_path), (0, 1), delay_s=1e-4)
    p = write_frames(tmp_path / f"log{suffix}", frames)
    assert log_kind(p) == {".log": "candump", ".csv": "gvret", ".mf4": "mdf"}.get(
        suffix, suffix[1:]
    )
    got = read_frames(p)
    _same(got, frames)
    assert got.data.shape[1] == 64 and got.n_frames == len(frames) and got.n_skipped == 0
    # only the wanted (id, extended) are kept; all frames are still counted
    esp = read_frames(p, {(0x100, False), (0x18FF0140, True), (0x100, True)})
    keep = np.isin(frames.id, (0x100, 0x18FF0140))
    _same(esp, frames.take(keep))
    assert esp.n_frames == len(frames) and esp.data.shape[1] == 8
    assert esp.t_first == got.t_first  # the log's first frame, though not wanted


def test_error_and_remote_frames_are_dropped_but_start_the_clock(tmp_path):
    msgs = [
        can.Message(timestamp=EPOCH, is_error_frame=True, channel=0),
        can.Message(timestamp=EPOCH + 0.1, arbitration_id=0x10, is_remote_frame=True, channel=0),
        can.Message(timestamp=EPOCH + 0.2, arbitration_id=0x10, data=b"\x01\x02", channel=1),
    ]
    for cls, suffix in ((can.BLFWriter, ".blf"), (can.ASCWriter, ".asc")):
        w = cls(str(tmp_path / f"e{suffix}"))
        for m in msgs:
            w.on_message_received(m)
        w.stop()
        got = read_frames(tmp_path / f"e{suffix}")
        assert (len(got), got.n_skipped, got.n_frames) == (1, 2, 1), suffix
        assert got.t[0] - got.t_first == pytest.approx(0.2) and got.bus[0] == 1
    log = tmp_path / "e.log"
    log.write_text(
        "(1700000000.000000) can0 20000004#0000000000000000\n"
        "(1700000000.100000) can0 010#R\n"
        "(1700000000.200000) vcan1 010#0102 R\n"
        "(1700000000.300000) vcan1 12345678##1" + "00" * 12 + "\n"
    )
    got = read_frames(log)
    assert (len(got), got.n_skipped) == (2, 2)
    np.testing.assert_allclose(got.t - got.t_first, [0.2, 0.3], rtol=0, atol=1e-6)
    assert list(got.id) == [0x10, 0x12345678] and list(got.extended) == [False, True]
    assert list(got.dlc) == [2, 12] and list(got.bus) == [1, 1]


def test_formats_are_recognised_by_content(dbc_path, tmp_path):
    frames = drive(dbc_path, 0.5, fd=False)
    table = tmp_path / "table.csv"
    table.write_text("t,vx\n0.0,1.0\n")
    assert not is_gvret_csv(table) and log_kind(table) is None
    assert is_gvret_csv(write_frames(tmp_path / "g.csv", frames))
    bus = write_mdf_bus_logging(tmp_path / "bus.mf4", frames)
    from asammdf import MDF, Signal

    signals = tmp_path / "signals.mf4"
    with MDF(version="4.10") as mdf:
        mdf.append([Signal(np.arange(3.0), np.arange(3.0), name="VehSpd")])
        mdf.save(signals, overwrite=True)
    assert is_bus_logging_mdf(bus) and log_kind(bus) == "mdf"
    assert not is_bus_logging_mdf(signals) and log_kind(signals) is None
    assert not is_bus_logging_mdf(table)
    assert log_kind(tmp_path / "x.parquet") is None


def test_gvret_variants_dir_column_crlf_trailing_comma_and_short_frames(tmp_path):
    p = tmp_path / "savvy.csv"
    p.write_bytes(
        b"\xef\xbb\xbfTime Stamp,ID,Extended,Dir,Bus,LEN,D1,D2,D3,D4,D5,D6,D7,D8\r\n"
        b"100,000007DF,false,Rx,0,2,AB,CD\r\n"
        b"\r\n"
        b"250,18DAF110,true,Tx,1,3,1,02,3,\r\n"
        b"400,00000010,False,Rx,2,0\r\n"
    )
    assert is_gvret_csv(p) and log_kind(p) == "gvret"
    got = read_frames(p)
    assert list(got.id) == [0x7DF, 0x18DAF110, 0x10] and list(got.extended) == [0, 1, 0]
    assert list(got.bus) == [0, 1, 2] and list(got.dlc) == [2, 3, 0]
    np.testing.assert_allclose(got.t, [100e-6, 250e-6, 400e-6])
    assert got.data[0, :2].tolist() == [0xAB, 0xCD] and got.data[1, :3].tolist() == [1, 2, 3]


def test_bus_numbers_of_candump_interfaces(tmp_path):
    log = tmp_path / "i.log"
    log.write_text("(1.000000) can7 001#01\n(1.100000) can3 001#02\n(1.200000) can7 001#03\n")
    assert list(read_frames(log).bus) == [7, 3, 7]  # trailing digits
    log.write_text("(1.000000) canB 001#01\n(1.100000) canA 001#02\n(1.200000) canB 001#03\n")
    assert list(read_frames(log).bus) == [0, 1, 0]  # no digits: order of appearance


def test_mdf_bus_logging_written_here_is_what_asammdf_decodes(dbc_path, tmp_path):
    frames = drive(dbc_path, 1.0, fd=False)
    p = write_mdf_bus_logging(tmp_path / "x.mf4", replace(frames, bus=frames.bus + 1))
    from asammdf import MDF

    with MDF(p) as mdf:
        out = mdf.extract_bus_logging({"CAN": [(str(dbc_path), 0)]})
        ref = out.get("CAN2.STR.StrWhlAng")  # BusChannel 2 is bus 1
        ref_gear = out.get("CAN2.GEAR.GearPos")
    series, prov = read_can_series(
        p,
        [
            CanRequest("steer#0", "steer", "STR", "StrWhlAng", "steer"),
            CanRequest("gear#0", "gear", "GEAR", "GearPos", "gear"),
        ],
        CanOptions(dbc=str(dbc_path)),
    )
    steer, gear = series
    np.testing.assert_array_equal(steer.values, ref.samples)
    np.testing.assert_allclose(steer.t + prov["log_t0_s"], ref.timestamps, rtol=0, atol=1e-9)
    labels = [x.decode() if isinstance(x, bytes) else str(x) for x in ref_gear.samples]
    assert list(gear.values) == ["P", "D"] and labels == ["P", "D"]
    assert prov["format"] == "mdf" and prov["bus_kept"] == {"STR": 1, "GEAR": 1}


# --------------------------------------------------------------------- read_can_series


def _requests(*channels: str) -> list[CanRequest]:
    out = []
    for ch in channels or CHANNELS:
        msg, sig = CHANNELS[ch]
        out.append(
            CanRequest(f"{ch}#0", ch, msg, sig, f"channel {ch!r} (message {msg!r}, signal {sig!r})")
        )
    return out


def test_series_are_decoded_per_request_from_the_first_frame_of_the_log(dbc_path, tmp_path):
    frames = drive(dbc_path)
    p = write_frames(tmp_path / "d.blf", frames)
    series, prov = read_can_series(p, _requests(), CanOptions(dbc=str(dbc_path)))
    by = {s.channel: s for s in series}
    assert [s.key for s in series] == [f"{c}#0" for c in CHANNELS]
    t20 = np.arange(0.005, 2.0, 0.02)
    np.testing.assert_allclose(by["vx"].t, t20, atol=1e-6)  # the filler at t=0 starts it
    np.testing.assert_allclose(by["vx"].values, np.round(500 * np.sin(t20)) / 100, atol=1e-9)
    assert by["vx"].unit == "km/h" and by["yaw_rate"].unit == "deg/s" and by["vx"].hold
    np.testing.assert_allclose(
        by["steer"].values, np.round(-1000 * np.sin(by["steer"].t)) / 10, atol=0.1 + 1e-9
    )
    assert list(by["gear"].values) == ["P", "D"] and by["gear"].event and not by["vx"].event
    assert by["gear"].values.dtype == object
    assert prov["format"] == "blf" and prov["dbc"] == str(dbc_path)
    assert prov["frames_read"] == len(frames) and prov["frames_mapped"] == len(frames) - 40 - 2
    assert prov["dbc_warnings"] == [] and prov["short_frames"] == {}
    assert prov["log_t0_s"] == pytest.approx(EPOCH)


def _on_two_buses(dbc_path: Path, bus1_fraction: float = 1.0, interleave: bool = True):
    """ESP on buses 0 and 1 (bus 1 maybe thinned out), IMU only on bus 1."""
    frames = drive(dbc_path, fd=False)
    esp = frames.take(frames.id == 0x100)
    esp1 = replace(esp, bus=np.ones(len(esp), np.int16), t=esp.t + 2e-4)
    esp1 = esp1.take(np.arange(int(len(esp1) * bus1_fraction)))
    rest = frames.take(frames.id != 0x100)
    rest = replace(rest, bus=np.where(rest.id == 0x120, 1, 0).astype(np.int16))
    if interleave:
        return merge_frames([rest, esp, esp1])
    first = merge_frames([rest, esp])  # then bus 1's ESP frames: time goes back once
    cols = ("t", "id", "extended", "bus", "dlc", "data")
    return replace(
        first, **{c: np.concatenate([getattr(first, c), getattr(esp1, c)]) for c in cols}
    )


def test_duplicate_buses_first_keeps_the_busiest_bus_per_message(dbc_path, tmp_path):
    p = write_frames(tmp_path / "two.blf", _on_two_buses(dbc_path, bus1_fraction=0.5))
    series, prov = read_can_series(p, _requests("vx", "ax"), CanOptions(dbc=str(dbc_path)))
    assert prov["bus_kept"] == {"ESP": 0, "IMU": 1}
    assert prov["duplicates_dropped"] == {"ESP": 50}
    assert len(series[0].t) == 100 and np.all(np.diff(series[0].t) > 0)
    frames = read_frames(p)
    kept, choices = drop_duplicate_buses(frames)
    assert [(c.key, c.counts, c.kept, c.dropped) for c in choices] == [
        (0x100, {0: 100, 1: 50}, 0, 50)
    ]
    assert len(kept) == len(frames) - 50
    # a tie goes to the lowest bus number
    tie = write_frames(tmp_path / "tie.blf", _on_two_buses(dbc_path))
    _, prov = read_can_series(tie, _requests("vx"), CanOptions(dbc=str(dbc_path)))
    assert prov["bus_kept"] == {"ESP": 0} and prov["duplicates_dropped"] == {"ESP": 100}
    # keep: both buses' frames
    series, prov = read_can_series(
        tie, _requests("vx"), CanOptions(dbc=str(dbc_path), duplicate_buses="keep")
    )
    assert len(series[0].t) == 200 and prov["bus_kept"] == {"ESP": [0, 1]}
    # bus_channel: that bus only
    series, prov = read_can_series(
        tie, _requests("vx"), CanOptions(dbc=str(dbc_path), bus_channel=1)
    )
    assert len(series[0].t) == 100 and prov["bus_kept"] == {"ESP": 1}
    np.testing.assert_allclose(series[0].t[0], 0.0052, atol=1e-6)


def test_bus_problems_name_the_fix(dbc_path, tmp_path):
    p = write_frames(tmp_path / "late.blf", _on_two_buses(dbc_path, interleave=False))
    with pytest.raises(DataError) as exc:
        read_can_series(p, _requests("vx"), CanOptions(dbc=str(dbc_path), duplicate_buses="keep"))
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(f"{p}: channel 'vx' (message 'ESP', signal")
    assert "non-monotonic time stamps, 1 steps backwards" in msg
    assert msg.endswith(
        "message 'ESP' arrives on buses 0 and 1: set can.bus_channel or can.duplicate_buses: first"
    )
    series, _ = read_can_series(p, _requests("vx"), CanOptions(dbc=str(dbc_path)))
    assert np.all(np.diff(series[0].t) >= 0)
    with pytest.raises(
        DataError,
        match=r"no frames of the message \(id 0x120\) on bus 0 "
        r"\(can.bus_channel\); the log has it on bus 1",
    ):
        read_can_series(p, _requests("ax"), CanOptions(dbc=str(dbc_path), bus_channel=0))


def test_unknown_names_and_short_frames(dbc_path, tmp_path):
    frames = drive(dbc_path, fd=False)
    k = int(np.flatnonzero(frames.id == 0x150)[10])
    short = replace(frames, dlc=frames.dlc.copy())
    short.dlc[k] = 2
    short.data[k, 2:] = 0
    p = write_frames(tmp_path / "s.blf", short)
    opts = CanOptions(dbc=str(dbc_path))
    series, prov = read_can_series(p, _requests("steer", "steer_cmd"), opts)
    assert len(series[0].t) == 200 and len(series[1].t) == 199  # 2 bytes carry StrWhlAng
    assert prov["short_frames"] == {"steer_cmd#0": 1}
    bad = [CanRequest("ax#0", "ax", "IMU2", "AccX", "channel 'ax' (message 'IMU2', signal 'AccX')")]
    with pytest.raises(DataError, match=r"message not in the DBC vehicle\.dbc; similar: IMU$"):
        read_can_series(p, bad, opts)
    bad = [CanRequest("vx#0", "vx", "ESP", "VehSpeed", "channel 'vx'")]
    with pytest.raises(
        DataError,
        match=r"signal not in message 'ESP' of the DBC vehicle\.dbc; "
        r"similar: VehSpd$",
    ):
        read_can_series(p, bad, opts)
    far = [CanRequest("x#0", "x", "FD64", "Far", "channel 'x' (message 'FD64', signal 'Far')")]
    p = write_frames(tmp_path / "fd.blf", drive(dbc_path, fd=True).take(slice(0, 10)))
    with pytest.raises(DataError, match="no frames of the message \\(id 0x170\\) in the log"):
        read_can_series(p, far, opts)


# --------------------------------------------------------------------- malformed logs


def _good(dbc: Path, suffix: str, folder: Path) -> Path:
    return write_frames(folder / f"park_in_left_r1{suffix}", drive(dbc, 1.0, fd=False))


def _edit_lines(p: Path, edit: Callable[[list[str]], None]) -> Path:
    lines = p.read_text().splitlines()
    edit(lines)
    p.write_text("\n".join(lines) + "\n")
    return p


def _set(line: int, text: str) -> Callable[[list[str]], None]:
    def edit(lines: list[str]) -> None:
        lines[line - 1] = text

    return edit


def _cut(p: Path, keep: float) -> Path:
    data = p.read_bytes()
    p.write_bytes(data[: int(len(data) * keep)])
    return p


def _cut_line(p: Path) -> Path:
    """Cut a text log 12 characters into a line in its middle (a logger killed mid-write)."""
    data = p.read_bytes()
    start = data.index(b"\n", len(data) // 2) + 1
    p.write_bytes(data[: start + 12])
    return p


GV = "1000000,00000100,false,0,8,01,02,03,04,05,06,07,08"
MALFORMED: dict[str, tuple[str, Callable[[Path], Path], str]] = {
    "gvret_header": (
        ".csv",
        lambda p: _edit_lines(p, _set(1, "Time,ID,Ext,Bus,LEN")),
        "line 1: not a GVRET header",
    ),
    "gvret_bad_hex": (
        ".csv",
        lambda p: _edit_lines(p, _set(3, GV.replace(",05,", ",ZZ,"))),
        "line 3: a data byte is not a hex byte",
    ),
    "gvret_len": (
        ".csv",
        lambda p: _edit_lines(p, _set(4, GV.replace(",8,", ",6,"))),
        "line 4: LEN differs from the number of data bytes",
    ),
    "gvret_time": (
        ".csv",
        lambda p: _edit_lines(p, _set(5, GV.replace("1000000", "1e6"))),
        "line 5: time stamp is not an integer number of µs",
    ),
    "gvret_id": (
        ".csv",
        lambda p: _edit_lines(p, _set(2, GV.replace("00000100", "0x100"))),
        "line 2: ID is not a hex CAN id",
    ),
    "gvret_truncated": (".csv", _cut_line, "fewer than 5 fields (GVRET line '"),
    "candump_hex": (
        ".log",
        lambda p: _edit_lines(p, _set(2, "(1.000000) can0 12G#00")),
        "line 2: CAN id is not hex",
    ),
    "candump_hash": (
        ".log",
        lambda p: _edit_lines(p, _set(3, "(1.000000) can0 123")),
        "line 3: no '#' in the frame",
    ),
    "candump_odd": (
        ".log",
        lambda p: _edit_lines(p, _set(4, "(1.000000) can0 123#ABC")),
        "line 4: data is not whole hex bytes",
    ),
    "candump_paren": (
        ".log",
        lambda p: _edit_lines(p, _set(1, "1.000000 can0 123#00")),
        "line 1: no '(time stamp)' at the start",
    ),
    "candump_truncated": (".log", _cut_line, "no ')' after the time stamp (candump line"),
    "blf_truncated": (".blf", lambda p: _cut(p, 0.9), "truncated .blf log (header says"),
    "blf_garbage": (
        ".blf",
        lambda p: (p.write_bytes(b"\x00garbage" * 50), p)[1],
        "not a readable .blf log",
    ),
    "blf_corrupt": (
        ".blf",
        lambda p: (p.write_bytes(p.read_bytes()[:300] + b"\xff" * 64 + p.read_bytes()[364:]), p)[1],
        "not a readable .blf log, corrupt or truncated",
    ),
    "asc_truncated": (".asc", lambda p: _cut(p, 0.5), "truncated .asc log (no closing"),
    "asc_bad_byte": (
        ".asc",
        lambda p: _edit_lines(p, lambda ls: ls.__setitem__(7, ls[7][:-2] + "ZZ")),
        "(line 8, after frame 2",
    ),
    "mf4_truncated": (".mf4", lambda p: _cut(p, 0.5), "not a readable MDF file"),
    "empty_log": (".log", lambda p: (p.write_text(""), p)[1], "no CAN frames in the log"),
}


@pytest.fixture(scope="module")
def cli_setup(dbc_path, tmp_path_factory) -> Path:
    """A mapping of every schema channel onto vehicle.dbc (the DBC beside it)."""
    folder = tmp_path_factory.mktemp("mapping")
    (folder / "vehicle.dbc").write_text(VEHICLE_DBC)
    doc = {
        "can": {"dbc": "vehicle.dbc"},
        "channels": {ch: {"message": m, "signal": s} for ch, (m, s) in CHANNELS.items()},
        "gear_values": {"P": 0, "R": -1, "N": 0, "D": 1},
    }
    (folder / "mapping.yaml").write_text(yaml.safe_dump(doc))
    return folder / "mapping.yaml"


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_malformed_log_is_one_line_naming_file_and_place(
    case, dbc_path, cli_setup, tmp_path, capsys
):
    suffix, spoil, fragment = MALFORMED[case]
    src = tmp_path / "logs"
    src.mkdir()
    p = spoil(_good(dbc_path, suffix, src))
    with pytest.raises(DataError) as exc:
        read_frames(p)
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(f"{p}: "), msg
    assert fragment in msg, msg
    if suffix != ".csv" or is_gvret_csv(p):  # a CSV without that header is a table log
        with pytest.raises(DataError) as exc:
            read_can_series(p, _requests("vx"), CanOptions(dbc=str(dbc_path)))
        assert str(exc.value) == msg
    code = main(
        ["campaign", "import", str(src), "--out", str(tmp_path / "c"), "--mapping", str(cli_setup)]
    )
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if ln.startswith("parknss: error:")]
    assert len(lines) == 1 and str(p.name) in lines[0], err


def test_a_good_log_of_each_format_imports_through_the_cli(dbc_path, cli_setup, tmp_path, capsys):
    src = tmp_path / "logs"
    src.mkdir()
    frames = on_buses(drive(dbc_path, 3.0, fd=False), (0, 1), 1e-4)
    for k, suffix in enumerate(SUFFIXES):
        write_frames(src / f"park_in_left_r{k + 1}{suffix}", frames)
    code = main(
        ["campaign", "import", str(src), "--out", str(tmp_path / "c"), "--mapping", str(cli_setup)]
    )
    err = capsys.readouterr().err
    assert code == 0 and "imported 5 trials" in err, err


# ------------------------------------------------------------------------ real logs


@pytest.mark.realdata
def test_kona_gvret_capture_two_buses_deduplicated():
    log = KONA / "230112-7-2019-pcan-ccan-power-off-on-ready-off.csv"
    assert is_gvret_csv(log)
    frames = read_frames(log)
    assert len(frames) == 39546 and set(np.unique(frames.bus)) == {0, 1}
    requests = [
        CanRequest("steer#0", "steer", "Steering", "Angle", "channel 'steer'"),
        CanRequest("yaw_rate#0", "yaw_rate", "StabilityControl", "YAW_RATE", "channel 'yaw'"),
        CanRequest("gear#0", "gear", "VCU_200", "CURRENT_GEAR", "channel 'gear'"),
    ]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DbcWarning)
        series, prov = read_can_series(log, requests, CanOptions(dbc=str(KONA / "pcan.dbc")))
    steer, _, gear = series
    assert prov["format"] == "gvret" and prov["frames_read"] == 39546
    assert prov["dbc_warnings"] == ["no BS_:/BU_: sections (empty ones assumed)"]
    assert prov["duplicates_dropped"]["Steering"] == 863
    assert prov["bus_kept"]["Steering"] == 0 and "StabilityControl" in prov["duplicates_dropped"]
    assert len(steer.t) == 863 and np.all(np.diff(steer.t) > 0) and steer.unit == "Deg"
    assert np.any(np.isclose(steer.values, 3276.7, rtol=0, atol=1e-9))  # start-up sentinel
    assert steer.t[0] >= 0 and steer.t[-1] < 11.0
    assert set(gear.values) <= {"P", "D", "N", "R"} | {str(k) for k in range(16)}
    with pytest.raises(DataError, match=r"pcan\.dbc: refused in strict mode"):
        read_can_series(log, requests, CanOptions(dbc=str(KONA / "pcan.dbc"), strict_dbc=True))


@pytest.mark.realdata
@pytest.mark.parametrize("name", ["00000005-60FEBFEB", "00000006-60FFE42F"])
def test_canedge_raw_mf4_decodes_as_the_vendor_did(name, monkeypatch):
    from asammdf import MDF

    raw = CANEDGE / "raw_mf4" / f"{name}.MF4"
    assert is_bus_logging_mdf(raw)
    wanted = {
        ("gnss_speed", "Speed"): "speed",
        ("gnss_imu", "AngularRateX"): "yaw_rate",
        ("gnss_imu", "AccelerationZ"): "ax",
        ("gnss_pos", "Latitude"): "lat",
    }
    requests = [CanRequest(f"{c}#0", c, m, s, f"channel {c!r}") for (m, s), c in wanted.items()]
    series, prov = read_can_series(raw, requests, CanOptions(dbc=str(CANEDGE / "canmod-gps.dbc")))
    whole = read_frames(raw)
    monkeypatch.setattr(canframes, "MDF_CHUNK_RECORDS", 5000)  # chunks of VLSD records
    chunked = read_frames(raw)
    for col in ("t", "id", "extended", "bus", "dlc", "data"):
        np.testing.assert_array_equal(getattr(chunked, col), getattr(whole, col))
    assert prov["format"] == "mdf" and prov["bus_kept"]["gnss_speed"] == 1  # CAN2
    with MDF(CANEDGE / "decoded_mf4" / f"{name}.mf4") as ref_mdf:
        for s, ((msg, sig), _) in zip(series, wanted.items(), strict=True):
            db = load_dbc(CANEDGE / "canmod-gps.dbc").db
            scale = db.get_message_by_name(msg).get_signal_by_name(sig).scale
            ref = ref_mdf.get(f"CAN2.{msg}.{sig}")
            np.testing.assert_allclose(s.values, ref.samples, rtol=0, atol=scale / 2, err_msg=sig)
            np.testing.assert_allclose(s.t + prov["log_t0_s"], ref.timestamps, rtol=0, atol=1e-9)
