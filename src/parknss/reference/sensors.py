"""Sensors of the reference vehicle: IMU with body-tilt coupling, wheel speed, bus quantization.

All turn noise-free truth into what the bus logs, drawing noise from one seeded
``random.Random`` (plain floats: fast and reproducible across platforms). Units: m/s,
m/s², rad/s, N·m, bar, deg.
"""

from __future__ import annotations

import math
import random

from parknss.reference.params import BusParams, ImuParams, WheelSpeedParams
from parknss.signals import G, deg_to_rad, kmh_to_ms


def quantize(x: float, q: float) -> float:
    """Round x to the nearest multiple of q (ties up), as a bus signal of resolution q."""
    return math.floor(x / q + 0.5) * q


class Imu:
    """Accelerometer and gyro on the sprung body, ahead of the rear axle.

    The body pitch follows ``pitch_gradient·ax`` through a first-order lag (and roll
    ``roll_gradient·ay`` likewise); on a road of pitch θ and bank φ (a trial's floor) the
    accelerometer reads the specific force f_x = ax + g·sin(pitch + θ),
    f_y = ay + g·sin(roll + φ), f_z = g·cos(pitch + θ)·cos(roll + φ), turned into the
    sensor frame by the misalignment (pitch ``pitch_rad`` and roll ``roll_rad`` of a
    trial's conditions, then the mounting yaw), plus bias and white noise. The gyro reads
    ω + bias + drift·t + noise (t the time since reset).
    """

    def __init__(
        self,
        p: ImuParams,
        dt: float,
        rng: random.Random,
        roll_rad: float = 0.0,
        pitch_rad: float = 0.0,
        drift: float = 0.0,
    ) -> None:
        self.p = p
        self.rng = rng
        self.dt = dt
        self.tilted = roll_rad != 0.0 or pitch_rad != 0.0
        self.cr, self.sr = math.cos(roll_rad), math.sin(roll_rad)
        self.cp, self.sp = math.cos(pitch_rad), math.sin(pitch_rad)
        self.drift = drift  # yaw-rate bias change, rad/s per s
        self.n = 0
        self.alpha = 1.0 - math.exp(-dt / p.pitch_lag_s)
        self.k_pitch = deg_to_rad(p.pitch_gradient_deg)
        self.k_roll = deg_to_rad(p.roll_gradient_deg)
        psi = deg_to_rad(p.mount_yaw_deg)
        self.c, self.s = math.cos(psi), math.sin(psi)
        self.pitch = 0.0
        self.roll = 0.0

    def reset(self) -> None:
        self.pitch, self.roll, self.n = 0.0, 0.0, 0

    def step(
        self, ax: float, ay: float, yaw_rate: float, grade: float = 0.0, bank: float = 0.0
    ) -> tuple[float, float, float]:
        """True IMU-point accelerations (m/s²) and yaw rate (rad/s) on a road of pitch
        ``grade`` and bank ``bank`` (rad) -> logged (ax, ay, ω)."""
        p, rng = self.p, self.rng
        self.pitch += (self.k_pitch * ax - self.pitch) * self.alpha
        self.roll += (self.k_roll * ay - self.roll) * self.alpha
        fx = ax + G * math.sin(self.pitch + grade)
        fy = ay + G * math.sin(self.roll + bank)
        if self.tilted:
            fz = G * math.cos(self.pitch + grade) * math.cos(self.roll + bank)
            fx, fz = self.cp * fx + self.sp * fz, self.cp * fz - self.sp * fx
            fy = self.cr * fy + self.sr * fz
        ax_m = self.c * fx + self.s * fy + p.ax_bias + rng.gauss(0.0, p.ax_noise)
        ay_m = -self.s * fx + self.c * fy + p.ay_bias + rng.gauss(0.0, p.ay_noise)
        bias = p.yaw_rate_bias + self.drift * (self.n * self.dt)
        self.n += 1
        w_m = yaw_rate + bias + rng.gauss(0.0, p.yaw_rate_noise)
        return ax_m, ay_m, w_m


class WheelSpeed:
    """Wheel-speed-derived vx: quantization noise inside the blind zone, noisy above."""

    def __init__(self, p: WheelSpeedParams, rng: random.Random) -> None:
        self.p = p
        self.rng = rng
        self.blind = kmh_to_ms(p.blind_zone_kmh)
        self.res = kmh_to_ms(p.resolution_kmh)

    def read(self, vx: float) -> float:
        """Logged speed in m/s for the true signed speed vx (m/s)."""
        p, rng = self.p, self.rng
        speed = abs(vx)
        if speed < self.blind:
            if rng.random() >= p.spike_prob + p.motion_spike_prob * speed / self.blind:
                return 0.0
            mag = rng.uniform(p.spike_min_frac, p.spike_max_frac) * self.blind
            if vx != 0.0:
                return math.copysign(mag, vx)
            return mag if rng.random() < 0.5 else -mag
        v = vx + rng.gauss(0.0, p.noise_ms)
        return quantize(v, self.res) if self.res > 0.0 else v


class Bus:
    """Actuator feedback on the bus: noise, then the bus resolution (2 N·m, 1 bar, 0.1 deg)."""

    def __init__(self, p: BusParams, rng: random.Random) -> None:
        self.p = p
        self.rng = rng

    def torque(self, x: float) -> float:
        """Logged motor torque, N·m (non-negative multiple of the torque quantum)."""
        q = self.p.torque_quantum_nm
        return max(quantize(x + self.rng.gauss(0.0, self.p.torque_noise_nm), q), 0.0)

    def pressure(self, x: float) -> float:
        """Logged master-cylinder pressure, bar (non-negative multiple of the quantum)."""
        q = self.p.pressure_quantum_bar
        return max(quantize(x + self.rng.gauss(0.0, self.p.pressure_noise_bar), q), 0.0)

    def steer(self, x: float) -> float:
        """Logged steering-wheel angle, deg."""
        q = self.p.steer_quantum_deg
        return quantize(x + self.rng.gauss(0.0, self.p.steer_noise_deg), q)
