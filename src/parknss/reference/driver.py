"""An APS-like scripted driver: closed loop on the logged signals, as a real APS would be.

It executes a :class:`~parknss.reference.maneuvers.ManeuverPlan` with the production
command set {gear, torque_cmd, decel_cmd, steer_cmd}:

* a gear state machine that shifts only at confirmed standstill, directly between
  reverse and drive (never through neutral), and to park (0) at the very end;
* a stop and hold (deceleration command) at every direction change; the steering for
  the next segment is turned during that hold, i.e. at standstill, before moving off;
* a launch that ramps the torque request until the wheel speed leaves the blind zone
  (pushing through the vehicle's auto-hold), then a speed controller: a
  reference that ramps up, cruises and falls as sqrt(2·a·remaining distance), tracked
  by a PI force controller split into a torque request (when more than the creep force
  is needed) or a deceleration request (when less);
* distance from the logged wheel speed, standstill when it reads inside the blind zone;
* a road-slope estimate from the logged longitudinal acceleration at standstill (as an
  ESC's hill-hold does): beyond ``slope_threshold`` it adds the grade force to the speed
  controller, the launch torque and the holding deceleration; below it (flat floors,
  accelerometer bias) the driver ignores it;
* two fallbacks a real APS also has: a stop that does not come to rest within
  ``stop_timeout_s`` brakes harder, and a launch that has not moved within
  ``launch_timeout_s`` of reaching its torque keeps raising it.
"""

from __future__ import annotations

import math

from pydantic import Field

from parknss.config import StrictModel
from parknss.plant import Commands, PlantOutput
from parknss.reference.maneuvers import ManeuverPlan, SegmentPlan
from parknss.reference.params import ReferenceVehicleParams
from parknss.signals import BLIND_ZONE_MS, DT, G, kmh_to_ms


class DriverParams(StrictModel):
    """Calibration of the scripted APS driver (units in each description)."""

    accel: float = Field(0.5, gt=0, description="speed-reference ramp-up, m/s²")
    decel: float = Field(0.4, gt=0, description="speed-reference approach decel, m/s²")
    kp: float = Field(2.0, ge=0, description="speed-error gain, 1/s")
    ki: float = Field(1.0, ge=0, description="speed-error integral gain, 1/s²")
    integral_max: float = Field(0.5, ge=0, description="integral clamp, m/s²")
    decel_cmd_min: float = Field(-0.8, lt=0, description="deceleration request floor, m/s²")
    hold_decel: float = Field(0.6, gt=0, description="deceleration held at stops, m/s²")
    launch_torque_nm: float = Field(45.0, gt=0, description="launch torque request, N·m")
    launch_rate_nms: float = Field(150.0, gt=0, description="launch torque ramp, N·m/s")
    stop_distance_m: float = Field(0.03, ge=0, description="stop margin before the end, m")
    brake_latency_s: float = Field(0.15, ge=0, description="assumed brake latency, s")
    standstill_s: float = Field(0.3, ge=0, description="blind-zone time confirming stop, s")
    steer_rate_dps: float = Field(400.0, gt=0, description="steering request slew, deg/s")
    steer_tolerance_deg: float = Field(3.0, gt=0, description="steer settled within, deg")
    slope_filter_s: float = Field(0.2, gt=0, description="slope-estimate filter time, s")
    slope_threshold: float = Field(
        0.015, ge=0, description="slope (sin) below which the estimate is ignored, -"
    )
    stop_timeout_s: float = Field(4.0, gt=0, description="stop not at rest after this, s")
    stop_extra_rate: float = Field(0.5, ge=0, description="extra decel request growth, m/s³")
    launch_timeout_s: float = Field(2.5, gt=0, description="launch not moving after this, s")
    launch_extra_rate_nms: float = Field(
        40.0, ge=0, description="launch torque growth after the timeout, N·m/s"
    )


IDLE, HOLD, LAUNCH, DRIVE, STOP, PARK, DONE = (
    "idle",
    "hold",
    "launch",
    "drive",
    "stop",
    "park",
    "done",
)


