"""Campaign summary: per-trial shape, channel flags and the kinematic checks of §IV-A.

Per trial: class, length, direction changes, blind-zone fraction, max |vx|, whether it
leaves the parking-speed domain, and per-channel flags (all-zero, constant, out of the
plausible range, sentinel-like values, clipping; rules below). For the campaign: which
channels it has, which workflows it supports (:mod:`parknss.data.workflows`), the R² of
the kinematic-bicycle yaw rate (eq. 4, constant ratio) against the measured yaw rate over
the moving region, the least-squares steering ratio of eq. 4, the total direction changes
and how many reversals did not happen at standstill, and whether its CV folds can be
stratified. A figure whose channels the campaign lacks is None, and ``unavailable`` says
which channels it needs.

Definitions (also in docs/data.md):

* direction change: a sign change of the ``gear`` channel between -1 (R) and +1 (D),
  neutral/park samples (0) skipped, so R -> N -> D counts once and R -> N -> R not at all;
* a reversal is at standstill when |vx| < 0.5 km/h (signals.BLIND_ZONE_MS) on every
  sample from the last sample of the old gear to the first sample of the new one;
* blind-zone fraction: share of samples with |vx| < 0.5 km/h;
* moving region: |vx| >= 0.5 km/h (signals.moving_mask), pooled over all trials;
* parking-speed domain: max |vx| <= ``describe.parking_speed_max_kmh`` (default 20 km/h).

Channel flags (per trial and schema channel present, ``t`` excluded; thresholds in the
``describe`` section of configs/data.yaml):

* ``out_of_range``: samples outside the channel's plausible range (``validation.ranges``
  of configs/data.yaml); a validated campaign has none, in-memory campaigns may;
* ``all_zero``: every sample is exactly 0;
* ``constant``: otherwise, peak-to-peak <= ``constant_tolerance`` (schema unit);
  integer channels (gear) are checked for these two only;
* ``sentinel``: the channel's observed max (min) v != 0 is held for at least
  ``sentinel_min_run`` consecutive samples, and the samples that are not v span a range
  R > 0 and stay at least ``sentinel_gap_ratio`` * R below (above) v: one repeated value
  far outside the rest of the signal, like an invalid-value code (3276.7 deg);
* ``clipped``: otherwise, for the channels of ``clip_channels``, the observed max (min)
  v != 0 is held for at least ``clip_min_run`` consecutive samples: the signal is pinned
  at its extreme (saturation). A run at exactly 0 is rest, not clipping.

The geometry (wheelbase, constant steering ratio) is ``campaign.meta["vehicle_geometry"]``
when present (generator and import record it), else the paper's (3.0 m, 12.1).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import Field, model_validator
from scipy.optimize import minimize_scalar

from parknss.config import StrictModel
from parknss.data.signchecks import SignCheck, short_frames, sign_check, yaw_offset
from parknss.data.trial import Campaign, Trial
from parknss.data.validate import load_data_section
from parknss.data.workflows import WorkflowSupport, campaign_channels, schema_order, support
from parknss.errors import DataError
from parknss.signals import (
    BLIND_ZONE_MS,
    CHANNEL_BY_NAME,
    DEG_PER_RAD,
    DT,
    REQUIRED_CHANNELS,
    SAMPLE_RATE_HZ,
    moving_mask,
    ms_to_kmh,
)
from parknss.vehicle import VehicleGeometry, yaw_rate_ref

# What each figure reads: field name (per trial and/or campaign) -> schema channels.
NEEDS: dict[str, tuple[str, ...]] = {
    "direction_changes": ("gear",),
    "reversals_while_moving": ("gear", "vx"),
    "reversals_at_standstill": ("gear", "vx"),
    "blind_zone_fraction": ("vx",),
    "max_speed_kmh": ("vx",),
    "outside_parking_domain": ("vx",),
    "moving_samples": ("vx",),
    "yaw_r2": ("vx", "steer", "yaw_rate"),
    "steer_ratio_fit": ("vx", "steer", "yaw_rate"),
}
MEASURED_CONTINUOUS: tuple[str, ...] = ("steer", "vx", "yaw_rate", "ax", "ay")


class DescribeConfig(StrictModel):
    """Settings of ``parknss campaign describe`` (section ``describe`` of configs/data.yaml).

    Attributes:
        steer_ratio_bounds: search interval of the bounded 1-D least-squares fit, (-).
        steer_ratio_xatol: absolute tolerance on the fitted ratio, (-).
        parking_speed_max_kmh: a trial whose max |vx| exceeds this leaves the
            parking-speed domain the NSS is meant for, km/h.
        constant_tolerance: peak-to-peak at or below which a channel counts as constant,
            in the channel's schema unit (0: every sample bit-identical).
        sentinel_min_run: consecutive samples at the extreme value for a sentinel, (-).
        sentinel_gap_ratio: how far the extreme value must lie beyond the rest of the
            channel, as a multiple of the rest's peak-to-peak range, (-).
        clip_min_run: consecutive samples at the extreme value for clipping, (-).
        clip_channels: the channels checked for clipping (schema names); by default the
            continuous measured ones (torque, brake pressure and the commands are held at
            set values by their ECUs, so a run at their max is normal).
        sign_corr_min: a correlation of ax with dvx/dt (ay with vx·ω_z) below this flags
            the channel as sign-inverted, (-) (:mod:`parknss.data.signchecks`).
        sign_smooth_s: moving-average window of those correlations, s.
        standstill_kmh: |vx| below this counts as standstill for the yaw offset, km/h.
        yaw_offset_min_dps: a median yaw rate at standstill beyond this is an offset, °/s.
        standstill_min_samples: fewer standstill samples than this: no offset check.
    """

    steer_ratio_bounds: tuple[float, float] = (5.0, 30.0)
    steer_ratio_xatol: float = Field(1.0e-6, gt=0.0)
    parking_speed_max_kmh: float = Field(20.0, gt=0.0)
    constant_tolerance: float = Field(0.0, ge=0.0)
    sentinel_min_run: int = Field(10, ge=2)
    sentinel_gap_ratio: float = Field(0.5, gt=0.0)
    clip_min_run: int = Field(25, ge=2)
    clip_channels: tuple[str, ...] = MEASURED_CONTINUOUS
    sign_corr_min: float = Field(-0.1, ge=-1.0, le=0.0)
    sign_smooth_s: float = Field(0.25, ge=0.0)
    standstill_kmh: float = Field(0.05, gt=0.0)
    yaw_offset_min_dps: float = Field(0.1, ge=0.0)
    standstill_min_samples: int = Field(100, ge=1)

    @model_validator(mode="after")
    def _ordered(self) -> DescribeConfig:
        lo, hi = self.steer_ratio_bounds
        if not 0.0 < lo < hi:
            raise ValueError("steer_ratio_bounds must satisfy 0 < lo < hi")
        unknown = [c for c in self.clip_channels if c not in REQUIRED_CHANNELS or c == "t"]
        if unknown:
            raise ValueError(f"clip_channels: {unknown[0]!r} is not a schema channel")
        return self


def load_describe_config(path: str | Path | None = None) -> DescribeConfig:
    """The ``describe`` section of configs/data.yaml (or of ``path``)."""
    return load_data_section(DescribeConfig, "describe", path)


def reversal_indices(gear: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs (last sample of the old gear, first of the new) of each R <-> D change.

    gear: (T,) in {-1, 0, 1}; zeros are skipped. Returns two int arrays of equal length.
    """
    nz = np.flatnonzero(np.asarray(gear) != 0)
    g = np.asarray(gear)[nz]
    sw = np.flatnonzero(g[1:] != g[:-1])
    return nz[sw], nz[sw + 1]


