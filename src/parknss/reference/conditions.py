"""Per-trial conditions of the reference vehicle: what differs between field tests and no
channel logs.

A real campaign is driven on floors of different slope, with different loads, tyre
pressures, brake, battery and drive-unit temperatures and a sensor cluster whose offsets
wander. This module declares them, the ranges each is drawn from (profiles ``none``,
``typical``, ``harsh``; every range in the vehicle YAML's ``conditions`` block) and the
draw itself; :mod:`parknss.reference.environment` turns one draw into the parameters and
the road of one trial. docs/reference.md, "Per-trial conditions", gives each phenomenon,
its equation, its ranges and where the ranges come from.

* Profile ``none`` draws nothing: every trial runs the nominal vehicle on a flat floor,
  bit for bit the campaign generated before conditions existed.
* The draw is a separate random stream per trial and per condition, derived from
  (campaign seed, class, repetition, condition name): it does not disturb the plan or
  sensor-noise streams, and the same seed gives the same uniform numbers under every
  profile (``harsh`` stretches ``typical``'s draw).
* The drawn values are ground truth: the generator writes them into each trial's
  provenance (``conditions``); identification code never reads them (a test guards it).
"""

from __future__ import annotations

import json
import math
import zlib
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from parknss.config import StrictModel

PROFILES: tuple[str, ...] = ("none", "typical", "harsh")
CONDITIONS_KEY = "conditions"
"""Key of the drawn conditions in a trial's provenance JSON (ground truth only)."""
STREAM_TAG = 0x434F4E44  # "COND": keeps the conditions stream apart from plan/noise seeds


class Span(StrictModel):
    """A uniform range [lo, hi] in the unit of the field it belongs to (lo == hi: fixed)."""

    lo: float
    hi: float

    @model_validator(mode="after")
    def _ordered(self) -> Span:
        if not (math.isfinite(self.lo) and math.isfinite(self.hi)) or self.hi < self.lo:
            raise ValueError(f"need finite lo <= hi, got [{self.lo}, {self.hi}]")
        return self

    def at(self, u: float) -> float:
        """The value at the fraction u in [0, 1) of the range."""
        return self.lo + (self.hi - self.lo) * u


def _s(lo: float, hi: float) -> Span:
    return Span(lo=lo, hi=hi)


class ConditionRanges(StrictModel):
    """The ranges of one profile; each trial draws every field uniformly from its span.

    Biases, misalignments and drift are added to the vehicle's fixed values (``imu.*``).
    The uphill direction of the floor and the undulation phase are uniform over 360°.
    """

    lot_slope_pct: Span = Field(description="floor plane slope (steepest), %")
    undulation_amplitude_mm: Span = Field(description="floor undulation height amplitude, mm")
    undulation_wavelength_m: Span = Field(description="floor undulation wavelength, m")
    payload_kg: Span = Field(description="load beyond the driver, kg")
    surface_rr_factor: Span = Field(description="rolling resistance of the surface / nominal, -")
    tyre_pressure_factor: Span = Field(description="tyre inflation pressure / placard, -")
    brake_temp_c: Span = Field(description="brake fluid and pad temperature, °C")
    battery_soc_pct: Span = Field(description="battery state of charge, %")
    powertrain_temp_c: Span = Field(description="battery and drive-unit temperature, °C")
    ax_bias_ms2: Span = Field(description="extra accelerometer x bias, m/s²")
    ay_bias_ms2: Span = Field(description="extra accelerometer y bias, m/s²")
    imu_roll_deg: Span = Field(description="sensor-frame roll misalignment, deg")
    imu_pitch_deg: Span = Field(description="sensor-frame pitch misalignment, deg")
    imu_yaw_deg: Span = Field(description="extra sensor-frame yaw misalignment, deg")
    gyro_bias_dps: Span = Field(description="extra yaw-rate bias at the trial start, deg/s")
    gyro_drift_dps_per_min: Span = Field(description="yaw-rate bias drift, deg/s per min")


