"""What one trial's conditions do to the reference vehicle: effective parameters and road.

:func:`trial_environment` turns a :class:`~parknss.reference.conditions.TrialConditions`
into a :class:`TrialEnvironment`: the vehicle parameters of that trial (mass, rolling
radius, rolling resistance, brake gain and bandwidth, IMU biases and yaw misalignment)
plus what has no vehicle parameter (the floor's grade field, the wheel-speed scale, the
drive-unit drag, the battery power limit, the sensor's roll/pitch misalignment, the gyro
drift). Under no conditions it returns the vehicle unchanged. Equations (docs/reference.md):

* tyre deflection δ = (m·g/4)/(k·(c + (1 - c)·p/p0)); rolling radius
  r = r0 - s·(δ - δ0) (Rill: r ≈ r_free - δ/3, s = 1/3); the wheel speed reads
  v·r0/r (the ECU assumes r0);
* rolling resistance c_rr·f_surface·(p/p0)^α·(m/m0)^(β-1) (SAE J2452 form);
* brake fluid viscosity ν(T) by the ASTM D341 (Walther) equation through two points;
  hydraulic lag × (1 + w·(ν(T)/ν(T_ref) - 1)); pad friction × (1 + k_μ·(T - T_ref));
* drive-unit drag τ_d·((ν_oil(T)/ν_oil(T_ref))^n - 1) at the motor (extra over the
  nominal vehicle's, whose drag is inside its efficiency and rolling resistance);
* battery power P·share(SOC)·share(T), available torque min(τ_max, η·P/ω_motor);
* floor: a plane of slope s rising toward ``uphill_heading_deg`` plus an undulation
  z(x) = A·sin(2πx/λ + φ) along the path, the car's grade being the chord slope between
  its axles, (z(x + L) - z(x))/L.

Units: m, kg, N, N·m, bar, rad, s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from parknss.reference.conditions import ConditionModelParams, TrialConditions
from parknss.reference.params import ReferenceVehicleParams
from parknss.signals import DEG_PER_RAD, G

KELVIN = 273.15


def walther_viscosity(temp_c: float, p1: tuple[float, float], p2: tuple[float, float]) -> float:
    """Kinematic viscosity in mm²/s at ``temp_c`` (°C) of an oil or brake fluid given at two
    (°C, mm²/s) points, by the ASTM D341 equation log log(ν + 0.7) = A - B·log T."""

    def ll(nu: float) -> float:
        return math.log10(math.log10(nu + 0.7))

    x1, x2 = math.log10(p1[0] + KELVIN), math.log10(p2[0] + KELVIN)
    b = (ll(p1[1]) - ll(p2[1])) / (x2 - x1)
    a = ll(p1[1]) + b * x1
    return 10.0 ** (10.0 ** (a - b * math.log10(temp_c + KELVIN))) - 0.7


def _share(x: float, x_min: float, share_min: float, x_full: float) -> float:
    """1 at or above x_full, share_min at or below x_min, linear between."""
    if x >= x_full:
        return 1.0
    if x <= x_min:
        return share_min
    return share_min + (1.0 - share_min) * (x - x_min) / (x_full - x_min)


def tyre_deflection(mass_kg: float, pressure_factor: float, m: ConditionModelParams) -> float:
    """Static vertical deflection in m of one tyre under a quarter of ``mass_kg``."""
    k = m.tyre_vertical_stiffness_n_per_mm * 1000.0
    c = m.tyre_carcass_stiffness_share
    return mass_kg * G / 4.0 / (k * (c + (1.0 - c) * pressure_factor))


@dataclass(frozen=True)
class Floor:
    """The floor of one trial: plane slope and undulation (see module docstring).

    slope: tangent of the steepest slope, -. uphill: direction of steepest ascent, rad,
    counter-clockwise from the initial heading. amplitude_m, wavelength_m, phase_rad:
    the undulation along the path. wheelbase_m: chord length of the car's grade.
    """

    slope: float
    uphill: float
    amplitude_m: float
    wavelength_m: float
    phase_rad: float
    wheelbase_m: float

    def height(self, x: float) -> float:
        """Undulation height in m at the signed path coordinate x (m)."""
        return self.amplitude_m * math.sin(2.0 * math.pi * x / self.wavelength_m + self.phase_rad)

    def grade(self, heading: float, x: float) -> tuple[float, float]:
        """(pitch, bank) of the road under the car in rad at heading (rad) and rear-axle
        path coordinate x (m): pitch > 0 nose up, bank > 0 left side up."""
        beta = self.uphill - heading
        und = (self.height(x + self.wheelbase_m) - self.height(x)) / self.wheelbase_m
        return (
            math.atan(self.slope * math.cos(beta) + und),
            math.atan(self.slope * math.sin(beta)),
        )


class Road:
    """The car's pose on its floor: heading and signed path coordinate, integrated."""

    def __init__(self, floor: Floor) -> None:
        self.floor = floor
        self.reset()

    def reset(self) -> None:
        self.heading, self.x = 0.0, 0.0
        self.pitch, self.bank = self.floor.grade(0.0, 0.0)

    def step(self, vx: float, yaw_rate: float, dt: float) -> None:
        """Advance by one sample at speed vx (m/s) and yaw rate (rad/s)."""
        self.heading += yaw_rate * dt
        self.x += vx * dt
        self.pitch, self.bank = self.floor.grade(self.heading, self.x)