def direction_changes(gear: np.ndarray) -> int:
    """Number of R <-> D changes of a gear sequence (neutral/park samples skipped)."""
    return len(reversal_indices(gear)[0])


def reversals_while_moving(gear: np.ndarray, vx: np.ndarray) -> int:
    """Reversals with |vx| >= 0.5 km/h somewhere from the old gear's last to the new's first."""
    starts, ends = reversal_indices(gear)
    speed = np.abs(np.asarray(vx))
    return sum(
        int(speed[a : b + 1].max() >= BLIND_ZONE_MS) for a, b in zip(starts, ends, strict=True)
    )


def _runs(mask: np.ndarray) -> np.ndarray:
    """Lengths of the runs of consecutive True samples of a (T,) boolean mask."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)


@dataclass(frozen=True)
class ChannelFlag:
    """One finding on one channel of one trial (rules in the module docstring).

    Attributes:
        channel: schema channel name.
        kind: ``out_of_range``, ``all_zero``, ``constant``, ``sentinel`` or ``clipped``.
        value: the constant, sentinel or pinned value (for ``out_of_range`` the worst
            sample), schema unit.
        samples: samples concerned (T at most).
        side: ``max`` or ``min`` for sentinel and clipped, else None.
        longest_run_s: longest run of consecutive samples at ``value``, s (sentinel and
            clipped), else None.
        detail: the finding in one line of words.
    """

    channel: str
    kind: str
    value: float
    samples: int
    side: str | None = None
    longest_run_s: float | None = None
    detail: str = ""

    def to_json(self) -> dict:
        return {
            "channel": self.channel,
            "kind": self.kind,
            "value": self.value,
            "samples": self.samples,
            "side": self.side,
            "longest_run_s": self.longest_run_s,
            "detail": self.detail,
        }


def plausible_ranges() -> dict[str, tuple[float, float]]:
    """The plausible [lo, hi] per schema channel, schema units, that validation uses
    (``validation.ranges`` of configs/data.yaml)."""
    from parknss.data.validate import load_validation_config

    return dict(load_validation_config().ranges)


def _out_of_range(
    name: str, x: np.ndarray, ranges: dict[str, tuple[float, float]]
) -> ChannelFlag | None:
    if name not in ranges:
        return None
    lo, hi = ranges[name]
    bad = (x < lo) | (x > hi)
    if not bad.any():
        return None
    worst = float(x[bad][np.argmax(np.abs(x[bad] - 0.5 * (lo + hi)))])
    detail = (
        f"{int(bad.sum())} samples outside the plausible range [{lo:g}, {hi:g}] "
        f"{CHANNEL_BY_NAME[name].unit} (worst {worst:g})"
    )
    return ChannelFlag(name, "out_of_range", worst, int(bad.sum()), detail=detail)


def _flat(name: str, x: np.ndarray, cfg: DescribeConfig) -> ChannelFlag | None:
    unit = CHANNEL_BY_NAME[name].unit
    if not np.any(x):
        return ChannelFlag(name, "all_zero", 0.0, len(x), detail=f"all {len(x)} samples are 0")
    if np.ptp(x) <= cfg.constant_tolerance and not CHANNEL_BY_NAME[name].integer:
        v = float(x[0])
        return ChannelFlag(name, "constant", v, len(x), detail=f"constant at {v:g} {unit}")
    return None


def _extreme(name: str, x: np.ndarray, side: str, cfg: DescribeConfig) -> ChannelFlag | None:
    """A sentinel or clipping flag at the channel's observed max (min), else None."""
    v = float(x.max() if side == "max" else x.min())
    if v == 0.0:
        return None
    at = x == v
    runs = _runs(at)
    longest = int(runs.max())
    rest = x[~at]
    unit = CHANNEL_BY_NAME[name].unit
    if longest >= cfg.sentinel_min_run and rest.size and np.ptp(rest) > 0.0:
        gap = v - rest.max() if side == "max" else rest.min() - v
        if gap >= cfg.sentinel_gap_ratio * np.ptp(rest):
            detail = (
                f"sentinel-like {v:g} {unit} at its {side} on {int(at.sum())} samples "
                f"(longest run {longest * DT:.2f} s), far from the rest "
                f"({rest.min():g} .. {rest.max():g} {unit})"
            )
            return ChannelFlag(name, "sentinel", v, int(at.sum()), side, longest * DT, detail)
    if name in cfg.clip_channels and longest >= cfg.clip_min_run:
        pinned = int(runs[runs >= cfg.clip_min_run].sum())
        detail = (
            f"clipped: pinned at its {side} {v:g} {unit} on {pinned} samples "
            f"(longest run {longest * DT:.2f} s)"
        )
        return ChannelFlag(name, "clipped", v, pinned, side, longest * DT, detail)
    return None


