"""Synthetic trials for the data-layer tests, built with NumPy only (no reference vehicle).

``kinematic_trial`` drives 30 s: park, shift to R at standstill, a reverse arc, a stop
with brake hold, shift to D at standstill, a forward arc, stop. The yaw rate is exactly
the kinematic-bicycle one (eq. 4) of the given wheelbase and constant steering ratio.
"""

from __future__ import annotations

import numpy as np

from parknss.data.trial import Trial
from parknss.signals import DT
from parknss.vehicle import VehicleGeometry, yaw_rate_ref

V_REVERSE = 0.8  # m/s peak speed of the reverse arc
V_FORWARD = 0.7  # m/s peak speed of the forward arc


def _bump(t: np.ndarray, start: float, length: float) -> np.ndarray:
    """sin² bump: 0 outside [start, start+length], 1 at its middle, smooth at both ends."""
    s = (t - start) / length
    return np.where((s > 0.0) & (s < 1.0), np.sin(np.pi * s) ** 2, 0.0)


def kinematic_trial(
    ratio: float = 12.1,
    wheelbase: float = 3.0,
    duration_s: float = 30.0,
    trial_id: str = "park_in_left_r1",
) -> Trial:
    """A plausible 100 Hz maneuver with one R -> D change at standstill (see module doc)."""
    n = round(duration_s / DT)
    t = np.arange(n) * DT
    vx = -V_REVERSE * _bump(t, 2.0, 10.0) + V_FORWARD * _bump(t, 15.0, 12.0)
    gear = np.where(t < 1.0, 0.0, np.where(t < 13.5, -1.0, 1.0))
    steer = 350.0 * np.sin(2.0 * np.pi * t / 20.0)
    geom = VehicleGeometry(wheelbase=wheelbase, steer_ratio=ratio)
    yaw = yaw_rate_ref(vx, steer, geom)
    moving = np.abs(vx) > 1e-3
    torque_cmd = np.where(moving, 40.0 + 60.0 * np.abs(vx), 0.0)
    ch = {
        "t": t,
        "gear": gear,
        "torque_cmd": torque_cmd,
        "torque": 2.0 * np.round(torque_cmd / 2.0),
        "decel_cmd": np.where(moving, 0.0, -2.0),
        "brake_pressure": np.where(moving, 0.0, 20.0),
        "steer_cmd": 350.0 * np.sin(2.0 * np.pi * (t + 0.1) / 20.0),
        "steer": steer,
        "vx": vx,
        "yaw_rate": yaw,
        "ax": np.gradient(vx, DT),
        "ay": vx * yaw,
        "truth_vx": vx.copy(),
    }
    cls, rep = trial_id.rsplit("_r", 1)
    return Trial(trial_id, cls, int(rep), ch, vehicle_id="synthetic", provenance="test")