@dataclass(frozen=True)
class TrialEnvironment:
    """The vehicle and its surroundings for one trial.

    params: the effective vehicle parameters. speed_scale: wheel-speed reading / true
    speed, -. drag_torque_nm: extra drive-unit drag at the motor (passive), N·m.
    power_limit_w: battery discharge power (inf: no limit), W. inverter_efficiency: -.
    imu_roll_rad, imu_pitch_rad: sensor-frame misalignment, rad. gyro_drift: yaw-rate
    bias change, rad/s per s. floor: the road grade field (None: flat).
    """

    params: ReferenceVehicleParams
    speed_scale: float = 1.0
    drag_torque_nm: float = 0.0
    power_limit_w: float = math.inf
    inverter_efficiency: float = 1.0
    imu_roll_rad: float = 0.0
    imu_pitch_rad: float = 0.0
    gyro_drift: float = 0.0
    floor: Floor | None = None

    def torque_available(self, vx: float) -> float:
        """Motor torque in N·m the battery can supply at speed vx (m/s)."""
        p = self.params
        t_max = p.drive.torque_max_nm
        omega = abs(vx) * p.body.drive_ratio / p.body.wheel_radius_m
        power = self.power_limit_w * self.inverter_efficiency
        return t_max if t_max * omega <= power else power / omega


def trial_environment(
    params: ReferenceVehicleParams, conditions: TrialConditions | None
) -> TrialEnvironment:
    """The environment of one trial of the vehicle ``params`` under ``conditions``."""
    if conditions is None:
        return TrialEnvironment(params)
    c, m = conditions, params.conditions.model
    body, brake, imu = params.body, params.brake, params.imu
    t_ref = m.reference_temp_c

    mass = body.mass_kg + c.payload_kg
    d0 = tyre_deflection(body.mass_kg, 1.0, m)
    d1 = tyre_deflection(mass, c.tyre_pressure_factor, m)
    radius = body.wheel_radius_m - m.rolling_radius_deflection_share * (d1 - d0)
    c_rr = (
        body.rolling_resistance
        * c.surface_rr_factor
        * c.tyre_pressure_factor**m.rr_pressure_exponent
        * (mass / body.mass_kg) ** (m.rr_load_exponent - 1.0)
    )

    fluid = (
        (m.brake_fluid_cold_c, m.brake_fluid_cold_cst),
        (m.brake_fluid_hot_c, m.brake_fluid_hot_cst),
    )
    visc = walther_viscosity(c.brake_temp_c, *fluid) / walther_viscosity(t_ref, *fluid)
    lag = 1.0 + m.brake_viscous_lag_share * (visc - 1.0)
    pad = 1.0 + m.pad_friction_temp_coeff_per_k * (c.brake_temp_c - t_ref)

    oil = ((m.drive_oil_cold_c, m.drive_oil_cold_cst), (m.drive_oil_hot_c, m.drive_oil_hot_cst))
    oil_ratio = walther_viscosity(c.powertrain_temp_c, *oil) / walther_viscosity(t_ref, *oil)
    drag = m.drive_drag_nm * (oil_ratio**m.drive_drag_viscosity_exponent - 1.0)
    soc_share = _share(
        c.battery_soc_pct, m.battery_soc_min_pct, m.battery_soc_min_share, m.battery_soc_full_pct
    )
    temp_share = _share(
        c.powertrain_temp_c, m.battery_temp_min_c, m.battery_temp_min_share, m.battery_temp_full_c
    )
    power = m.battery_power_kw * 1000.0 * soc_share * temp_share

    effective = params.replace(
        body={"mass_kg": mass, "wheel_radius_m": radius, "rolling_resistance": c_rr},
        brake={
            "force_per_bar": brake.force_per_bar * pad,
            "natural_freq_hz": brake.natural_freq_hz / lag,
        },
        imu={
            "ax_bias": imu.ax_bias + c.ax_bias_ms2,
            "ay_bias": imu.ay_bias + c.ay_bias_ms2,
            "yaw_rate_bias": imu.yaw_rate_bias + c.gyro_bias_dps / DEG_PER_RAD,
            "mount_yaw_deg": imu.mount_yaw_deg + c.imu_yaw_deg,
        },
    )
    flat = c.lot_slope_pct == 0.0 and c.undulation_amplitude_mm == 0.0
    floor = None
    if not flat:
        floor = Floor(
            slope=c.lot_slope_pct / 100.0,
            uphill=c.uphill_heading_deg / DEG_PER_RAD,
            amplitude_m=c.undulation_amplitude_mm / 1000.0,
            wavelength_m=c.undulation_wavelength_m,
            phase_rad=c.undulation_phase_deg / DEG_PER_RAD,
            wheelbase_m=params.geometry.wheelbase,
        )
    return TrialEnvironment(
        params=effective,
        speed_scale=body.wheel_radius_m / radius,
        drag_torque_nm=drag,
        power_limit_w=power,
        inverter_efficiency=m.inverter_efficiency,
        imu_roll_rad=c.imu_roll_deg / DEG_PER_RAD,
        imu_pitch_rad=c.imu_pitch_deg / DEG_PER_RAD,
        gyro_drift=c.gyro_drift_dps_per_min / DEG_PER_RAD / 60.0,
        floor=floor,
    )