def channel_flags(
    name: str,
    x: np.ndarray,
    cfg: DescribeConfig,
    ranges: dict[str, tuple[float, float]] | None = None,
) -> list[ChannelFlag]:
    """The flags of one schema channel ``name`` with samples x (T,), schema unit.

    ``ranges``: plausible [lo, hi] per channel (default :func:`plausible_ranges`).
    """
    x = np.asarray(x, dtype=np.float64)
    oor = _out_of_range(name, x, plausible_ranges() if ranges is None else ranges)
    flags = [oor] if oor is not None else []
    flat = _flat(name, x, cfg)
    if flat is not None:
        return [*flags, flat]
    if CHANNEL_BY_NAME[name].integer or len(x) == 0:
        return flags
    extremes = (_extreme(name, x, side, cfg) for side in ("max", "min"))
    return flags + [f for f in extremes if f is not None]


def trial_flags(
    trial: Trial, cfg: DescribeConfig, ranges: dict[str, tuple[float, float]] | None = None
) -> tuple[ChannelFlag, ...]:
    """Flags of every schema channel the trial has (``t`` excluded), schema order."""
    rng = plausible_ranges() if ranges is None else ranges
    names = [c for c in schema_order(tuple(trial.channels)) if c != "t"]
    return tuple(f for c in names for f in channel_flags(c, trial[c], cfg, rng))


