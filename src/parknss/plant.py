"""The one Plant protocol shared by every executable vehicle: reference, chain, kinematic.

A plant consumes the production command set {gear, torque_cmd, decel_cmd, steer_cmd} at
100 Hz and returns what the car's bus would log. Pose is not part of a plant: the closed
loop integrates (x, y, heading) of the rear axle from vx and yaw rate. The closed loop
drives every plant through this protocol (:mod:`parknss.sim.plants`); the ideal
kinematic plant, which has no actuators, gets the speed it executes from its own command
interface adapter, not through the Commands.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np


@dataclass(frozen=True)
class Commands:
    """One 10 ms command sample. gear in {-1, 0, 1}; torque_cmd N·m; decel_cmd m/s² (<= 0);
    steer_cmd deg of steering-wheel angle."""

    gear: int
    torque_cmd: float
    decel_cmd: float
    steer_cmd: float

    def as_array(self) -> np.ndarray:
        return np.array([self.gear, self.torque_cmd, self.decel_cmd, self.steer_cmd], float)


@dataclass(frozen=True)
class PlantOutput:
    """What the bus logs after one step: actuals (torque N·m, brake_pressure bar, steer deg),
    states (vx m/s, yaw_rate rad/s) and IMU outputs (ax, ay m/s²)."""

    gear: int
    torque: float
    brake_pressure: float
    steer: float
    vx: float
    yaw_rate: float
    ax: float
    ay: float


@runtime_checkable
class Plant(Protocol):
    """A vehicle that can be stepped at a fixed dt (s)."""

    dt: float

    def reset(
        self, vx: float = 0.0, yaw_rate: float = 0.0, steer: float = 0.0, gear: int = 0
    ) -> PlantOutput:
        """Start from the given state (at rest by default); return the first output."""
        ...

    def step(self, cmd: Commands) -> PlantOutput:
        """Advance one dt under command `cmd` and return the new output."""
        ...