TYPICAL = ConditionRanges(
    lot_slope_pct=_s(0.0, 3.0),
    undulation_amplitude_mm=_s(0.0, 5.0),
    undulation_wavelength_m=_s(4.0, 15.0),
    payload_kg=_s(0.0, 225.0),
    surface_rr_factor=_s(0.9, 1.15),
    tyre_pressure_factor=_s(0.9, 1.05),
    brake_temp_c=_s(10.0, 60.0),
    battery_soc_pct=_s(20.0, 90.0),
    powertrain_temp_c=_s(10.0, 35.0),
    ax_bias_ms2=_s(-0.02, 0.02),
    ay_bias_ms2=_s(-0.02, 0.02),
    imu_roll_deg=_s(-0.2, 0.2),
    imu_pitch_deg=_s(-0.2, 0.2),
    imu_yaw_deg=_s(-0.1, 0.1),
    gyro_bias_dps=_s(-0.05, 0.05),
    gyro_drift_dps_per_min=_s(-0.01, 0.01),
)
HARSH = ConditionRanges(
    lot_slope_pct=_s(0.0, 6.67),
    undulation_amplitude_mm=_s(0.0, 10.0),
    undulation_wavelength_m=_s(4.0, 15.0),
    payload_kg=_s(0.0, 500.0),
    surface_rr_factor=_s(0.85, 1.35),
    tyre_pressure_factor=_s(0.75, 1.1),
    brake_temp_c=_s(-20.0, 150.0),
    battery_soc_pct=_s(5.0, 100.0),
    powertrain_temp_c=_s(-20.0, 45.0),
    ax_bias_ms2=_s(-0.06, 0.06),
    ay_bias_ms2=_s(-0.06, 0.06),
    imu_roll_deg=_s(-0.5, 0.5),
    imu_pitch_deg=_s(-0.5, 0.5),
    imu_yaw_deg=_s(-0.3, 0.3),
    gyro_bias_dps=_s(-0.2, 0.2),
    gyro_drift_dps_per_min=_s(-0.05, 0.05),
)


class ConditionModelParams(StrictModel):
    """Constants of the models that turn a drawn condition into physics (units in each
    description; sources and equations in docs/reference.md)."""

    reference_temp_c: float = Field(
        20.0, description="temperature of the nominal vehicle's brake and drive values, °C"
    )
    tyre_vertical_stiffness_n_per_mm: float = Field(
        250.0, gt=0, description="tyre vertical stiffness at placard pressure, N/mm"
    )
    tyre_carcass_stiffness_share: float = Field(
        0.1, ge=0, lt=1, description="share of that stiffness not due to inflation, -"
    )
    rolling_radius_deflection_share: float = Field(
        1.0 / 3.0, ge=0, le=1, description="rolling-radius change per tyre deflection, -"
    )
    rr_pressure_exponent: float = Field(
        -0.4, description="rolling resistance ∝ pressure^this (SAE J2452 form), -"
    )
    rr_load_exponent: float = Field(
        0.9, description="rolling-resistance force ∝ load^this (SAE J2452 form), -"
    )
    brake_fluid_cold_c: float = Field(-40.0, description="brake-fluid viscosity point 1, °C")
    brake_fluid_cold_cst: float = Field(700.0, gt=0, description="viscosity there, mm²/s")
    brake_fluid_hot_c: float = Field(100.0, description="brake-fluid viscosity point 2, °C")
    brake_fluid_hot_cst: float = Field(2.0, gt=0, description="viscosity there, mm²/s")
    brake_viscous_lag_share: float = Field(
        0.05, ge=0, le=1, description="share of the hydraulic lag due to viscous flow, -"
    )
    pad_friction_temp_coeff_per_k: float = Field(
        0.0005, description="relative pad friction change per kelvin, 1/K"
    )
    drive_oil_cold_c: float = Field(40.0, description="drive-unit oil viscosity point 1, °C")
    drive_oil_cold_cst: float = Field(25.0, gt=0, description="viscosity there, mm²/s")
    drive_oil_hot_c: float = Field(100.0, description="drive-unit oil viscosity point 2, °C")
    drive_oil_hot_cst: float = Field(5.5, gt=0, description="viscosity there, mm²/s")
    drive_drag_nm: float = Field(
        0.5, ge=0, description="oil-dependent drive-unit drag at the motor, reference temp, N·m"
    )
    drive_drag_viscosity_exponent: float = Field(
        0.6, ge=0, description="drag ∝ viscosity^this (bearing friction model), -"
    )
    battery_power_kw: float = Field(
        150.0, gt=0, description="discharge power, warm and charged, kW"
    )
    battery_soc_full_pct: float = Field(20.0, description="full power at or above this SOC, %")
    battery_soc_min_pct: float = Field(5.0, description="SOC of the lowest power share, %")
    battery_soc_min_share: float = Field(0.3, ge=0, le=1, description="power share there, -")
    battery_temp_full_c: float = Field(10.0, description="full power at or above this temp, °C")
    battery_temp_min_c: float = Field(-20.0, description="temp of the lowest power share, °C")
    battery_temp_min_share: float = Field(0.3, ge=0, le=1, description="power share there, -")
    inverter_efficiency: float = Field(0.95, gt=0, le=1, description="battery -> motor, -")

    @model_validator(mode="after")
    def _ordered(self) -> ConditionModelParams:
        pairs = (
            ("brake_fluid_cold_c", "brake_fluid_hot_c"),
            ("drive_oil_cold_c", "drive_oil_hot_c"),
            ("battery_soc_min_pct", "battery_soc_full_pct"),
            ("battery_temp_min_c", "battery_temp_full_c"),
        )
        for lo, hi in pairs:
            if not getattr(self, lo) < getattr(self, hi):
                raise ValueError(f"{lo} must be below {hi}")
        return self


