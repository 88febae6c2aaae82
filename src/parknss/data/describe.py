"""Campaign summary: per-trial shape and the campaign-level kinematic checks of §IV-A.

Per trial: class, length, direction changes, blind-zone fraction, max |vx|. For the
campaign: the R² of the kinematic-bicycle yaw rate (eq. 4, constant ratio) against the
measured yaw rate over the moving region, the least-squares steering ratio of eq. 4, the
total direction changes and how many reversals did not happen at standstill.

Definitions (also in docs/data.md):

* direction change: a sign change of the ``gear`` channel between -1 (R) and +1 (D),
  neutral/park samples (0) skipped, so R -> N -> D counts once and R -> N -> R not at all;
* a reversal is at standstill when |vx| < 0.5 km/h (signals.BLIND_ZONE_MS) on every
  sample from the last sample of the old gear to the first sample of the new one;
* blind-zone fraction: share of samples with |vx| < 0.5 km/h;
* moving region: |vx| >= 0.5 km/h (signals.moving_mask), pooled over all trials.

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
from parknss.data.trial import Campaign, Trial
from parknss.data.validate import load_data_section
from parknss.signals import BLIND_ZONE_MS, moving_mask, ms_to_kmh
from parknss.vehicle import VehicleGeometry, yaw_rate_ref


class DescribeConfig(StrictModel):
    """Settings of the steering-ratio fit (section ``describe`` of configs/data.yaml).

    Attributes:
        steer_ratio_bounds: search interval of the bounded 1-D least-squares fit, (-).
        steer_ratio_xatol: absolute tolerance on the fitted ratio, (-).
    """

    steer_ratio_bounds: tuple[float, float] = (5.0, 30.0)
    steer_ratio_xatol: float = Field(1.0e-6, gt=0.0)

    @model_validator(mode="after")
    def _ordered(self) -> DescribeConfig:
        lo, hi = self.steer_ratio_bounds
        if not 0.0 < lo < hi:
            raise ValueError("steer_ratio_bounds must satisfy 0 < lo < hi")
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


@dataclass(frozen=True)
class TrialSummary:
    """One trial's shape. Lengths in s, speed in km/h, fractions in [0, 1]."""

    id: str
    maneuver: str
    length_s: float
    direction_changes: int
    blind_zone_fraction: float
    max_speed_kmh: float
    reversals_while_moving: int

    def to_json(self) -> dict:
        return {
            "id": self.id,
            "class": self.maneuver,
            "length_s": round(self.length_s, 2),
            "direction_changes": self.direction_changes,
            "blind_zone_fraction": self.blind_zone_fraction,
            "max_speed_kmh": self.max_speed_kmh,
            "reversals_while_moving": self.reversals_while_moving,
        }


def summarize_trial(trial: Trial) -> TrialSummary:
    """The per-trial figures of :class:`TrialSummary`."""
    vx, gear = trial["vx"], trial["gear"]
    return TrialSummary(
        id=trial.id,
        maneuver=trial.maneuver,
        length_s=float(trial.duration_s),
        direction_changes=direction_changes(gear),
        blind_zone_fraction=float(1.0 - moving_mask(vx).mean()),
        max_speed_kmh=float(ms_to_kmh(np.abs(vx).max())),
        reversals_while_moving=reversals_while_moving(gear, vx),
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


@dataclass(frozen=True)
class CampaignSummary:
    """Per-trial summaries plus the campaign-level checks (None where undefined)."""

    name: str
    trials: list[TrialSummary]
    yaw_r2: float | None
    steer_ratio_fit: float | None
    wheelbase_m: float
    nominal_steer_ratio: float
    moving_samples: int
    blind_zone_fraction: float

    @property
    def direction_changes(self) -> int:
        return sum(t.direction_changes for t in self.trials)

    @property
    def reversals_while_moving(self) -> int:
        return sum(t.reversals_while_moving for t in self.trials)

    @property
    def total_length_s(self) -> float:
        return sum(t.length_s for t in self.trials)

    def to_json(self) -> dict:
        """One JSON-able object (keys in docs/data.md)."""
        return {
            "name": self.name,
            "n_trials": len(self.trials),
            "total_length_s": round(self.total_length_s, 2),
            "trials": [t.to_json() for t in self.trials],
            "yaw_r2": self.yaw_r2,
            "steer_ratio_fit": self.steer_ratio_fit,
            "direction_changes": self.direction_changes,
            "reversals_at_standstill": self.reversals_while_moving == 0,
            "reversals_while_moving": self.reversals_while_moving,
            "blind_zone_fraction": self.blind_zone_fraction,
            "moving_samples": self.moving_samples,
            "wheelbase_m": self.wheelbase_m,
            "nominal_steer_ratio": self.nominal_steer_ratio,
        }

    def table(self) -> str:
        """Plain-text table: one row per trial, then the campaign checks."""
        head = (
            f"{'trial':<22} {'class':<16} {'length s':>8} {'dir.ch.':>7} "
            f"{'blind':>6} {'max km/h':>8} {'moving rev.':>11}"
        )
        lines = [
            f"campaign {self.name}: {len(self.trials)} trials, {self.total_length_s:.1f} s",
            head,
        ]
        for t in self.trials:
            lines.append(
                f"{t.id:<22} {t.maneuver:<16} {t.length_s:8.2f} {t.direction_changes:7d} "
                f"{t.blind_zone_fraction:6.3f} {t.max_speed_kmh:8.2f} "
                f"{t.reversals_while_moving:11d}"
            )
        r2 = "n/a" if self.yaw_r2 is None else f"{self.yaw_r2:.4f}"
        fit = "n/a" if self.steer_ratio_fit is None else f"{self.steer_ratio_fit:.3f}"
        stand = (
            "all at standstill"
            if self.reversals_while_moving == 0
            else f"{self.reversals_while_moving} NOT at standstill"
        )
        lines += [
            f"yaw R² (eq. 4, L={self.wheelbase_m} m, i={self.nominal_steer_ratio}, moving "
            f"region, {self.moving_samples} samples): {r2}",
            f"steering-ratio fit (eq. 4, least squares): {fit}",
            f"direction changes: {self.direction_changes} ({stand})",
            f"blind-zone fraction (|vx| < 0.5 km/h): {self.blind_zone_fraction:.3f}",
        ]
        return "\n".join(lines)


def describe_campaign(
    campaign: Campaign, geom: VehicleGeometry | None = None, config: DescribeConfig | None = None
) -> CampaignSummary:
    """Summarize a campaign; ``geom`` overrides the recorded/default vehicle geometry."""
    cfg = config or load_describe_config()
    g = geom or campaign_geometry(campaign)
    vx, steer, yaw = moving_samples(campaign)
    n_total = sum(tr.n for tr in campaign)
    n_blind = sum(int(np.sum(~moving_mask(tr["vx"]))) for tr in campaign)
    return CampaignSummary(
        name=campaign.name,
        trials=[summarize_trial(tr) for tr in campaign],
        yaw_r2=yaw_r2(vx, steer, yaw, g),
        steer_ratio_fit=fit_steer_ratio(vx, steer, yaw, g, cfg),
        wheelbase_m=g.wheelbase,
        nominal_steer_ratio=g.steer_ratio,
        moving_samples=len(vx),
        blind_zone_fraction=n_blind / n_total if n_total else 0.0,
    )