@dataclass(frozen=True)
class TrialSummary:
    """One trial's shape. Lengths in s, speed in km/h, fractions in [0, 1]; None where the
    trial lacks a channel the figure needs (:data:`NEEDS`)."""

    id: str
    maneuver: str
    length_s: float
    direction_changes: int | None
    blind_zone_fraction: float | None
    max_speed_kmh: float | None
    reversals_while_moving: int | None
    outside_parking_domain: bool | None = None
    flags: tuple[ChannelFlag, ...] = ()

    def to_json(self) -> dict:
        return {
            "id": self.id,
            "class": self.maneuver,
            "length_s": round(self.length_s, 2),
            "direction_changes": self.direction_changes,
            "blind_zone_fraction": self.blind_zone_fraction,
            "max_speed_kmh": self.max_speed_kmh,
            "reversals_while_moving": self.reversals_while_moving,
            "outside_parking_domain": self.outside_parking_domain,
            "flags": [f.to_json() for f in self.flags],
        }


def summarize_trial(
    trial: Trial,
    config: DescribeConfig | None = None,
    ranges: dict[str, tuple[float, float]] | None = None,
) -> TrialSummary:
    """The per-trial figures of :class:`TrialSummary` (None for those lacking a channel);
    ``ranges`` as for :func:`channel_flags`."""
    cfg = config or DescribeConfig()
    vx = trial.channels.get("vx")
    gear = trial.channels.get("gear")
    speed = None if vx is None else float(ms_to_kmh(np.abs(vx).max()))
    return TrialSummary(
        id=trial.id,
        maneuver=trial.maneuver,
        length_s=float(trial.duration_s),
        direction_changes=None if gear is None else direction_changes(gear),
        blind_zone_fraction=None if vx is None else float(1.0 - moving_mask(vx).mean()),
        max_speed_kmh=speed,
        reversals_while_moving=(
            None if gear is None or vx is None else reversals_while_moving(gear, vx)
        ),
        outside_parking_domain=None if speed is None else speed > cfg.parking_speed_max_kmh,
        flags=trial_flags(trial, cfg, ranges),
    )