class ConditionsConfig(StrictModel):
    """The vehicle YAML's ``conditions`` block: the profile trials are drawn from, the
    ranges of each profile and the constants of the condition models."""

    profile: Literal["none", "typical", "harsh"] = Field(
        "typical", description="profile the campaign draws from (none | typical | harsh)"
    )
    model: ConditionModelParams = ConditionModelParams()
    typical: ConditionRanges = TYPICAL
    harsh: ConditionRanges = HARSH

    @model_validator(mode="before")
    @classmethod
    def _complete_profiles(cls, data):
        """A YAML that lists some ranges of a profile keeps the shipped ones for the rest."""
        if not isinstance(data, dict):
            return data
        data = dict(data)
        for name, base in (("typical", TYPICAL), ("harsh", HARSH)):
            given = data.get(name)
            if isinstance(given, dict):
                data[name] = {**base.model_dump(), **given}
        return data

    def ranges(self, profile: str | None = None) -> ConditionRanges | None:
        """The ranges of ``profile`` (default: the configured one); None for ``none``."""
        name = self.profile if profile is None else profile
        if name not in PROFILES:
            raise ValueError(f"unknown conditions profile {name!r}; expected one of {PROFILES}")
        return None if name == "none" else getattr(self, name)


class TrialConditions(StrictModel):
    """The conditions of one trial (ground truth; units as in :class:`ConditionRanges`).

    ``uphill_heading_deg`` is the direction of steepest ascent of the floor plane,
    counter-clockwise from the car's heading at the start of the trial.
    """

    profile: str = "none"
    lot_slope_pct: float = 0.0
    uphill_heading_deg: float = 0.0
    undulation_amplitude_mm: float = 0.0
    undulation_wavelength_m: float = 10.0
    undulation_phase_deg: float = 0.0
    payload_kg: float = 0.0
    surface_rr_factor: float = 1.0
    tyre_pressure_factor: float = 1.0
    brake_temp_c: float = 20.0
    battery_soc_pct: float = 80.0
    powertrain_temp_c: float = 20.0
    ax_bias_ms2: float = 0.0
    ay_bias_ms2: float = 0.0
    imu_roll_deg: float = 0.0
    imu_pitch_deg: float = 0.0
    imu_yaw_deg: float = 0.0
    gyro_bias_dps: float = 0.0
    gyro_drift_dps_per_min: float = 0.0

    @classmethod
    def nominal(cls, model: ConditionModelParams | None = None) -> TrialConditions:
        """The nominal trial: flat floor, no load, reference temperatures (the ``none``
        vehicle, expressed as conditions)."""
        t = (model or ConditionModelParams()).reference_temp_c
        return cls(brake_temp_c=t, powertrain_temp_c=t)


