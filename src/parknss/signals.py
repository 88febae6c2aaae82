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
    """One logged channel: its schema name, unit, meaning and plausible range."""

    name: str
    unit: str
    meaning: str
    lo: float
    hi: float
    integer: bool = False


CHANNELS: tuple[Channel, ...] = (
    Channel("t", "s", "time from trial start", 0.0, 1.0e5),
    Channel("gear", "-", "-1 reverse, 0 neutral/park, +1 drive", -1, 1, integer=True),
    Channel("torque_cmd", "N*m", "motor torque command", -50.0, 600.0),
    Channel("torque", "N*m", "motor torque actual", -50.0, 600.0),
    Channel("decel_cmd", "m/s^2", "deceleration command a_x* (<= 0)", -10.0, 0.0),
    Channel("brake_pressure", "bar", "master-cylinder pressure p_b", -1.0, 200.0),
    Channel("steer_cmd", "deg", "steering-wheel angle request", -600.0, 600.0),
    Channel("steer", "deg", "steering-wheel angle actual", -600.0, 600.0),
    Channel("vx", "m/s", "longitudinal velocity, signed", -5.0, 5.0),
    Channel("yaw_rate", "rad/s", "yaw rate", -2.0, 2.0),
    Channel("ax", "m/s^2", "IMU longitudinal acceleration", -10.0, 10.0),
    Channel("ay", "m/s^2", "IMU lateral acceleration", -10.0, 10.0),
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
# A value v in `unit` becomes v * scale in the schema unit.
UNIT_CONVERSIONS: dict[str, tuple[str, float]] = {
    "s": ("s", 1.0),
    "ms": ("s", 1.0e-3),
    "m/s": ("m/s", 1.0),
    "km/h": ("m/s", 1.0 / KMH_PER_MS),
    "kph": ("m/s", 1.0 / KMH_PER_MS),
    "rad/s": ("rad/s", 1.0),
    "deg/s": ("rad/s", 1.0 / DEG_PER_RAD),
    "m/s^2": ("m/s^2", 1.0),
    "g": ("m/s^2", G),
    "N*m": ("N*m", 1.0),
    "Nm": ("N*m", 1.0),
    "bar": ("bar", 1.0),
    "MPa": ("bar", 10.0),
    "kPa": ("bar", 0.01),
    "Pa": ("bar", 1.0e-5),
    "deg": ("deg", 1.0),
    "rad": ("deg", DEG_PER_RAD),
    "-": ("-", 1.0),
}


def convert_to_schema(values: np.ndarray, unit: str, channel: str) -> np.ndarray:
    """Convert `values` given in `unit` to the schema unit of `channel`.

    Raises ValueError if the unit is unknown or not convertible to the channel's unit.
    """
    if channel not in CHANNEL_BY_NAME:
        raise ValueError(f"unknown channel {channel!r}")
    target = CHANNEL_BY_NAME[channel].unit
    if unit not in UNIT_CONVERSIONS:
        raise ValueError(f"unknown unit {unit!r} for channel {channel!r}")
    schema_unit, scale = UNIT_CONVERSIONS[unit]
    if schema_unit != target:
        raise ValueError(f"unit {unit!r} cannot be converted to {target!r} for channel {channel!r}")
    return np.asarray(values, dtype=np.float64) * scale


def moving_mask(vx_ms) -> np.ndarray:
    """Boolean mask of the moving region |vx| >= 0.5 km/h (the blind zone is masked out)."""
    return np.abs(np.asarray(vx_ms)) >= BLIND_ZONE_MS