class ApsDriver:
    """Closed-loop driver of one maneuver plan; call :meth:`command` once per 10 ms.

    The force model is calibrated on the vehicle it drives (mass, driveline, creep
    torque, rolling resistance), as a production APS is; the integral absorbs the rest.
    """

    def __init__(
        self,
        plan: ManeuverPlan,
        vehicle: ReferenceVehicleParams,
        params: DriverParams | None = None,
        dt: float = DT,
    ) -> None:
        self.plan = plan
        self.p = params or DriverParams()
        self.dt = dt
        b = vehicle.body
        self.mass = b.mass_kg
        self.k_tf = b.drive_ratio * b.drive_efficiency / b.wheel_radius_m  # N per N·m
        self.f_roll = b.rolling_resistance * b.mass_kg * G
        self.creep_nm = vehicle.drive.creep_torque_nm
        self.creep_fade = kmh_to_ms(vehicle.drive.creep_fade_kmh)
        self.decel_floor = vehicle.brake.decel_cmd_min
        self.phase = IDLE
        self.seg_index = 0
        self.t_phase = 0.0
        self.gear = 0
        self.steer = 0.0
        self.torque = 0.0
        self.decel = -self.p.hold_decel
        self.s = 0.0
        self.v_ref = 0.0
        self.integral = 0.0
        self._still = 0.0
        self._ax_still = 0.0  # filtered logged ax at confirmed standstill, m/s²
        self.slope = 0.0  # slope estimate (sin of the pitch, nose up > 0) in use, -

    # ------------------------------------------------------------------ public
    @property
    def done(self) -> bool:
        return self.phase == DONE

    @property
    def segment(self) -> SegmentPlan:
        return self.plan.segments[self.seg_index]

    def command(self, y: PlantOutput) -> Commands:
        """Next command from the logged output `y` of the current sample."""
        dt = self.dt
        self.t_phase += dt
        self._still = self._still + dt if abs(y.vx) < BLIND_ZONE_MS else 0.0
        if self._still >= self.p.standstill_s and self.phase in (IDLE, HOLD, STOP, PARK):
            self._estimate_slope(y.ax)  # braked and at rest: ax reads the slope
        getattr(self, f"_{self.phase}")(y)
        return Commands(self.gear, self.torque, self.decel, self.steer)

    # ------------------------------------------------------------------ phases
    def _goto(self, phase: str) -> None:
        self.phase, self.t_phase = phase, 0.0

    def _idle(self, y: PlantOutput) -> None:
        self.torque, self.decel = 0.0, -self._hold_decel()
        if self.t_phase >= self.plan.idle_start_s:
            self._goto(HOLD)

    def _hold(self, y: PlantOutput) -> None:
        """At standstill: keep braking, engage the segment's gear, turn to its start angle."""
        seg = self.segment
        self.torque, self.decel = 0.0, -self._hold_decel()
        if self._still >= self.p.standstill_s:
            self.gear = seg.direction
        self._slew(seg.steer_start_deg)
        settled = abs(y.steer - seg.steer_start_deg) <= self.p.steer_tolerance_deg
        if self.t_phase >= seg.hold_s and y.gear == self.gear == seg.direction and settled:
            self.s, self.v_ref, self.integral = 0.0, 0.0, 0.0
            self._goto(LAUNCH)

    def _launch(self, y: PlantOutput) -> None:
        """Release the brake request and ramp the torque request until the car moves."""
        p, dt = self.p, self.dt
        self.decel = 0.0
        target = p.launch_torque_nm + max(self._grade_force(), 0.0) / self.k_tf
        ramp_end = target / p.launch_rate_nms + p.launch_timeout_s
        if self.t_phase > ramp_end:  # not moving: the slope is steeper than estimated
            self.torque += p.launch_extra_rate_nms * dt
        else:
            self.torque = min(self.torque + p.launch_rate_nms * dt, target)
        self.s += abs(y.vx) * dt
        if abs(y.vx) >= BLIND_ZONE_MS:
            self.v_ref = max(y.vx * self.segment.direction, 0.0)
            self.integral = 0.0
            self._goto(DRIVE)

    def _drive(self, y: PlantOutput) -> None:
        """Track the speed reference along the segment and its steering profile."""
        p, seg, dt = self.p, self.segment, self.dt
        u = y.vx * seg.direction  # speed along the gear direction, m/s
        self.s += abs(y.vx) * dt
        remaining = seg.length_m - self.s
        v_cap = math.sqrt(2.0 * p.decel * max(remaining - p.stop_distance_m, 0.0))
        v_ref = min(kmh_to_ms(seg.speed_kmh), self.v_ref + p.accel * dt, v_cap)
        a_ff = (v_ref - self.v_ref) / dt
        self.v_ref = v_ref
        err = v_ref - u
        self.integral += p.ki * err * dt
        self.integral = min(max(self.integral, -p.integral_max), p.integral_max)
        force = self.mass * (a_ff + p.kp * err + self.integral) + self.f_roll
        if self.slope != 0.0:
            force += self._grade_force()
        creep = self._creep_force(u)
        if force >= creep:
            self.torque, self.decel = force / self.k_tf, 0.0
        else:
            self.torque = 0.0
            self.decel = max(-(creep - force) / self.mass, p.decel_cmd_min)
        self._slew(seg.steer_at(min(self.s / seg.length_m, 1.0)))
        if remaining <= self._braking_distance(u) + p.stop_distance_m:
            self._goto(STOP)

    def _stop(self, y: PlantOutput) -> None:
        """Brake to standstill at the end of the segment, then go to the next one."""
        seg = self.segment
        self.torque, self.decel = 0.0, -self._hold_decel()
        if self.t_phase > self.p.stop_timeout_s:  # still rolling: brake harder
            self.decel -= self.p.stop_extra_rate * (self.t_phase - self.p.stop_timeout_s)
            self.decel = max(self.decel, self.decel_floor)
        self._slew(seg.steer_end_deg)
        if self._still >= self.p.standstill_s:
            if self.seg_index + 1 < len(self.plan.segments):
                self.seg_index += 1
                self._goto(HOLD)
            else:
                self._goto(PARK)

    def _park(self, y: PlantOutput) -> None:
        """Hold, shift to park, release the request and idle to the end of the trial."""
        self.torque = 0.0
        if self.t_phase < self.segment.hold_s:
            self.decel = -self._hold_decel()
            return
        self.gear = 0
        self.decel = 0.0 if y.gear == 0 else -self._hold_decel()
        if y.gear == 0 and self.t_phase >= self.segment.hold_s + self.plan.idle_end_s:
            self._goto(DONE)

    def _done(self, y: PlantOutput) -> None:
        self.torque, self.decel = 0.0, 0.0

    # ------------------------------------------------------------------ helpers
    def _estimate_slope(self, ax_logged: float) -> None:
        """Update the slope estimate from the logged ax (m/s²) at confirmed standstill:
        at rest the accelerometer reads g·sin(pitch) (plus its bias)."""
        p = self.p
        alpha = 1.0 - math.exp(-self.dt / p.slope_filter_s)
        self._ax_still += (ax_logged - self._ax_still) * alpha
        est = min(max(self._ax_still / G, -1.0), 1.0)
        self.slope = est if abs(est) >= p.slope_threshold else 0.0

    def _grade_force(self) -> float:
        """Estimated grade force (N) to overcome along the segment's direction."""
        return self.mass * G * self.slope * self.segment.direction

    def _hold_decel(self) -> float:
        """Deceleration request (m/s², > 0) that holds the car on the estimated slope."""
        return self.p.hold_decel + G * abs(self.slope)

    def _creep_force(self, u: float) -> float:
        """Calibrated creep force (N) along the gear direction at speed u (m/s)."""
        frac = min(max(1.0 - max(u, 0.0) / self.creep_fade, 0.0), 1.0)
        return self.creep_nm * frac * self.k_tf

    def _braking_distance(self, u: float) -> float:
        """Predicted path (m) to stop from speed u (m/s) under the hold deceleration."""
        u = max(u, 0.0)
        return u * u / (2.0 * self.p.hold_decel) + u * self.p.brake_latency_s

    def _slew(self, target: float) -> None:
        """Move the steering request toward `target` (deg) at the APS slew rate."""
        step = self.p.steer_rate_dps * self.dt
        self.steer += min(max(target - self.steer, -step), step)
