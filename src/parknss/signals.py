"""The channel schema and every unit conversion of parknss, in one place.

Internal computation uses SI-like schema units (m/s, rad/s, m/s², N·m, bar, deg of
steering-wheel angle). Reports use the paper's units ((km/h)², (°/s)²) through the
conversions below; no other module multiplies by 3.6 or 180/π.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

SCHEMA_VERSION = "1"
SAMPLE_RATE_HZ = 100.0
DT = 1.0 / SAMPLE_RATE_HZ
TRUTH_PREFIX = "truth_"

KMH_PER_MS = 3.6
DEG_PER_RAD = 180.0 / math.pi
G = 9.80665
BLIND_ZONE_KMH = 0.5
BLIND_ZONE_MS = BLIND_ZONE_KMH / KMH_PER_MS


@dataclass(frozen=True)
class Channel:
    """One logged channel: its schema name, unit and meaning.

    Its plausible range is configuration (configs/data.yaml, ``validation.ranges``).
    """

    name: str
    unit: str
    meaning: str
    integer: bool = False


CHANNELS: tuple[Channel, ...] = (
    Channel("t", "s", "time from trial start"),
    Channel("gear", "-", "-1 reverse, 0 neutral/park, +1 drive", integer=True),
    Channel("torque_cmd", "N*m", "motor torque command"),
    Channel("torque", "N*m", "motor torque actual"),
    Channel("decel_cmd", "m/s^2", "deceleration command a_x* (<= 0)"),
    Channel("brake_pressure", "bar", "master-cylinder pressure p_b"),
    Channel("steer_cmd", "deg", "steering-wheel angle request"),
    Channel("steer", "deg", "steering-wheel angle actual"),
    Channel("vx", "m/s", "longitudinal velocity, signed"),
    Channel("yaw_rate", "rad/s", "yaw rate"),
    Channel("ax", "m/s^2", "IMU longitudinal acceleration"),
    Channel("ay", "m/s^2", "IMU lateral acceleration"),
)
CHANNEL_BY_NAME: dict[str, Channel] = {c.name: c for c in CHANNELS}
REQUIRED_CHANNELS: tuple[str, ...] = tuple(c.name for c in CHANNELS)
COMMAND_CHANNELS: tuple[str, ...] = ("gear", "torque_cmd", "decel_cmd", "steer_cmd")
ACTUAL_CHANNELS: tuple[str, ...] = ("gear", "torque", "brake_pressure", "steer")
STATE_CHANNELS: tuple[str, ...] = ("vx", "yaw_rate")
OUTPUT_CHANNELS: tuple[str, ...] = ("ax", "ay")


def ms_to_kmh(v):
    """Speed m/s -> km/h (works on floats, NumPy arrays and torch tensors)."""
    return v * KMH_PER_MS


def kmh_to_ms(v):
    """Speed km/h -> m/s."""
    return v / KMH_PER_MS


def rad_to_deg(a):
    """Angle or rate rad(/s) -> deg(/s)."""
    return a * DEG_PER_RAD


def deg_to_rad(a):
    """Angle or rate deg(/s) -> rad(/s)."""
    return a / DEG_PER_RAD


# Paper-unit factors for squared errors: MSE in schema units times these gives the paper's.
MSE_FACTOR_KMH2 = KMH_PER_MS**2  # (m/s)^2 -> (km/h)^2
MSE_FACTOR_DEGS2 = DEG_PER_RAD**2  # (rad/s)^2 -> (deg/s)^2

# Unit conversions for logs whose units differ from the schema: unit -> (schema unit, scale).
# A value v in `unit` becomes v * scale in the schema unit. Keys are the canonical
# spellings; :data:`UNIT_ALIASES` and :func:`canonical_unit` map what loggers and DBCs
# write ("Bar", "Deg", "kph", "°/s", "m/s²", "µs", ...) onto them, ignoring case.
UNIT_CONVERSIONS: dict[str, tuple[str, float]] = {
    "s": ("s", 1.0),
    "ms": ("s", 1.0e-3),
    "us": ("s", 1.0e-6),
    "ns": ("s", 1.0e-9),
    "m/s": ("m/s", 1.0),
    "km/h": ("m/s", 1.0 / KMH_PER_MS),
    "mph": ("m/s", 0.44704),
    "rad/s": ("rad/s", 1.0),
    "deg/s": ("rad/s", 1.0 / DEG_PER_RAD),
    "m/s^2": ("m/s^2", 1.0),
    "g": ("m/s^2", G),
    "N*m": ("N*m", 1.0),
    "kN*m": ("N*m", 1.0e3),
    "bar": ("bar", 1.0),
    "mbar": ("bar", 1.0e-3),
    "MPa": ("bar", 10.0),
    "kPa": ("bar", 0.01),
    "Pa": ("bar", 1.0e-5),
    "psi": ("bar", 0.0689475729),
    "deg": ("deg", 1.0),
    "rad": ("deg", DEG_PER_RAD),
    "-": ("-", 1.0),
}

# Other spellings (compared case-insensitively, spaces removed) -> canonical unit.
UNIT_ALIASES: dict[str, str] = {
    "sec": "s", "second": "s", "seconds": "s",
    "msec": "ms", "millisecond": "ms", "milliseconds": "ms",
    "µs": "us", "μs": "us", "usec": "us", "microsecond": "us", "microseconds": "us",
    "nsec": "ns", "nanosecond": "ns", "nanoseconds": "ns",
    "mps": "m/s", "m/sec": "m/s", "ms-1": "m/s", "m*s^-1": "m/s",
    "kph": "km/h", "kmh": "km/h", "km/hr": "km/h", "kmph": "km/h", "kmh-1": "km/h",
    "rad/sec": "rad/s", "rads-1": "rad/s",
    "deg/sec": "deg/s", "°/s": "deg/s", "dps": "deg/s", "degree/s": "deg/s",
    "degrees/s": "deg/s", "degs-1": "deg/s",
    "m/s2": "m/s^2", "m/s²": "m/s^2", "m/s/s": "m/s^2", "mps2": "m/s^2", "ms-2": "m/s^2",
    "m*s^-2": "m/s^2", "m/sec^2": "m/s^2",
    "nm": "N*m", "n.m": "N*m", "n·m": "N*m", "n-m": "N*m", "newtonmeter": "N*m",
    "knm": "kN*m",
    "°": "deg", "degree": "deg", "degrees": "deg",
    "radian": "rad", "radians": "rad",
    "": "-", "1": "-", "none": "-",
}
_UNIT_KEYS: dict[str, str] = {u.lower(): u for u in UNIT_CONVERSIONS}
# "mPa" (millipascal) is never a brake pressure; lower-case "mpa" means MPa.


def canonical_unit(unit: str | None) -> str | None:
    """The canonical spelling of ``unit`` (a key of UNIT_CONVERSIONS), or None if unknown.

    Case and spaces are ignored and the aliases of :data:`UNIT_ALIASES` are accepted:
    ``"Bar" -> "bar"``, ``"Deg" -> "deg"``, ``"kph" -> "km/h"``, ``"°/s" -> "deg/s"``.
    """
    if unit is None:
        return None
    key = "".join(str(unit).split()).lower()
    if key in _UNIT_KEYS:
        return _UNIT_KEYS[key]
    alias = UNIT_ALIASES.get(key)
    return alias if alias is not None else None


def unit_dimension(unit: str | None) -> str | None:
    """The schema unit that ``unit`` converts to (``"km/h" -> "m/s"``), or None if unknown."""
    canon = canonical_unit(unit)
    return None if canon is None else UNIT_CONVERSIONS[canon][0]


def convert_to_schema(values: np.ndarray, unit: str, channel: str) -> np.ndarray:
    """Convert `values` given in `unit` (any accepted spelling) to the schema unit of `channel`.

    Raises ValueError if the unit is unknown or not convertible to the channel's unit.
    """
    if channel not in CHANNEL_BY_NAME:
        raise ValueError(f"unknown channel {channel!r}")
    target = CHANNEL_BY_NAME[channel].unit
    canon = canonical_unit(unit)
    if canon is None:
        raise ValueError(f"unknown unit {unit!r} for channel {channel!r}")
    schema_unit, scale = UNIT_CONVERSIONS[canon]
    if schema_unit != target:
        raise ValueError(f"unit {unit!r} cannot be converted to {target!r} for channel {channel!r}")
    return np.asarray(values, dtype=np.float64) * scale


def moving_mask(vx_ms) -> np.ndarray:
    """Boolean mask of the moving region |vx| >= 0.5 km/h (the blind zone is masked out)."""
    return np.abs(np.asarray(vx_ms)) >= BLIND_ZONE_MS
