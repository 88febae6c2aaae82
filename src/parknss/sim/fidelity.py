"""Closed-loop fidelity of the learned chain against the truth, cell by cell.

The same plan is driven once under the learned chain and once under the reference
vehicle (the truth the chain was identified from); :func:`compare_outcomes` scores the
chain's run against the truth's as a :class:`CellFidelity`, :func:`summarize_fidelity`
aggregates the cells into a :class:`FidelitySummary` and checks the targets of
:class:`FidelityConfig` (configs/fidelity.yaml). Differences are chain minus truth.

Traces (100 Hz, the bus outputs each plant reports, as the closed loop recorded them:
``vx`` m/s, ``yaw_rate`` rad/s, ``ax`` m/s², ``steer`` deg of steering wheel,
``gear_cmd``) are compared on one time axis from the start of the manoeuvre; the
shorter run is held at its last sample (the car parked) up to the longer run's length,
so a stretched run is scored for being late. The ISO/TS 18571 rating takes the truth
as the measured curve and the chain as the prediction.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from pydantic import Field

from parknss.config import StrictModel, load_config
from parknss.metrics.iso18571 import ISORatingConfig, rate
from parknss.signals import DT
from parknss.sim.closed_loop import Outcome

TRACE_CHANNELS = ("vx", "yaw_rate", "ax", "steer")


class FidelityTargets(StrictModel):
    """The issue's targets (issue 44): pass/fail lines of the summary."""

    outcome_agreement: float = Field(0.99, ge=0, le=1, description="same outcome, fraction")
    collisions_where_truth_parks: int = Field(0, ge=0, description="at most this many")
    duration_median: float = Field(0.05, ge=0, description="median |ratio - 1| at most")
    duration_p90: float = Field(0.15, ge=0, description="90th pct |ratio - 1| at most")
    goal_diff_median_cm: float = Field(2.0, ge=0, description="median |goal diff| at most")
    clearance_diff_median_cm: float = Field(3.0, ge=0, description="median |clr diff|, cm")
    iso_mean: float = Field(0.8, ge=0, le=1, description="mean ISO rating of vx and ω_z")


class FidelityConfig(StrictModel):
    """configs/fidelity.yaml: the plant noise seeds and the targets."""

    seed: int = Field(44_000, ge=0, description="base of the fresh per-cell noise seeds")
    targets: FidelityTargets = FidelityTargets()
    iso: ISORatingConfig = ISORatingConfig()


def load_fidelity_config(path: str | Path | None = None) -> FidelityConfig:
    """Read ``path`` (default: the shipped configs/fidelity.yaml)."""
    return load_config(FidelityConfig, path, default="fidelity.yaml")


def cell_seed(base: int, name: str) -> int:
    """The fresh plant-noise seed of the cell ``name`` under the base seed ``base``
    (independent of the campaign's trial seeds and of the cell's place in a list)."""
    digest = np.frombuffer(name.encode(), dtype=np.uint8).astype(np.uint32)
    ss = np.random.SeedSequence([int(base) & 0xFFFFFFFF, 44, *digest.tolist()])
    return int(ss.generate_state(1)[0])


@dataclass
class CellFidelity:
    """The chain's run of one cell against the truth's (cm, deg, s; diff = chain - truth)."""

    cell: str
    chain_reason: str
    truth_reason: str
    outcome_agree: bool
    collision_where_truth_parks: bool
    chain_duration_s: float
    truth_duration_s: float
    duration_ratio: float | None
    chain_goal_cm: float | None
    truth_goal_cm: float | None
    goal_diff_cm: float | None
    heading_diff_deg: float | None
    chain_clearance_cm: float | None
    truth_clearance_cm: float | None
    clearance_diff_cm: float | None
    iso_vx: float | None
    iso_yaw_rate: float | None
    rmse_vx_ms: float | None
    rmse_yaw_rate_dps: float | None
    rmse_ax_ms2: float | None
    rmse_steer_deg: float | None
    chain_gear_changes: int
    truth_gear_changes: int
    gear_sequence_agree: bool
    gear_timing_mean_s: float | None  # mean |Δt| of matching gear changes (same sequence)
    # where the time goes (s): the tracker requesting forward, reverse, or standing
    chain_forward_s: float | None = None
    truth_forward_s: float | None = None
    chain_reverse_s: float | None = None
    truth_reverse_s: float | None = None
    chain_stand_s: float | None = None
    truth_stand_s: float | None = None

    @property
    def both_completed(self) -> bool:
        return self.chain_reason == "completed" and self.truth_reason == "completed"

    def to_json(self) -> dict:
        return asdict(self)


