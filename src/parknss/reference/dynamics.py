"""Vehicle-body dynamics of the reference vehicle: longitudinal with stiction, low-speed yaw.

Longitudinal: m·dv/dt = F_drive + F_grade - sign(v)·(F_brake + F_roll + F_drag), with
F_drive = gear·τ·i·η/r (gear 0 gives none), F_grade = -m·g·sin θ (θ the road pitch, nose
up > 0), F_roll = c_rr·m·g·cos θ and F_drag the extra drive-unit drag of a trial's
conditions (0 for the nominal car). Brake, rolling resistance and drag are passive: they
can stop the car but never reverse it, and at rest they hold it as long as they exceed
|F_drive + F_grade| (stiction); gravity can start a car at rest (roll-back), except in
park (gear 0 at rest: the parking lock holds it).
Lateral: the path curvature follows the steady-state single-track value
κ_ss = tan(δ)/(L + K_us·v²) (δ the road-wheel angle of the nonlinear rack) over the
travelled distance with the tyre relaxation length σ, and ω = v·κ. Units: m, m/s, m/s²,
rad/s, N, s.
"""

from __future__ import annotations

import math

from parknss.reference.params import BodyParams, LateralParams
from parknss.signals import DEG_PER_RAD, G
from parknss.vehicle import VehicleGeometry


class Longitudinal:
    """Signed speed of the rear axle with a standstill (stiction) state."""

    def __init__(self, p: BodyParams, dt: float, drag_torque_nm: float = 0.0) -> None:
        self.dt = dt
        self.mass = p.mass_kg
        self.torque_to_force = p.drive_ratio * p.drive_efficiency / p.wheel_radius_m
        self.f_roll_flat = p.rolling_resistance * p.mass_kg * G
        self.f_roll = self.f_roll_flat
        self.f_grade = 0.0
        self.f_drag = drag_torque_nm * p.drive_ratio / p.wheel_radius_m
        self.vx = 0.0
        self.accel = 0.0
        self.at_rest = True

    def reset(self, vx: float = 0.0) -> None:
        self.vx, self.accel, self.at_rest = vx, 0.0, vx == 0.0

    def set_grade(self, pitch: float) -> None:
        """Road pitch in rad under the car (nose up > 0) for the next steps."""
        self.f_grade = -self.mass * G * math.sin(pitch)
        self.f_roll = self.f_roll_flat * math.cos(pitch)

    def drive_force(self, torque: float, gear: int) -> float:
        """Tractive force in N, signed along the body x axis."""
        return gear * torque * self.torque_to_force

    def step(self, torque: float, gear: int, brake_force: float) -> float:
        """Advance one sample with motor torque (N·m), gear and brake force (N, >= 0).

        Returns the new signed speed (m/s); ``accel`` holds the mean dv/dt of the step.
        """
        f_active = self.drive_force(torque, gear) + self.f_grade
        f_resist = brake_force + self.f_roll + self.f_drag
        v0 = self.vx
        if self.at_rest:
            if gear == 0 or abs(f_active) <= f_resist:
                self.accel = 0.0
                return 0.0
            a = (f_active - math.copysign(f_resist, f_active)) / self.mass
            self.vx, self.accel, self.at_rest = a * self.dt, a, False
            return self.vx
        a = (f_active - math.copysign(f_resist, v0)) / self.mass
        v1 = v0 + a * self.dt
        if v1 * v0 <= 0.0:
            # the speed reaches zero within this step: the car comes to rest. Passive forces
            # cannot push it further; a drive or gravity force opposing the motion may break
            # it away the other way from rest on the next step (stiction logic above).
            v1 = 0.0
            self.at_rest = True
        self.accel = (v1 - v0) / self.dt
        self.vx = v1
        return v1


class Lateral:
    """Yaw rate of the low-speed single-track model with the nonlinear rack.

    κ relaxes toward κ_ss over distance (exactly discretised for the step's |v|·dt), so
    at rest it keeps the tyres' wound-up state and a steering change made at standstill
    reaches the path over the first σ metres once the car rolls.
    """

    def __init__(self, p: LateralParams, geom: VehicleGeometry, dt: float) -> None:
        self.sigma = p.relaxation_length_m
        self.k_us = p.understeer_gradient
        self.geom = geom
        self.dt = dt
        self.curvature = 0.0
        self.yaw_rate = 0.0
        self.yaw_accel = 0.0

    def reset(self, yaw_rate: float = 0.0, vx: float = 0.0) -> None:
        self.curvature = yaw_rate / vx if vx != 0.0 else 0.0
        self.yaw_rate, self.yaw_accel = yaw_rate, 0.0

    def road_wheel_angle(self, steer_deg: float) -> float:
        """Road-wheel angle in rad of the nonlinear rack (plain-float twin of vehicle.py)."""
        g = self.geom
        frac = min(abs(steer_deg) / g.steer_lock_deg, 1.0)
        ratio = g.steer_ratio_lock + (g.steer_ratio_center - g.steer_ratio_lock) * (
            1.0 - frac * frac
        )
        return steer_deg / ratio / DEG_PER_RAD

    def steady_curvature(self, vx: float, steer_deg: float) -> float:
        """Steady-state path curvature in 1/m at speed vx (m/s) and steering angle (deg)."""
        tan_d = math.tan(self.road_wheel_angle(steer_deg))
        return tan_d / (self.geom.wheelbase + self.k_us * vx * vx)

    def step(self, vx: float, steer_deg: float) -> float:
        """Advance one sample; returns the yaw rate in rad/s (``yaw_accel`` in rad/s²)."""
        alpha = 1.0 - math.exp(-abs(vx) * self.dt / self.sigma)
        self.curvature += (self.steady_curvature(vx, steer_deg) - self.curvature) * alpha
        w0 = self.yaw_rate
        w1 = vx * self.curvature
        self.yaw_accel = (w1 - w0) / self.dt
        self.yaw_rate = w1
        return w1
