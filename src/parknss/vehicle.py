"""Vehicle geometry and the kinematic-bicycle relations shared by every part of parknss.

Defaults are the paper's test vehicle (EXEED Sterra ES, §IV-A): wheelbase 3.0 m, track
1.695 m, steering-wheel lock ±400°, steering ratio 12.1 (rack mildly nonlinear: about 13
near centre, 12.1 toward the lock). Functions accept floats, NumPy arrays or torch tensors.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

from parknss.errors import ConfigError


@dataclass(frozen=True)
class VehicleGeometry:
    """Fixed vehicle constants. Lengths in m, angles in deg of steering-wheel angle."""

    wheelbase: float = 3.0
    track: float = 1.695
    steer_lock_deg: float = 400.0
    steer_ratio: float = 12.1
    steer_ratio_center: float = 13.0
    steer_ratio_lock: float = 12.1
    length: float = 4.95
    width: float = 1.98
    rear_overhang: float = 1.0

    @property
    def front_overhang(self) -> float:
        """Distance front axle -> front bumper, m."""
        return self.length - self.wheelbase - self.rear_overhang

    def min_turning_radius(self) -> float:
        """Rear-axle turning radius at the steering lock (nonlinear rack), m."""
        return min_turning_radius(self)

    def to_dict(self) -> dict[str, float]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> VehicleGeometry:
        known = {k: float(v) for k, v in d.items() if k in cls.__dataclass_fields__}
        return cls(**known)


def load_vehicle_geometry(path: str | Path) -> VehicleGeometry:
    """The geometry of a vehicle YAML: its ``geometry:`` section (the reference vehicle
    files' layout; the rest of such a file is ignored) or, without one, the top level.

    Keys are the fields of :class:`VehicleGeometry` (m, deg of steering-wheel angle);
    omitted ones keep the defaults. One-line ConfigError for a missing file, an unknown
    key, or a value that is not a positive finite number.
    """
    import yaml

    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{p}: vehicle file not found")
    try:
        doc = yaml.safe_load(p.read_text()) or {}
    except yaml.YAMLError as exc:
        raise ConfigError(f"{p}: not valid YAML ({exc.__class__.__name__})") from exc
    section = doc.get("geometry", doc) if isinstance(doc, dict) else None
    if not isinstance(section, dict):
        raise ConfigError(f"{p}: expected a mapping with a 'geometry' section")
    known = {f.name for f in fields(VehicleGeometry)}
    unknown = sorted(set(section) - known)
    if unknown:
        raise ConfigError(f"{p}: unknown geometry key(s) {unknown}; known: {sorted(known)}")
    values = {}
    for k, v in section.items():
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v <= 0:
            raise ConfigError(f"{p}: geometry.{k} must be a positive number, got {v!r}")
        values[k] = float(v)
    geom = VehicleGeometry(**values)
    if geom.front_overhang < 0:
        raise ConfigError(f"{p}: length must cover wheelbase + rear_overhang")
    if geom.steer_ratio_center < geom.steer_ratio_lock:
        raise ConfigError(f"{p}: steer_ratio_center must be >= steer_ratio_lock")
    return geom


def same_geometry(a: VehicleGeometry, b: VehicleGeometry, rtol: float = 1e-6) -> list[str]:
    """The fields in which two geometries differ (relative tolerance ``rtol``); [] if none."""
    return [
        f.name
        for f in fields(VehicleGeometry)
        if not math.isclose(getattr(a, f.name), getattr(b, f.name), rel_tol=rtol)
    ]


def _tan(x):
    if hasattr(x, "tan") and not isinstance(x, np.ndarray):
        return x.tan()  # torch tensor
    return np.tan(x)


def _abs(x):
    return abs(x) if not isinstance(x, np.ndarray) else np.abs(x)


def steering_ratio_at(steer_deg, geom: VehicleGeometry):
    """Nonlinear rack ratio i(δ_sw): i_center at centre, falling quadratically to i_lock.

    i(δ) = i_lock + (i_center - i_lock) · (1 - min(|δ|/lock, 1)²). The road-wheel angle
    δ/i(δ) is strictly increasing in δ for any i_center >= i_lock > 0.
    """
    frac = _abs(steer_deg) / geom.steer_lock_deg
    frac = frac.clamp(max=1.0) if hasattr(frac, "clamp") else np.minimum(frac, 1.0)
    return geom.steer_ratio_lock + (geom.steer_ratio_center - geom.steer_ratio_lock) * (
        1.0 - frac * frac
    )


def road_wheel_angle(steer_deg, geom: VehicleGeometry, nonlinear: bool = False):
    """Road-wheel angle in rad from steering-wheel angle in deg.

    With ``nonlinear=False`` the constant ratio ``geom.steer_ratio`` is used (the paper's
    kinematic prior, eq. 4); with ``nonlinear=True`` the nonlinear rack of the vehicle.
    """
    ratio = steering_ratio_at(steer_deg, geom) if nonlinear else geom.steer_ratio
    return steer_deg / ratio * (math.pi / 180.0)


def yaw_rate_ref(vx, steer_deg, geom: VehicleGeometry, nonlinear: bool = False):
    """Kinematic-bicycle yaw rate ω_ref = vx / L · tan(δ_sw / i_sw) (paper eq. 4).

    vx in m/s (signed), steer_deg in deg of steering-wheel angle; returns rad/s, same shape.
    """
    return vx / geom.wheelbase * _tan(road_wheel_angle(steer_deg, geom, nonlinear))


def curvature(steer_deg, geom: VehicleGeometry, nonlinear: bool = False):
    """Path curvature of the rear axle, 1/m, for a steering-wheel angle in deg."""
    return _tan(road_wheel_angle(steer_deg, geom, nonlinear)) / geom.wheelbase


def steer_for_curvature(kappa, geom: VehicleGeometry) -> np.ndarray:
    """Steering-wheel angle (deg) that gives curvature kappa (1/m) with the constant ratio."""
    return np.degrees(np.arctan(np.asarray(kappa) * geom.wheelbase)) * geom.steer_ratio


def min_turning_radius(geom: VehicleGeometry) -> float:
    """Rear-axle turning radius at the steering lock with the nonlinear rack, m (~4.6 m)."""
    delta = geom.steer_lock_deg / geom.steer_ratio_lock * math.pi / 180.0
    return geom.wheelbase / math.tan(delta)


_SCALAR = (float, int)


def arc_step(x, y, heading, ds, dheading):
    """The exact pose step along a circular arc: the one source of this geometry.

    From the rear-axle pose (x m, y m, heading rad), travel ``ds`` m (signed: negative in
    reverse) along the arc that turns the heading by ``dheading`` rad, i.e. at constant
    curvature kappa = dheading / ds (a straight line when dheading = 0). The position
    moves along the chord, of length ds·sinc(dheading/2), in the direction
    heading + dheading/2; the heading becomes heading + dheading (not wrapped). This is
    the kinematic bicycle integrated exactly over a step of constant curvature (the
    planner's arcs: dheading = kappa·ds) or of constant speed and yaw rate (the closed
    loop: ds = vx·dt, dheading = ω·dt), and stays finite when kappa is unbounded
    (ds = 0, dheading != 0: turning on the spot).

    Python (or NumPy float64) scalars are computed with ``math``, for the 100 Hz loop and
    the per-node search; otherwise NumPy broadcasts the arguments to one shape (N,) and
    returns arrays of it. Both evaluate the same formula.

    Returns:
        (x, y, heading) after the step: floats, or arrays of the broadcast shape.
    """
    s = _SCALAR
    if (
        isinstance(ds, s)
        and isinstance(dheading, s)
        and isinstance(x, s)
        and isinstance(y, s)
        and isinstance(heading, s)
    ):
        half = 0.5 * dheading
        chord = ds * (math.sin(half) / half if abs(half) > 1e-12 else 1.0 - half * half / 6.0)
        ang = heading + half
        return x + chord * math.cos(ang), y + chord * math.sin(ang), heading + dheading
    dth = np.asarray(dheading, dtype=float)
    chord = np.asarray(ds, dtype=float) * np.sinc(dth / (2.0 * math.pi))  # sin(πu)/(πu)
    mid = heading + 0.5 * dth
    return x + chord * np.cos(mid), y + chord * np.sin(mid), heading + dth
