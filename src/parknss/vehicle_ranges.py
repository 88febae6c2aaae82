"""Physical ranges of the vehicle parameters a user supplies (a ``--vehicle`` YAML, the
reference vehicle's parameters, a mapping's ``vehicle.geometry``).

A value outside its range is refused in one line that names the parameter, the value and
the range (:func:`check_vehicle`); nothing is clamped. The ranges span cars from a city
two-seater to a long van at parking speeds, with margin; they exist to catch typos and
hostile files (``steer_lock_deg: 100000``, ``wheelbase: 1e-9``), not to judge a design.
The numeric code of :mod:`parknss.vehicle` is unchanged: the check runs where the values
are loaded (:func:`parknss.sim.vehicles.resolve_vehicle`,
:func:`parknss.reference.params.load_vehicle_params`, the import mapping).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from parknss.errors import ConfigError


@dataclass(frozen=True)
class Range:
    """An inclusive physical range [lo, hi] of one parameter, in ``unit``."""

    lo: float
    hi: float
    unit: str

    def text(self) -> str:
        return f"[{self.lo:g}, {self.hi:g}] {self.unit}".rstrip()


RANGES: dict[str, Range] = {
    # geometry (parknss.vehicle.VehicleGeometry)
    "wheelbase": Range(1.5, 7.0, "m"),
    "track": Range(0.9, 2.6, "m"),
    "steer_lock_deg": Range(90.0, 1440.0, "deg of steering-wheel angle"),
    "steer_ratio": Range(5.0, 40.0, ""),
    "steer_ratio_center": Range(5.0, 40.0, ""),
    "steer_ratio_lock": Range(5.0, 40.0, ""),
    "length": Range(2.0, 15.0, "m"),
    "width": Range(1.0, 3.0, "m"),
    "rear_overhang": Range(0.1, 5.0, "m"),
    # body (parknss.reference.params.BodyParams)
    "mass_kg": Range(300.0, 20000.0, "kg"),
    "wheel_radius_m": Range(0.15, 0.8, "m"),
    # drive and brake limits (parknss.reference.params)
    "torque_max_nm": Range(10.0, 10000.0, "N·m"),
    "pressure_max_bar": Range(10.0, 300.0, "bar"),
}
"""Parameter name -> its physical range (inclusive)."""

DERIVED: dict[str, Range] = {
    "front_overhang": Range(0.1, 5.0, "m"),
    "road_wheel_lock_deg": Range(10.0, 60.0, "deg"),
}
"""Quantities derived from the geometry: front overhang (length - wheelbase - rear
overhang) and the road-wheel angle at the lock (steer_lock_deg / steer_ratio_lock)."""


def _check(name: str, value: object, rng: Range, source: str) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{source}: {name} must be a number, got {value!r}")
    if not math.isfinite(value) or not rng.lo <= value <= rng.hi:
        raise ConfigError(
            f"{source}: {name}: {value:g} is outside the physical range {rng.text()}"
        )


def check_vehicle(values: Mapping[str, object], source: str) -> None:
    """Refuse, in one ConfigError line naming ``source``, the parameter and its range, any
    value of ``values`` (name -> value; names without a range are skipped) outside
    :data:`RANGES`, and, when the geometry is complete enough, a derived quantity outside
    :data:`DERIVED`."""
    for name, value in values.items():
        if name in RANGES:
            _check(name, value, RANGES[name], source)
    if {"length", "wheelbase", "rear_overhang"} <= set(values):
        front = float(values["length"]) - float(values["wheelbase"]) - float(
            values["rear_overhang"])
        _check("front_overhang (length - wheelbase - rear_overhang)", front,
               DERIVED["front_overhang"], source)
    if {"steer_lock_deg", "steer_ratio_lock"} <= set(values):
        wheel = float(values["steer_lock_deg"]) / float(values["steer_ratio_lock"])
        _check("road_wheel_lock_deg (steer_lock_deg / steer_ratio_lock)", wheel,
               DERIVED["road_wheel_lock_deg"], source)


def range_table() -> str:
    """The ranges as a Markdown table (docs)."""
    rows = [f"| `{k}` | {r.lo:g} | {r.hi:g} | {r.unit} |" for k, r in RANGES.items()]
    rows += [f"| {k} (derived) | {r.lo:g} | {r.hi:g} | {r.unit} |" for k, r in DERIVED.items()]
    return "\n".join(["| parameter | min | max | unit |", "| --- | --- | --- | --- |", *rows])