def held(series: dict[str, np.ndarray], key: str, n: int) -> np.ndarray:
    """``series[key]`` lengthened to ``n`` samples by holding its last sample."""
    v = np.asarray(series[key], float)
    if len(v) >= n:
        return v[:n]
    return np.concatenate([v, np.full(n - len(v), v[-1] if len(v) else 0.0)])


def gear_changes(series: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(times s, new gear) of every change of the commanded gear."""
    g = np.asarray(series["gear_cmd"], float)
    idx = np.flatnonzero(np.diff(g)) + 1
    return np.asarray(series["t"], float)[idx], g[idx]


def phase_times(series: dict[str, np.ndarray], dt: float = DT) -> tuple[float, float, float]:
    """Seconds with the tracker's speed request forward (> 0), reverse (< 0) and zero
    (standing: steering at standstill, stops, holds, gear changes)."""
    req = np.asarray(series.get("speed_req", ()), float)
    fwd, rev = int(np.sum(req > 0)), int(np.sum(req < 0))
    return fwd * dt, rev * dt, (len(req) - fwd - rev) * dt


def _diff(a: float | None, b: float | None) -> float | None:
    return None if a is None or b is None else float(a) - float(b)


def _iso(truth: np.ndarray, chain: np.ndarray, dt: float, cfg: ISORatingConfig) -> float:
    return float(rate(truth, chain, dt, cfg).overall)


def compare_outcomes(
    chain: Outcome, truth: Outcome, cell: str = "", iso: ISORatingConfig | None = None
) -> CellFidelity:
    """Score ``chain``'s closed-loop run against ``truth``'s on the same plan."""
    iso = iso or ISORatingConfig()
    ran = bool(chain.series) and bool(truth.series)
    n = max(len(chain.series.get("t", ())), len(truth.series.get("t", ()))) if ran else 0
    traces: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    if n >= 2:
        traces = {k: (held(chain.series, k, n), held(truth.series, k, n)) for k in TRACE_CHANNELS}
    dt = DT  # the closed loop records every plant at 10 ms

    def rmse(key: str, scale: float = 1.0) -> float | None:
        if key not in traces:
            return None
        c, t = traces[key]
        return float(np.sqrt(np.mean((scale * (c - t)) ** 2)))

    def iso_of(key: str) -> float | None:
        if key not in traces or n < 20:
            return None
        return _iso(traces[key][1], traces[key][0], dt, iso)

    tc, gc = gear_changes(chain.series) if ran else (np.zeros(0), np.zeros(0))
    tt, gt = gear_changes(truth.series) if ran else (np.zeros(0), np.zeros(0))
    same_gears = len(gc) == len(gt) and bool(np.all(gc == gt))
    ratio = chain.duration_s / truth.duration_s if ran and truth.duration_s > 0 else None
    pc = phase_times(chain.series) if ran else (None, None, None)
    pt = phase_times(truth.series) if ran else (None, None, None)
    return CellFidelity(
        cell=cell,
        chain_reason=chain.reason,
        truth_reason=truth.reason,
        outcome_agree=chain.reason == truth.reason,
        collision_where_truth_parks=chain.reason == "collision" and truth.reason == "completed",
        chain_duration_s=chain.duration_s,
        truth_duration_s=truth.duration_s,
        duration_ratio=ratio,
        chain_goal_cm=chain.goal_error_cm,
        truth_goal_cm=truth.goal_error_cm,
        goal_diff_cm=_diff(chain.goal_error_cm, truth.goal_error_cm),
        heading_diff_deg=_diff(chain.heading_error_deg, truth.heading_error_deg),
        chain_clearance_cm=chain.clearance_cm,
        truth_clearance_cm=truth.clearance_cm,
        clearance_diff_cm=_diff(chain.clearance_cm, truth.clearance_cm),
        iso_vx=iso_of("vx"),
        iso_yaw_rate=iso_of("yaw_rate"),
        rmse_vx_ms=rmse("vx"),
        rmse_yaw_rate_dps=rmse("yaw_rate", math.degrees(1.0)),
        rmse_ax_ms2=rmse("ax"),
        rmse_steer_deg=rmse("steer"),
        chain_gear_changes=len(gc),
        truth_gear_changes=len(gt),
        gear_sequence_agree=same_gears,
        gear_timing_mean_s=float(np.mean(np.abs(tc - tt))) if same_gears and len(gc) else None,
        chain_forward_s=pc[0],
        truth_forward_s=pt[0],
        chain_reverse_s=pc[1],
        truth_reverse_s=pt[1],
        chain_stand_s=pc[2],
        truth_stand_s=pt[2],
    )


@dataclass
class TargetLine:
    """One target: what is measured, the limit and whether it holds."""

    label: str
    measured: float | None
    limit: float
    passed: bool

    def text(self) -> str:
        m = "-" if self.measured is None else f"{self.measured:.3g}"
        return f"{'PASS' if self.passed else 'FAIL'}  {self.label}: {m} (target {self.limit:g})"


@dataclass
class FidelitySummary:
    """The cells of one fidelity run aggregated (cm, s); ratios over cells where both
    plants completed, outcome agreement and ISO over every executed cell."""

    cells: int
    executed: int
    outcome_agree: int
    collisions_where_truth_parks: int
    truth_completed: int
    chain_completed: int
    both_completed: int
    duration_ratio_median: float | None
    duration_dev_median: float | None  # median |ratio - 1|
    duration_dev_p90: float | None
    goal_diff_median_cm: float | None  # median |chain - truth|
    goal_diff_max_cm: float | None
    chain_goal_max_cm: float | None
    heading_diff_median_deg: float | None
    clearance_diff_median_cm: float | None
    iso_vx_mean: float | None
    iso_yaw_rate_mean: float | None
    gear_sequence_agree: int
    gear_timing_median_s: float | None
    targets: list[TargetLine]
    phase_ratio_median: dict[str, float | None] | None = None  # chain/truth per phase

    def to_json(self) -> dict:
        return asdict(self)


def _ratio(a: float | None, b: float | None) -> float | None:
    return None if a is None or b is None or b <= 0 else a / b


def _stat(fn, values) -> float | None:
    a = np.array([v for v in values if v is not None], float)
    return float(fn(a)) if len(a) else None


def summarize_fidelity(
    cells: list[CellFidelity | None], targets: FidelityTargets | None = None
) -> FidelitySummary:
    """Aggregate cells (None: a cell the planner could not solve) and check the targets."""
    tg = targets or FidelityTargets()
    ran = [c for c in cells if c is not None]
    both = [c for c in ran if c.both_completed]
    dev = [abs(c.duration_ratio - 1.0) for c in both if c.duration_ratio is not None]
    iso_vx = _stat(np.mean, [c.iso_vx for c in ran])
    iso_wz = _stat(np.mean, [c.iso_yaw_rate for c in ran])
    agree = sum(c.outcome_agree for c in ran)
    coll = sum(c.collision_where_truth_parks for c in ran)
    s = FidelitySummary(
        cells=len(cells),
        executed=len(ran),
        outcome_agree=agree,
        collisions_where_truth_parks=coll,
        truth_completed=sum(c.truth_reason == "completed" for c in ran),
        chain_completed=sum(c.chain_reason == "completed" for c in ran),
        both_completed=len(both),
        duration_ratio_median=_stat(np.median, [c.duration_ratio for c in both]),
        duration_dev_median=_stat(np.median, dev),
        duration_dev_p90=_stat(lambda a: np.percentile(a, 90), dev),
        goal_diff_median_cm=_stat(np.median, [abs(c.goal_diff_cm) for c in both]),
        goal_diff_max_cm=_stat(np.max, [abs(c.goal_diff_cm) for c in both]),
        chain_goal_max_cm=_stat(np.max, [c.chain_goal_cm for c in ran]),
        heading_diff_median_deg=_stat(np.median, [abs(c.heading_diff_deg) for c in both]),
        clearance_diff_median_cm=_stat(
            np.median, [abs(c.clearance_diff_cm) for c in both if c.clearance_diff_cm is not None]
        ),
        iso_vx_mean=iso_vx,
        iso_yaw_rate_mean=iso_wz,
        gear_sequence_agree=sum(c.gear_sequence_agree for c in ran),
        gear_timing_median_s=_stat(np.median, [c.gear_timing_mean_s for c in ran]),
        targets=[],
    )
    s.phase_ratio_median = {
        ph: _stat(np.median, [_ratio(getattr(c, f"chain_{ph}_s"), getattr(c, f"truth_{ph}_s"))
                              for c in both])
        for ph in ("forward", "reverse", "stand")
    }  # fmt: skip
    frac = agree / len(ran) if ran else None
    iso_mean = None if iso_vx is None or iso_wz is None else 0.5 * (iso_vx + iso_wz)

    def at_most(label, v, lim):
        return TargetLine(label, v, lim, v is not None and v <= lim)

    s.targets = [
        TargetLine("same outcome as the truth, fraction of executed cells", frac,
                   tg.outcome_agreement, frac is not None and frac >= tg.outcome_agreement),
        at_most("collisions where the truth parks", float(coll), tg.collisions_where_truth_parks),
        at_most("median |duration ratio - 1|", s.duration_dev_median, tg.duration_median),
        at_most("90th percentile |duration ratio - 1|", s.duration_dev_p90, tg.duration_p90),
        at_most("median |goal error difference| [cm]", s.goal_diff_median_cm,
                tg.goal_diff_median_cm),
        at_most("median |clearance difference| [cm]", s.clearance_diff_median_cm,
                tg.clearance_diff_median_cm),
        TargetLine("mean ISO/TS 18571 rating of vx and ω_z", iso_mean, tg.iso_mean,
                   iso_mean is not None and iso_mean >= tg.iso_mean),
    ]  # fmt: skip
    return s


def _f(v, spec: str) -> str:
    return "-" if v is None else format(v, spec)


def fidelity_text(s: FidelitySummary) -> str:
    """The summary as the lines ``parknss fidelity`` prints."""
    lines = [
        f"executed cells {s.executed}/{s.cells}; same outcome {s.outcome_agree}/{s.executed}; "
        f"completed chain {s.chain_completed}, truth {s.truth_completed}, both {s.both_completed}",
        f"duration ratio chain/truth median {_f(s.duration_ratio_median, '.3f')}; "
        f"|ratio-1| median {_f(s.duration_dev_median, '.3f')}, "
        f"p90 {_f(s.duration_dev_p90, '.3f')}",
        f"|goal error diff| median {_f(s.goal_diff_median_cm, '.2f')} cm, max "
        f"{_f(s.goal_diff_max_cm, '.2f')} cm (chain goal max {_f(s.chain_goal_max_cm, '.2f')}"
        f" cm); |heading diff| median {_f(s.heading_diff_median_deg, '.2f')} deg",
        f"|clearance diff| median {_f(s.clearance_diff_median_cm, '.2f')} cm",
        f"ISO/TS 18571 mean: vx {_f(s.iso_vx_mean, '.3f')}, ω_z {_f(s.iso_yaw_rate_mean, '.3f')}",
        f"gear sequence agrees {s.gear_sequence_agree}/{s.executed}; gear timing |Δt| median "
        f"{_f(s.gear_timing_median_s, '.2f')} s",
    ]
    if s.phase_ratio_median:
        lines.append(
            "time chain/truth, median per phase: "
            + ", ".join(f"{k} {_f(v, '.3f')}" for k, v in s.phase_ratio_median.items())
        )
    return "\n".join(lines + [t.text() for t in s.targets])
