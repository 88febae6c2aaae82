"""Vehicle geometry and the kinematic-bicycle relations shared by every part of parknss.

Defaults are the paper's test vehicle (EXEED Sterra ES, §IV-A): wheelbase 3.0 m, track
1.695 m, steering-wheel lock ±400°, steering ratio 12.1 (rack mildly nonlinear: about 13
near centre, 12.1 toward the lock). Functions accept floats, NumPy arrays or torch tensors.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np


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
