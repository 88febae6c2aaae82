"""Parameters of the synthetic reference vehicle, every one named, with its unit.

The defaults describe a car like the paper's test vehicle (§IV-A: a ~2.1 t battery-electric
sedan, wheelbase 3.0 m, steering ratio 12.1 with a mildly nonlinear rack) at parking speeds.
Values the paper states (geometry, quantization 2 N·m / 1 bar, blind zone 0.5 km/h) are
the paper's; the others are plausible magnitudes for such a car, chosen so that every
phenomenon of DESIGN.md is visible in the logs. ``configs/reference_vehicle.yaml`` lists
them all; load a variant with :func:`load_vehicle_params`.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from pydantic import Field

from parknss.config import StrictModel, load_config, override
from parknss.reference.conditions import ConditionsConfig
from parknss.signals import BLIND_ZONE_KMH
from parknss.vehicle import VehicleGeometry
from parknss.vehicle_ranges import check_vehicle


class GeometryParams(StrictModel):
    """Fixed geometry (paper §IV-A). Lengths in m, angles in deg of steering-wheel angle."""

    wheelbase: float = Field(3.0, gt=0, description="wheelbase L, m")
    track: float = Field(1.695, gt=0, description="track width, m")
    steer_lock_deg: float = Field(400.0, gt=0, description="steering-wheel lock, ±deg")
    steer_ratio: float = Field(12.1, gt=0, description="nominal (kinematic-prior) ratio, -")
    steer_ratio_center: float = Field(13.0, gt=0, description="rack ratio near centre, -")
    steer_ratio_lock: float = Field(12.1, gt=0, description="rack ratio at the lock, -")
    length: float = Field(4.95, gt=0, description="body length, m")
    width: float = Field(1.98, gt=0, description="body width, m")
    rear_overhang: float = Field(1.0, ge=0, description="rear axle -> rear bumper, m")

    def to_geometry(self) -> VehicleGeometry:
        """The :class:`~parknss.vehicle.VehicleGeometry` shared with the rest of parknss."""
        return VehicleGeometry(**self.model_dump())


class BodyParams(StrictModel):
    """Mass and driveline constants of the longitudinal model."""

    mass_kg: float = Field(2100.0, gt=0, description="vehicle mass with driver, kg")
    wheel_radius_m: float = Field(0.36, gt=0, description="dynamic rolling radius, m")
    drive_ratio: float = Field(9.0, gt=0, description="motor -> wheel gear ratio, -")
    drive_efficiency: float = Field(0.92, gt=0, le=1, description="driveline efficiency, -")
    rolling_resistance: float = Field(0.012, ge=0, description="rolling-resistance coeff., -")


class DriveParams(StrictModel):
    """Electric drive: torque lag depending on speed and gear, and creep torque.

    The motor torque follows its target through a pure delay and a first-order lag whose
    time constant is ``tau_standstill_s`` at rest, falling toward ``tau_moving_s`` with
    speed (e-folding speed ``tau_speed_scale_kmh``) and multiplied by ``reverse_lag_factor``
    in reverse. In D or R the motor delivers at least the creep torque, which fades
    linearly from ``creep_torque_nm`` at rest to zero at ``creep_fade_kmh``.
    """

    torque_max_nm: float = Field(300.0, gt=0, description="torque command clamp, N·m")
    creep_torque_nm: float = Field(20.0, ge=0, description="creep torque at rest, N·m")
    creep_fade_kmh: float = Field(4.0, gt=0, description="speed where creep reaches 0, km/h")
    delay_s: float = Field(0.03, ge=0, description="command dead time, s")
    tau_standstill_s: float = Field(0.25, gt=0, description="torque lag at rest, s")
    tau_moving_s: float = Field(0.08, gt=0, description="torque lag when moving, s")
    tau_speed_scale_kmh: float = Field(1.0, gt=0, description="lag e-folding speed, km/h")
    reverse_lag_factor: float = Field(1.5, gt=0, description="lag multiplier in R, -")


class BrakeParams(StrictModel):
    """Brake: decel command -> master-cylinder pressure (dead zone, 2nd order) -> force."""

    decel_cmd_min: float = Field(-5.0, lt=0, description="decel command clamp, m/s²")
    dead_zone_ms2: float = Field(0.05, ge=0, description="command dead zone, m/s²")
    pressure_per_decel: float = Field(10.0, gt=0, description="pressure gain, bar/(m/s²)")
    force_per_bar: float = Field(210.0, gt=0, description="total brake force gain, N/bar")
    natural_freq_hz: float = Field(3.0, gt=0, description="hydraulics natural freq., Hz")
    damping: float = Field(0.8, gt=0, description="hydraulics damping ratio, -")
    delay_s: float = Field(0.05, ge=0, description="command dead time, s")
    pressure_max_bar: float = Field(120.0, gt=0, description="pressure ceiling, bar")


class AutoHoldParams(StrictModel):
    """Chassis auto-hold: pressure kept at a stop without any command, ramped out at launch.

    It engages when the car has stood still (|vx| < ``standstill_ms``) with at least
    ``engage_min_bar`` for ``engage_time_s``; it then holds max(pressure, ``hold_bar``)
    until the motor torque reaches ``release_torque_nm`` in D or R, and ramps the held
    pressure linearly to zero over ``release_time_s``.
    """

    enabled: bool = Field(True, description="auto-hold present")
    standstill_ms: float = Field(0.005, gt=0, description="standstill speed threshold, m/s")
    engage_time_s: float = Field(0.3, ge=0, description="standstill time to engage, s")
    engage_min_bar: float = Field(2.0, ge=0, description="pressure needed to engage, bar")
    hold_bar: float = Field(12.0, ge=0, description="minimum held pressure, bar")
    release_torque_nm: float = Field(30.0, gt=0, description="motor torque that releases, N·m")
    release_time_s: float = Field(0.8, gt=0, description="linear ramp-out duration, s")


class GearParams(StrictModel):
    """Shift-by-wire: a requested gear is taken only at standstill, after a shift time."""

    max_shift_speed_kmh: float = Field(0.1, ge=0, description="shift refused above, km/h")
    shift_time_s: float = Field(0.25, ge=0, description="time to engage a new gear, s")


class SteeringParams(StrictModel):
    """Electric power steering: first-order lag with a rate limit on the wheel angle."""

    lag_s: float = Field(0.08, gt=0, description="steering-wheel angle lag, s")
    rate_limit_dps: float = Field(500.0, gt=0, description="max steering-wheel rate, deg/s")


class LateralParams(StrictModel):
    """Low-speed single-track: path curvature relaxes over distance, small understeer.

    The curvature κ follows the steady-state κ_ss = tan(δ)/(L + K_us·v²) over the
    travelled distance with the tyre relaxation length σ (dκ/ds = (κ_ss - κ)/σ), and the
    yaw rate is ω = vx·κ: steering changes reach the yaw rate with a lag of σ/|v|.
    """

    relaxation_length_m: float = Field(0.04, gt=0, description="tyre relaxation length, m")
    understeer_gradient: float = Field(
        0.0025, ge=0, description="understeer gradient K_us, rad/(m/s²)"
    )


class ImuParams(StrictModel):
    """IMU on the centreline ``x_offset_m`` ahead of the rear axle, body tilt coupling.

    The body pitches by ``pitch_gradient_deg`` per m/s² of longitudinal acceleration
    (load transfer, nose up when accelerating) with a first-order lag ``pitch_lag_s``; the
    accelerometer then reads a_x + g·sin(pitch). Roll couples into a_y the same way.
    """

    x_offset_m: float = Field(1.4, description="IMU ahead of rear axle, m")
    mount_yaw_deg: float = Field(0.3, description="mounting yaw misalignment, deg")
    pitch_gradient_deg: float = Field(0.2, ge=0, description="pitch per accel, deg/(m/s²)")
    pitch_lag_s: float = Field(0.1, gt=0, description="body pitch lag, s")
    roll_gradient_deg: float = Field(0.4, ge=0, description="roll per lat. accel, deg/(m/s²)")
    ax_bias: float = Field(0.03, description="ax bias, m/s²")
    ay_bias: float = Field(-0.02, description="ay bias, m/s²")
    yaw_rate_bias: float = Field(0.001, description="gyro bias, rad/s")
    ax_noise: float = Field(0.03, ge=0, description="ax white-noise std, m/s²")
    ay_noise: float = Field(0.03, ge=0, description="ay white-noise std, m/s²")
    yaw_rate_noise: float = Field(0.0015, ge=0, description="gyro white-noise std, rad/s")


class WheelSpeedParams(StrictModel):
    """Wheel-speed-derived vx: noisy above the blind zone, quantization noise inside it.

    Inside |vx| < ``blind_zone_kmh`` the pulse period is too long to measure: the reading
    is 0 except for spikes, drawn with probability ``spike_prob`` (plus ``motion_spike_prob``
    times |vx|/blind zone when creeping) with magnitude uniform in
    [``spike_min_frac``, ``spike_max_frac``] of the blind zone, signed as the motion (or
    random at rest). Above it, Gaussian noise and a resolution of ``resolution_kmh``.
    """

    blind_zone_kmh: float = Field(BLIND_ZONE_KMH, gt=0, description="blind zone, km/h")
    noise_ms: float = Field(0.005, ge=0, description="white-noise std above the zone, m/s")
    resolution_kmh: float = Field(0.01, ge=0, description="speed resolution, km/h")
    spike_prob: float = Field(0.05, ge=0, le=1, description="spike probability at rest, -")
    motion_spike_prob: float = Field(0.4, ge=0, le=1, description="extra spikes moving, -")
    spike_min_frac: float = Field(0.2, ge=0, le=1, description="spike min / blind zone, -")
    spike_max_frac: float = Field(0.95, ge=0, lt=1, description="spike max / blind zone, -")


class BusParams(StrictModel):
    """Resolution and noise of the actuator feedback signals on the bus (paper §III-B)."""

    torque_quantum_nm: float = Field(2.0, gt=0, description="torque resolution, N·m")
    pressure_quantum_bar: float = Field(1.0, gt=0, description="pressure resolution, bar")
    steer_quantum_deg: float = Field(0.1, gt=0, description="steering-angle resolution, deg")
    torque_noise_nm: float = Field(0.5, ge=0, description="torque noise std, N·m")
    pressure_noise_bar: float = Field(0.15, ge=0, description="pressure noise std, bar")
    steer_noise_deg: float = Field(0.05, ge=0, description="steering-angle noise std, deg")


class ReferenceVehicleParams(StrictModel):
    """Every parameter of the synthetic reference vehicle (see docs/reference.md), and the
    ``conditions`` block its campaigns draw per-trial conditions from
    (:mod:`parknss.reference.conditions`)."""

    vehicle_id: str = Field("reference-es", description="vehicle id written into trials")
    seed: int = Field(0, description="base seed of the sensor noise")
    geometry: GeometryParams = GeometryParams()
    body: BodyParams = BodyParams()
    drive: DriveParams = DriveParams()
    brake: BrakeParams = BrakeParams()
    autohold: AutoHoldParams = AutoHoldParams()
    gear: GearParams = GearParams()
    steering: SteeringParams = SteeringParams()
    lateral: LateralParams = LateralParams()
    imu: ImuParams = ImuParams()
    wheel_speed: WheelSpeedParams = WheelSpeedParams()
    bus: BusParams = BusParams()
    conditions: ConditionsConfig = ConditionsConfig()

    def to_geometry(self) -> VehicleGeometry:
        return self.geometry.to_geometry()

    def digest(self) -> str:
        """Stable short hash of the vehicle's own parameters. The ``conditions`` block is
        left out: it says how trials are drawn, not what the car is (a campaign records
        the drawn conditions per trial and the block's digest in its meta)."""
        blob = json.dumps(self.model_dump(mode="json", exclude={"conditions"}), sort_keys=True)
        return hashlib.sha256(blob.encode()).hexdigest()[:16]

    def replace(self, **groups: dict) -> ReferenceVehicleParams:
        """A copy with some fields of some groups changed: ``replace(drive={"delay_s": 0})``."""
        return override(self, groups)


def load_vehicle_params(path: str | Path | None = None) -> ReferenceVehicleParams:
    """Read reference-vehicle parameters from ``path`` (default: the shipped
    configs/reference_vehicle.yaml); geometry, mass, wheel radius and drive/brake limits
    outside their physical ranges (:mod:`parknss.vehicle_ranges`) are refused in one line."""
    params = load_config(ReferenceVehicleParams, path, default="reference_vehicle.yaml")
    check_vehicle({**params.geometry.model_dump(), **params.body.model_dump(),
                   "torque_max_nm": params.drive.torque_max_nm,
                   "pressure_max_bar": params.brake.pressure_max_bar},
                  str(path) if path is not None else "reference_vehicle.yaml")
    return params
