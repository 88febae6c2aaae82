"""A synthetic CAN drive for the bus-log tests: a DBC (as configs/mapping_can_example.yaml
expects it), analytic signals, cyclic frames plus gear events, and log writers."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import can
import numpy as np
from cantools.database.can import Database, Message
from cantools.database.can import Signal as CanSignal
from cantools.database.conversion import BaseConversion

from parknss.config import CONFIG_DIR
from parknss.signals import DEG_PER_RAD, KMH_PER_MS

EXAMPLE = CONFIG_DIR / "mapping_can_example.yaml"
EPOCH = 1_700_000_000.0  # loggers stamp frames in absolute time
GEAR_EVENTS = ((0.0, "P"), (1.234, "R"), (3.0, "D"), (4.005, "N"))
GEAR_CHANGES_S = (1.24, 3.0, 4.01)  # first grid time at/after each change


def sig(name, start, scale, unit="", signed=True, length=16, choices=None) -> CanSignal:
    conv = BaseConversion.factory(scale=scale, offset=0, choices=choices)
    return CanSignal(name, start, length, is_signed=signed, conversion=conv, unit=unit)


def vehicle_dbc() -> Database:
    """The DBC of configs/mapping_can_example.yaml; units km/h, deg/s, MPa, Nm, deg."""
    gear = {0: "P", 1: "R", 2: "N", 3: "D"}
    msgs = [
        Message(
            0x100, "ESP", 8, [sig("VehSpd", 0, 0.01, "km/h"), sig("YawRate", 16, 0.01, "deg/s")]
        ),
        Message(
            0x120, "IMU", 8, [sig("AccX", 0, 0.001, "m/s^2"), sig("AccY", 16, 0.001, "m/s^2")]
        ),
        Message(
            0x130,
            "BRK",
            8,
            [sig("BrkPrs", 0, 0.001, "MPa", signed=False), sig("DecelReq", 16, 0.001, "m/s^2")],
        ),
        Message(
            0x18FF0140,
            "MOT",
            8,
            [sig("MotTrq", 0, 0.1, "Nm"), sig("MotTrqReq", 16, 0.1, "Nm")],
            is_extended_frame=True,
        ),
        Message(
            0x150,
            "STR",
            8,
            [sig("StrWhlAng", 0, 0.1, "deg"), sig("StrWhlAngReq", 16, 0.1, "deg")],
        ),
        Message(0x160, "GEAR", 1, [sig("GearPos", 0, 1, signed=False, length=8, choices=gear)]),
    ]
    return Database(messages=msgs)


# Analytic signals in schema units, t in s from the first frame.
SIGNALS: dict[str, tuple[str, str, Callable, float]] = {
    # schema channel: (message, signal, f(t) in schema units, factor schema -> DBC unit)
    "vx": ("ESP", "VehSpd", lambda t: 1.5 * np.sin(2 * np.pi * t / 6), KMH_PER_MS),
    "yaw_rate": ("ESP", "YawRate", lambda t: 0.3 * np.sin(2 * np.pi * t / 4), DEG_PER_RAD),
    "ax": ("IMU", "AccX", lambda t: 0.5 * t - 1.0, 1.0),
    "ay": ("IMU", "AccY", lambda t: -0.25 * t + 0.5, 1.0),
    "brake_pressure": ("BRK", "BrkPrs", lambda t: t + 5.0, 0.1),
    "decel_cmd": ("BRK", "DecelReq", lambda t: -2.0 + 0.1 * t, 1.0),
    "torque": ("MOT", "MotTrq", lambda t: 50.0 + 10.0 * t, 1.0),
    "torque_cmd": ("MOT", "MotTrqReq", lambda t: 55.0 + 10.0 * t, 1.0),
    "steer": ("STR", "StrWhlAng", lambda t: 100.0 * np.sin(2 * np.pi * t / 5), 1.0),
    "steer_cmd": ("STR", "StrWhlAngReq", lambda t: 20.0 * t, 1.0),
}
# message: (first frame s, period s, last frame s); BRK starts late, MOT is off the grid
TIMING = {
    "ESP": (0.0, 0.02, 6.0),
    "IMU": (0.003, 0.01, 6.0),
    "BRK": (0.237, 0.05, 6.0),
    "MOT": (0.005, 0.01, 6.0),
    "STR": (0.0, 0.01, 6.0),
}


def frame_times(msg: str) -> np.ndarray:
    t0, period, t1 = TIMING[msg]
    return t0 + np.arange(int(np.floor((t1 - t0) / period + 1e-9)) + 1) * period


def frames(db: Database) -> list[can.Message]:
    """Every frame of the test drive, sorted by time: cyclic messages plus gear events."""
    out = []
    for name in TIMING:
        msg = db.get_message_by_name(name)
        for t in frame_times(name):
            data = {
                s: SIGNALS[c][2](t) * SIGNALS[c][3]
                for c, (m, s, _, _) in SIGNALS.items()
                if m == name
            }
            out.append((t, msg, data))
    gear = db.get_message_by_name("GEAR")
    out += [(t, gear, {"GearPos": label}) for t, label in GEAR_EVENTS]
    out.sort(key=lambda x: x[0])
    return [
        can.Message(
            timestamp=EPOCH + t,
            arbitration_id=msg.frame_id,
            is_extended_id=msg.is_extended_frame,
            data=msg.encode(data),
            channel=0,
        )
        for t, msg, data in out
    ]


def write_log(path: Path, messages: list[can.Message]) -> Path:
    writer = can.BLFWriter(str(path)) if path.suffix == ".blf" else can.ASCWriter(str(path))
    for m in messages:
        writer.on_message_received(m)
    writer.stop()
    return path


def setup_logs(folder: Path, suffix: str = ".blf", messages=None, name="park_in_left_r1"):
    """The DBC as vehicle.dbc and the example mapping beside it, and one log; -> mapping."""
    folder.mkdir(parents=True, exist_ok=True)
    db = vehicle_dbc()
    (folder.parent / "vehicle.dbc").write_text(db.as_dbc_string())
    shutil.copy(EXAMPLE, folder.parent / "mapping.yaml")
    write_log(folder / f"{name}{suffix}", frames(db) if messages is None else messages)
    return folder.parent / "mapping.yaml"