def campaign_geometry(campaign: Campaign) -> VehicleGeometry:
    """The campaign's recorded vehicle geometry, else the paper's defaults."""
    geom = campaign.meta.get("vehicle_geometry")
    return VehicleGeometry.from_dict(geom) if isinstance(geom, dict) else VehicleGeometry()


def moving_samples(campaign: Campaign) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vx m/s, steer deg, yaw_rate rad/s) of all trials on the moving region, each (N,)."""
    parts = [(tr["vx"], tr["steer"], tr["yaw_rate"]) for tr in campaign]
    masks = [moving_mask(v) for v, _, _ in parts]
    return tuple(  # type: ignore[return-value]
        np.concatenate([p[j][m] for p, m in zip(parts, masks, strict=True)] or [np.zeros(0)])
        for j in range(3)
    )


def yaw_r2(
    vx: np.ndarray, steer: np.ndarray, yaw: np.ndarray, geom: VehicleGeometry
) -> float | None:
    """R² of eq. 4 (constant ratio) against measured yaw rate; None if undefined."""
    if len(yaw) < 2:
        return None
    ss_tot = float(np.sum((yaw - yaw.mean()) ** 2))
    if ss_tot == 0.0:
        return None
    ss_res = float(np.sum((yaw - yaw_rate_ref(vx, steer, geom)) ** 2))
    return 1.0 - ss_res / ss_tot


def fit_steer_ratio(
    vx: np.ndarray, steer: np.ndarray, yaw: np.ndarray, geom: VehicleGeometry, cfg: DescribeConfig
) -> float | None:
    """Least-squares constant steering ratio i_sw of eq. 4 (bounded 1-D search); None if no data."""
    if len(yaw) < 2 or not np.any(steer):
        return None

    def sse(ratio: float) -> float:
        ref = yaw_rate_ref(vx, steer, dataclasses.replace(geom, steer_ratio=ratio))
        return float(np.sum((yaw - ref) ** 2))

    res = minimize_scalar(
        sse,
        bounds=cfg.steer_ratio_bounds,
        method="bounded",
        options={"xatol": cfg.steer_ratio_xatol},
    )
    return float(res.x)


def _na(v, fmt: str) -> str:
    return "n/a" if v is None else format(v, fmt)


def unavailable_fields(channels: tuple[str, ...]) -> dict[str, str]:
    """field -> one-line reason, for every figure of :data:`NEEDS` a channel set lacks."""
    have = set(channels)
    out = {}
    for fld, needs in NEEDS.items():
        missing = [c for c in needs if c not in have]
        if missing:
            out[fld] = f"needs {', '.join(needs)}; the campaign lacks {', '.join(missing)}"
    return out


@dataclass(frozen=True)
class FoldSummary:
    """Whether the campaign's k-fold CV can be stratified, and the plan's one-line note."""

    stratified: bool
    note: str

    def to_json(self) -> dict:
        return {"stratified": self.stratified, "note": self.note}


def fold_summary(campaign: Campaign) -> FoldSummary:
    """The CV fold plan of :func:`parknss.data.splits.cv_plan` in brief (never raises)."""
    from parknss.data.splits import cv_plan

    try:
        plan = cv_plan(campaign)
    except DataError as exc:
        return FoldSummary(False, f"no CV possible: {exc}")
    return FoldSummary(plan.stratified, plan.note)


@dataclass(frozen=True)
class CampaignSummary:
    """Per-trial summaries plus the campaign-level checks (None where undefined or where
    the campaign lacks a channel: ``unavailable`` says which)."""

    name: str
    trials: list[TrialSummary]
    yaw_r2: float | None
    steer_ratio_fit: float | None
    wheelbase_m: float
    nominal_steer_ratio: float
    moving_samples: int | None
    blind_zone_fraction: float | None
    channels: tuple[str, ...] = REQUIRED_CHANNELS
    workflows: dict[str, WorkflowSupport] = dataclasses.field(default_factory=dict)
    unavailable: dict[str, str] = dataclasses.field(default_factory=dict)
    parking_speed_max_kmh: float = 20.0
    folds: FoldSummary | None = None
    sign_checks: list[SignCheck] = dataclasses.field(default_factory=list)
    short_frames: dict[str, dict[str, int]] = dataclasses.field(default_factory=dict)

    @property
    def absent_channels(self) -> tuple[str, ...]:
        return tuple(c for c in REQUIRED_CHANNELS if c not in self.channels)

    @property
    def direction_changes(self) -> int | None:
        vals = [t.direction_changes for t in self.trials]
        return None if None in vals else sum(vals)  # type: ignore[arg-type]

    @property
    def reversals_while_moving(self) -> int | None:
        vals = [t.reversals_while_moving for t in self.trials]
        return None if None in vals else sum(vals)  # type: ignore[arg-type]

    @property
    def total_length_s(self) -> float:
        return sum(t.length_s for t in self.trials)

    @property
    def outside_parking_domain(self) -> list[str]:
        """Ids of the trials whose max |vx| exceeds the parking-speed threshold."""
        return [t.id for t in self.trials if t.outside_parking_domain]

    @property
    def flagged_trials(self) -> list[str]:
        """Ids of the trials with at least one channel flag."""
        return [t.id for t in self.trials if t.flags]

    def to_json(self) -> dict:
        """One JSON-able object (keys in docs/data.md)."""
        rwm = self.reversals_while_moving
        return {
            "name": self.name,
            "n_trials": len(self.trials),
            "total_length_s": round(self.total_length_s, 2),
            "trials": [t.to_json() for t in self.trials],
            "yaw_r2": self.yaw_r2,
            "steer_ratio_fit": self.steer_ratio_fit,
            "direction_changes": self.direction_changes,
            "reversals_at_standstill": None if rwm is None else rwm == 0,
            "reversals_while_moving": rwm,
            "blind_zone_fraction": self.blind_zone_fraction,
            "moving_samples": self.moving_samples,
            "wheelbase_m": self.wheelbase_m,
            "nominal_steer_ratio": self.nominal_steer_ratio,
            "channels": list(self.channels),
            "absent_channels": list(self.absent_channels),
            "workflows": {k: w.to_json() for k, w in self.workflows.items()},
            "unavailable": dict(self.unavailable),
            "parking_speed_max_kmh": self.parking_speed_max_kmh,
            "outside_parking_domain": self.outside_parking_domain,
            "flagged_trials": self.flagged_trials,
            "folds": None if self.folds is None else self.folds.to_json(),
            "sign_checks": [c.to_json() for c in self.sign_checks],
            "short_frames": dict(self.short_frames),
        }

    def _id_width(self) -> int:
        return max([22, *(len(t.id) for t in self.trials)])

    def _trial_rows(self) -> list[str]:
        w, c = self._id_width(), max([16, *(len(t.maneuver) for t in self.trials)])
        head = (
            f"{'trial':<{w}} {'class':<{c}} {'length s':>8} {'dir.ch.':>7} "
            f"{'blind':>6} {'max km/h':>8} {'moving rev.':>11} {'flags':>5}"
        )
        rows = [head]
        for t in self.trials:
            mark = " !" if t.outside_parking_domain else ""
            rows.append(
                f"{t.id:<{w}} {t.maneuver:<{c}} {t.length_s:8.2f} "
                f"{_na(t.direction_changes, '7d')} "
                f"{_na(t.blind_zone_fraction, '6.3f')} {_na(t.max_speed_kmh, '8.2f')} "
                f"{_na(t.reversals_while_moving, '11d')} {len(t.flags):5d}{mark}"
            )
        return rows

    def _why(self, fld: str) -> str:
        return f" ({self.unavailable[fld]})" if fld in self.unavailable else ""

    def _check_rows(self) -> list[str]:
        r2 = _na(self.yaw_r2, ".4f")
        fit = _na(self.steer_ratio_fit, ".3f")
        rwm, dc = self.reversals_while_moving, self.direction_changes
        stand = (
            "n/a"
            if rwm is None
            else ("all at standstill" if rwm == 0 else f"{rwm} NOT at standstill")
        )
        moving = _na(self.moving_samples, "d")
        return [
            f"yaw R² (eq. 4, L={self.wheelbase_m} m, i={self.nominal_steer_ratio}, moving "
            f"region, {moving} samples): {r2}{self._why('yaw_r2')}",
            f"steering-ratio fit (eq. 4, least squares): {fit}{self._why('steer_ratio_fit')}",
            f"direction changes: {_na(dc, 'd')} ({stand}){self._why('reversals_while_moving')}",
            f"blind-zone fraction (|vx| < 0.5 km/h): {_na(self.blind_zone_fraction, '.3f')}"
            f"{self._why('blind_zone_fraction')}",
        ]

    def _domain_row(self) -> str:
        lim = f"max |vx| <= {self.parking_speed_max_kmh:g} km/h"
        if "outside_parking_domain" in self.unavailable:
            return f"parking-speed domain ({lim}): n/a{self._why('outside_parking_domain')}"
        out = [t for t in self.trials if t.outside_parking_domain]
        if not out:
            return f"parking-speed domain ({lim}): all {len(self.trials)} trials inside"
        ids = ", ".join(f"{t.id} ({t.max_speed_kmh:.1f} km/h)" for t in out)
        return f"parking-speed domain ({lim}): {len(out)} trial(s) outside (!): {ids}"

    def _flag_rows(self) -> list[str]:
        flags = [(t.id, f) for t in self.trials for f in t.flags]
        if not flags:
            return ["channel flags: none"]
        rows = [f"channel flags ({len(flags)} in {len(self.flagged_trials)} trials):"]
        w = self._id_width()
        rows += [f"  {tid:<{w}} {f.channel:<15} {f.detail}" for tid, f in flags]
        return rows

    def _sign_rows(self) -> list[str]:
        rows = ["sign and offset checks:" if self.sign_checks else "sign and offset checks: n/a"]
        for c in self.sign_checks:
            rows.append(f"  {c.detail}")
            if c.fix is not None:
                rows.append(f"    fix in the mapping: {c.fix}")
        if self.short_frames:
            items = "; ".join(f"{tid}: " + ", ".join(f"{k} {n}" for k, n in d.items())
                              for tid, d in self.short_frames.items())
            rows.append(f"frames shorter than the DBC length (masked): {items}")
        return rows

    def _workflow_rows(self) -> list[str]:
        rows = ["workflows:"]
        for name, w in self.workflows.items():
            rows.append(f"  {name:<12} {'yes' if w.ok else 'no ':<4} {w.reason}")
        return rows

    def table(self) -> str:
        """Plain-text report: channels, one row per trial, the campaign checks, the
        parking-speed domain, the channel flags, the workflows and the fold plan."""
        absent = self.absent_channels
        have = (
            f"all {len(self.channels)} schema channels"
            if not absent
            else f"{len(self.channels)} of {len(REQUIRED_CHANNELS)} schema channels "
            f"(absent: {', '.join(absent)})"
        )
        lines = [
            f"campaign {self.name}: {len(self.trials)} trials, {self.total_length_s:.1f} s",
            f"channels: {have}",
            *self._trial_rows(),
            *self._check_rows(),
            self._domain_row(),
            *self._flag_rows(),
            *self._sign_rows(),
            *self._workflow_rows(),
        ]
        if self.folds is not None:
            lines.append(f"folds: {self.folds.note}")
        return "\n".join(lines)


def describe_campaign(
    campaign: Campaign, geom: VehicleGeometry | None = None, config: DescribeConfig | None = None
) -> CampaignSummary:
    """Summarize a campaign; ``geom`` overrides the recorded/default vehicle geometry.

    Works on campaigns lacking channels (figures needing them are None, with the reason in
    ``unavailable``); raises DataError if the trials differ in their channels.
    """
    cfg = config or load_describe_config()
    g = geom or campaign_geometry(campaign)
    channels = campaign_channels(campaign)
    unavailable = unavailable_fields(channels)
    has_vx = "vx" in channels
    if "yaw_r2" not in unavailable:
        vx, steer, yaw = moving_samples(campaign)
        r2, fit = yaw_r2(vx, steer, yaw, g), fit_steer_ratio(vx, steer, yaw, g, cfg)
    else:
        r2 = fit = None
    checks = sign_checks(campaign, channels, g, cfg)
    ranges = plausible_ranges()
    n_total = sum(tr.n for tr in campaign)
    n_moving = sum(int(np.sum(moving_mask(tr["vx"]))) for tr in campaign) if has_vx else None
    blind = None
    if n_moving is not None:
        blind = (n_total - n_moving) / n_total if n_total else 0.0
    return CampaignSummary(
        name=campaign.name,
        trials=[summarize_trial(tr, cfg, ranges) for tr in campaign],
        yaw_r2=r2,
        steer_ratio_fit=fit,
        wheelbase_m=g.wheelbase,
        nominal_steer_ratio=g.steer_ratio,
        moving_samples=n_moving,
        blind_zone_fraction=blind,
        channels=channels,
        workflows=support(campaign),
        unavailable=unavailable,
        parking_speed_max_kmh=cfg.parking_speed_max_kmh,
        folds=fold_summary(campaign),
        sign_checks=checks,
        short_frames=short_frames(campaign),
    )


def sign_checks(
    campaign: Campaign, channels: tuple[str, ...], g: VehicleGeometry, cfg: DescribeConfig
) -> list[SignCheck]:
    """The sign checks of ax and ay and the yaw-rate offset (those the channels allow)."""
    have = set(channels)
    n = max(1, round(cfg.sign_smooth_s * SAMPLE_RATE_HZ))
    out = []
    if {"vx", "ax"} <= have:
        out.append(sign_check(campaign, "ax", "dvx/dt",
                              lambda tr: np.gradient(tr["vx"], tr["t"]), n, cfg.sign_corr_min))
    if {"vx", "ay", "yaw_rate"} <= have:
        out.append(sign_check(campaign, "ay", "vx·ω_z", lambda tr: tr["vx"] * tr["yaw_rate"],
                              n, cfg.sign_corr_min))
    if {"vx", "yaw_rate"} <= have:
        out.append(_yaw_offset_check(campaign, "steer" in have, g, cfg))
    return out


def _yaw_offset_check(campaign: Campaign, steer: bool, g: VehicleGeometry,
                      cfg: DescribeConfig) -> SignCheck:
    off, n = yaw_offset(campaign, cfg.standstill_kmh)
    where = f"yaw rate at standstill (|vx| < {cfg.standstill_kmh:g} km/h, {n} samples)"
    if off is None or n < cfg.standstill_min_samples:
        return SignCheck("yaw_offset", off, None, f"{where}: too few samples to check")
    dps = off * DEG_PER_RAD
    if abs(dps) <= cfg.yaw_offset_min_dps:
        return SignCheck("yaw_offset", off, True, f"{where}: median {dps:.3f} °/s (no offset)")
    extra: dict = {"offset_dps": dps}
    after = ""
    if steer:
        vx, st, yaw = moving_samples(campaign)
        r2 = yaw_r2(vx, st, yaw - off, g)
        fit = fit_steer_ratio(vx, st, yaw - off, g, cfg)
        extra |= {"yaw_r2_after": r2, "steer_ratio_fit_after": fit}
        after = f"; after removing it: yaw R² {_na(r2, '.4f')}, steering-ratio fit " \
                f"{_na(fit, '.3f')}"
    return SignCheck(
        "yaw_offset", off, False,
        f"{where}: median {dps:.3f} °/s: an offset{after}",
        f"yaw_rate: {{..., offset: {-dps:.4g}}} (yaw rate mapped in deg/s; "
        f"{-off:.4g} in rad/s)",
        extra,
    )