def _uniform(seed: int, cls: int, repetition: int, name: str) -> float:
    """One uniform number in [0, 1) of the stream (seed, class, repetition, name)."""
    ss = np.random.SeedSequence(
        [int(seed) & 0xFFFFFFFF, cls, int(repetition), STREAM_TAG, zlib.crc32(name.encode())]
    )
    return float(np.random.default_rng(ss).random())


def draw_conditions(
    config: ConditionsConfig,
    seed: int,
    class_index: int,
    repetition: int,
    profile: str | None = None,
) -> TrialConditions | None:
    """The conditions of one trial (None under profile ``none``).

    Args:
        config: the vehicle YAML's ``conditions`` block.
        seed: the campaign seed.
        class_index: index of the maneuver class (MANEUVER_CLASSES).
        repetition: repetition number (1-based).
        profile: overrides ``config.profile``.
    """
    ranges = config.ranges(profile)
    if ranges is None:
        return None
    values: dict[str, float | str] = {"profile": profile or config.profile}
    for name in ConditionRanges.model_fields:
        values[name] = getattr(ranges, name).at(_uniform(seed, class_index, repetition, name))
    for name in ("uphill_heading_deg", "undulation_phase_deg"):
        values[name] = 360.0 * _uniform(seed, class_index, repetition, name)
    return TrialConditions(**values)


# ------------------------------------------------------------------ reading them back
def trial_conditions(provenance: str | None) -> TrialConditions | None:
    """The conditions recorded in a trial's provenance JSON, or None (none recorded)."""
    if not provenance:
        return None
    try:
        prov = json.loads(provenance)
    except (TypeError, ValueError):
        return None
    cond = prov.get(CONDITIONS_KEY) if isinstance(prov, dict) else None
    return TrialConditions(**cond) if isinstance(cond, dict) else None


SUMMARY_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("lot_slope_pct", "slope%", "6.2f"),
    ("uphill_heading_deg", "uphill°", "7.0f"),
    ("payload_kg", "load kg", "7.0f"),
    ("surface_rr_factor", "rr×", "5.2f"),
    ("tyre_pressure_factor", "tyre p×", "7.3f"),
    ("brake_temp_c", "brake°C", "7.0f"),
    ("battery_soc_pct", "SOC%", "5.0f"),
    ("powertrain_temp_c", "drive°C", "7.0f"),
    ("ax_bias_ms2", "ax bias", "7.3f"),
    ("imu_pitch_deg", "pitch°", "6.2f"),
    ("gyro_bias_dps", "ω bias°/s", "9.3f"),
    ("gyro_drift_dps_per_min", "drift°/s/min", "12.3f"),
)
"""Columns of the ``campaign describe`` conditions block: (field, header, format)."""


def conditions_summary(trials) -> dict[str, dict] | None:
    """{trial id: conditions dict} for the trials of a campaign that record conditions;
    None when none does (a campaign of profile ``none`` or real logs)."""
    out = {}
    for tr in trials:
        cond = trial_conditions(tr.provenance)
        if cond is not None:
            out[tr.id] = cond.model_dump()
    return out or None


def conditions_rows(summary: dict[str, dict] | None) -> list[str]:
    """Plain-text block of :data:`SUMMARY_COLUMNS`, one row per trial ([] when None)."""
    if not summary:
        return []
    w = max(22, *(len(t) for t in summary))
    widths = [max(len(h), int(f.split(".")[0])) for _, h, f in SUMMARY_COLUMNS]
    profiles = sorted({str(c["profile"]) for c in summary.values()})
    head = " ".join(f"{h:>{n}}" for (_, h, _), n in zip(SUMMARY_COLUMNS, widths, strict=True))
    rows = [f"conditions (ground truth, profile {', '.join(profiles)}):", f"{'trial':<{w}} {head}"]
    for tid, c in summary.items():
        cells = " ".join(
            f"{c[k]:>{n}{f[f.index('.') :]}}"
            for (k, _, f), n in zip(SUMMARY_COLUMNS, widths, strict=True)
        )
        rows.append(f"{tid:<{w}} {cells}")
    return rows
