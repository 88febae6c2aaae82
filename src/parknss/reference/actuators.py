"""Actuator dynamics of the reference vehicle: gear, drive torque, brake with auto-hold, steering.

Each actuator is a tiny state machine stepped once per 10 ms with plain floats (no NumPy
in the loop, so a whole campaign simulates in seconds). Units: torque N·m, pressure bar,
angles deg of steering-wheel angle, speed m/s, time s.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
from scipy.linalg import expm

from parknss.reference.params import (
    AutoHoldParams,
    BrakeParams,
    DriveParams,
    GearParams,
    SteeringParams,
)
from parknss.signals import kmh_to_ms


class DeadTime:
    """A pure delay of n = round(delay / dt) samples (n = 0 passes the input through)."""

    def __init__(self, delay_s: float, dt: float, initial: float = 0.0) -> None:
        self.n = round(delay_s / dt)
        self._buf: deque[float] = deque([initial] * self.n)

    def reset(self, value: float = 0.0) -> None:
        self._buf = deque([value] * self.n)

    def __call__(self, x: float) -> float:
        if self.n == 0:
            return x
        self._buf.append(x)
        return self._buf.popleft()


class GearSelector:
    """Shift-by-wire: the requested gear is engaged only after ``shift_time_s`` at rest.

    While |vx| exceeds the shift speed a differing request is refused (counted in
    ``refusals``) and the current gear stays. ``shifting`` is True while a request waits.
    """

    def __init__(self, p: GearParams, dt: float) -> None:
        self.max_speed = kmh_to_ms(p.max_shift_speed_kmh)
        self.n_shift = round(p.shift_time_s / dt)
        self.gear = 0
        self.shifting = False
        self.refusals = 0
        self._count = 0

    def reset(self, gear: int = 0) -> None:
        self.gear, self.shifting, self.refusals, self._count = gear, False, 0, 0

    def step(self, request: int, vx: float) -> int:
        """Advance one sample under gear `request` at true speed `vx` (m/s); return the gear."""
        if request == self.gear:
            self.shifting, self._count = False, 0
        elif abs(vx) > self.max_speed:
            self.shifting, self._count = False, 0
            self.refusals += 1
        else:
            self.shifting = True
            self._count += 1
            if self._count >= self.n_shift:
                self.gear, self.shifting, self._count = request, False, 0
        return self.gear


class DriveActuator:
    """Motor torque: dead time, creep floor in D/R, lag depending on speed and gear.

    target = 0 in neutral/park or while shifting, else min(max(cmd, creep(v_along_gear)),
    ``limit``) (``limit``: the torque the battery can supply, set per step by the vehicle;
    infinite unless a trial's conditions limit it); the torque follows the target with
    time constant
    tau = (tau_moving + (tau_standstill - tau_moving)·exp(-|v|/v_scale))·(reverse factor).
    """

    def __init__(self, p: DriveParams, dt: float) -> None:
        self.p = p
        self.dt = dt
        self.creep_fade = kmh_to_ms(p.creep_fade_kmh)
        self.v_scale = kmh_to_ms(p.tau_speed_scale_kmh)
        self.delay = DeadTime(p.delay_s, dt)
        self.torque = 0.0
        self.limit = math.inf

    def reset(self, torque: float = 0.0) -> None:
        self.torque = torque
        self.delay.reset(0.0)

    def creep(self, vx: float, gear: int) -> float:
        """Creep torque in N·m at signed speed vx (m/s) in `gear` (0 in neutral/park)."""
        if gear == 0:
            return 0.0
        along = vx * gear
        frac = 1.0 - max(along, 0.0) / self.creep_fade
        return self.p.creep_torque_nm * min(max(frac, 0.0), 1.0)

    def time_constant(self, vx: float, gear: int) -> float:
        """Lag time constant in s at speed vx (m/s) in `gear`."""
        p = self.p
        tau = p.tau_moving_s + (p.tau_standstill_s - p.tau_moving_s) * math.exp(
            -abs(vx) / self.v_scale
        )
        return tau * p.reverse_lag_factor if gear < 0 else tau

    def step(self, torque_cmd: float, gear: int, shifting: bool, vx: float) -> float:
        """Advance one sample; `torque_cmd` already clamped to [0, torque_max]. Returns N·m."""
        cmd = self.delay(torque_cmd)
        target = 0.0 if (gear == 0 or shifting) else min(max(cmd, self.creep(vx, gear)), self.limit)
        alpha = 1.0 - math.exp(-self.dt / self.time_constant(vx, gear))
        self.torque += (target - self.torque) * alpha
        return self.torque


class AutoHold:
    """Chassis auto-hold: a pressure floor no command explains, released slowly at launch."""

    def __init__(self, p: AutoHoldParams, dt: float) -> None:
        self.p = p
        self.dt = dt
        self.n_engage = round(p.engage_time_s / dt)
        self.reset()

    def reset(self) -> None:
        self.engaged = False
        self.releasing = False
        self.pressure = 0.0  # held pressure floor, bar
        self._ramp = 0.0
        self._count = 0

    def step(self, vx: float, pressure: float, torque: float, gear: int) -> float:
        """Update from the true speed (m/s), actual pressure (bar), motor torque (N·m), gear.

        Returns the pressure floor in bar that the hydraulics must keep (0 when inactive).
        """
        p = self.p
        if not p.enabled:
            return 0.0
        if not self.engaged:
            if abs(vx) < p.standstill_ms and pressure >= p.engage_min_bar:
                self._count += 1
            else:
                self._count = 0
            if self._count >= self.n_engage and self._count > 0:
                self.engaged, self.releasing = True, False
                self.pressure = max(pressure, p.hold_bar)
            return self.pressure if self.engaged else 0.0
        if not self.releasing and gear != 0 and torque >= p.release_torque_nm:
            self.releasing = True
            self._ramp = self.pressure * self.dt / p.release_time_s
        if self.releasing:
            self.pressure -= self._ramp
            if self.pressure <= 0.0:
                self.reset()
        return self.pressure


class BrakeActuator:
    """Decel command -> pressure target (dead zone, gain) -> 2nd-order hydraulics.

    The target is max(k·max(-a* - dz, 0), hold floor); the pressure follows it through
    the dead time and an exactly discretised (zero-order hold) 2nd-order lag
    p'' = ω²(target - p) - 2ζω p', floored at 0 and capped at pressure_max_bar.
    """

    def __init__(self, p: BrakeParams, dt: float) -> None:
        self.p = p
        w = 2.0 * math.pi * p.natural_freq_hz
        a = np.array([[0.0, 1.0], [-w * w, -2.0 * p.damping * w]])
        b = np.array([[0.0], [w * w]])
        m = expm(np.block([[a, b], [np.zeros((1, 3))]]) * dt)
        self._a = [[float(m[i, j]) for j in range(2)] for i in range(2)]
        self._b = [float(m[0, 2]), float(m[1, 2])]
        self.delay = DeadTime(p.delay_s, dt)
        self.pressure = 0.0
        self.rate = 0.0

    def reset(self) -> None:
        self.pressure, self.rate = 0.0, 0.0
        self.delay.reset(0.0)

    def command_target(self, decel_cmd: float) -> float:
        """Pressure in bar requested by a (clamped, <= 0) decel command in m/s²."""
        p = self.p
        return p.pressure_per_decel * max(-decel_cmd - p.dead_zone_ms2, 0.0)

    def step(self, decel_cmd: float, hold_floor: float) -> float:
        """Advance one sample; returns the master-cylinder pressure in bar."""
        target = max(self.command_target(self.delay(decel_cmd)), hold_floor)
        (a00, a01), (a10, a11) = self._a
        p0, r0 = self.pressure, self.rate
        p1 = a00 * p0 + a01 * r0 + self._b[0] * target
        r1 = a10 * p0 + a11 * r0 + self._b[1] * target
        if p1 < 0.0:
            p1, r1 = 0.0, max(r1, 0.0)
        elif p1 > self.p.pressure_max_bar:
            p1, r1 = self.p.pressure_max_bar, min(r1, 0.0)
        self.pressure, self.rate = p1, r1
        return p1


class SteeringActuator:
    """Steering-wheel angle: first-order lag toward the command, rate-limited, within lock."""

    def __init__(self, p: SteeringParams, lock_deg: float, dt: float) -> None:
        self.alpha = 1.0 - math.exp(-dt / p.lag_s)
        self.max_step = p.rate_limit_dps * dt
        self.lock = lock_deg
        self.angle = 0.0

    def reset(self, angle: float = 0.0) -> None:
        self.angle = min(max(angle, -self.lock), self.lock)

    def step(self, steer_cmd: float) -> float:
        """Advance one sample toward `steer_cmd` (deg, already clamped); returns deg."""
        delta = (steer_cmd - self.angle) * self.alpha
        delta = min(max(delta, -self.max_step), self.max_step)
        self.angle += delta
        return self.angle
