"""Table II: stratified k-fold cross-validation of the NSS, with two baselines on the same folds.

Every fold of :func:`~parknss.data.splits.stratified_folds` (one trial per maneuver class
held out) is fitted and scored by :func:`~parknss.experiments.folds.fold_job`, for three
models in the same run:

* ``nss``: the physics-informed NSS at the given configuration (the paper's by default);
* ``nss_direct_yaw``: the same with the yaw rate as a plain state (no residual readout);
* ``linear``: the least-squares linear state-space model of :mod:`parknss.nss.linear`.

Rows are the moving-region vx MSE in (km/h)², the reverse-subset vx MSE and the
moving-region yaw-rate MSE in (°/s)², per fold and as mean ± std over the folds, where
std is the population standard deviation (ddof = 0), the convention that reproduces the
paper's 0.108 ± 0.038 from its four fold values.

A campaign that is not stratifiable (unlabelled trials, a class with fewer trials than
folds, classes of different sizes) is split by plain k-fold instead
(:func:`~parknss.data.splits.cv_plan`); the result says so in ``stratified`` and ``note``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from parknss.data.splits import DEFAULT_FOLDS, FoldPlan
from parknss.experiments.executor import Job, run_jobs

MODEL_VARIANTS: dict[str, tuple[str, dict]] = {
    "nss": ("nss", {}),
    "nss_direct_yaw": ("nss", {"model": {"residual_yaw": False}}),
    "linear": ("linear", {}),
}
COLUMNS: tuple[tuple[str, str], ...] = (
    ("vx_mse_moving_kmh2", "vx [(km/h)²]"),
    ("vx_mse_reverse_kmh2", "rev. vx [(km/h)²]"),
    ("yaw_mse_moving_degs2", "ω_z [(°/s)²]"),
)
FOLDS = DEFAULT_FOLDS


def merge(base: dict, extra: dict) -> dict:
    """Section-wise merge of two override dicts ({section: {field: value}})."""
    out = {k: dict(v) for k, v in base.items()}
    for sec, vals in extra.items():
        out[sec] = {**out.get(sec, {}), **vals}
    return out


def mean_std(values: list[float]) -> tuple[float, float]:
    """Mean and population std (ddof = 0) ignoring NaN; (nan, nan) if nothing is left."""
    v = np.asarray([x for x in values if x is not None and not math.isnan(x)], dtype=float)
    if v.size == 0:
        return math.nan, math.nan
    return float(v.mean()), float(v.std(ddof=0))


@dataclass
class CVResult:
    """Fold results by model variant (each a list of FoldResult JSON, fold order).

    ``stratified`` and ``note`` come from the fold plan (:class:`FoldPlan`): False and the
    reason when the campaign was split by plain k-fold.
    """

    folds: dict[str, list[dict]]
    overrides: dict = field(default_factory=dict)
    wall_s: float = 0.0
    stratified: bool = True
    note: str = ""

    def column(self, variant: str, key: str, reference: str = "errors") -> list[float]:
        """One metric over the folds of a variant (NaN where absent)."""
        out = []
        for f in self.folds[variant]:
            errs = f.get(reference) or {}
            v = errs.get(key)
            out.append(math.nan if v is None else float(v))
        return out

    def summary(self, reference: str = "errors") -> dict[str, dict[str, dict[str, float]]]:
        """variant -> metric -> {"mean", "std"}."""
        return {
            var: {
                key: dict(
                    zip(("mean", "std"), mean_std(self.column(var, key, reference)), strict=True)
                )
                for key, _ in COLUMNS
            }
            for var in self.folds
        }

    def table(self) -> str:
        """Table II as text: NSS per fold and mean ± std, then the baselines' mean ± std."""
        head = f"{'':36s}" + "".join(f"{label:>22s}" for _, label in COLUMNS)
        kind = "stratified" if self.stratified else "plain"
        lines = [f"Table II: {kind} {FOLDS}-fold CV on held-out maneuvers (moving region)"]
        if self.note:
            lines.append(self.note)
        lines.append(head)
        if "nss" in self.folds:
            for i, _ in enumerate(self.folds["nss"]):
                cells = "".join(f"{self.column('nss', k)[i]:>22.3f}" for k, _ in COLUMNS)
                lines.append(f"{'fold ' + str(i):36s}{cells}")
        for ref, tag in (("errors", ""), ("truth_errors", " vs truth")):
            s = self.summary(ref)
            for var in self.folds:
                cells = "".join(
                    f"{s[var][k]['mean']:>13.3f} ± {s[var][k]['std']:<6.3f}" for k, _ in COLUMNS
                )
                if all(math.isnan(s[var][k]["mean"]) for k, _ in COLUMNS):
                    continue
                lines.append(f"{var + tag + ' mean ± std':36s}{cells}")
        return "\n".join(lines)

    def to_json(self) -> dict:
        return {
            "folds": self.folds,
            "summary": self.summary("errors"),
            "summary_truth": self.summary("truth_errors"),
            "overrides": self.overrides,
            "wall_s": self.wall_s,
            "stratified": self.stratified,
            "note": self.note,
        }


def cv_jobs(
    data: str | None,
    config: str | None,
    overrides: dict,
    variants: list[str],
    save_dir: Path | None = None,
    folds: int = FOLDS,
) -> list[tuple[str, Job]]:
    """(variant, job) for every variant and fold."""
    jobs = []
    for var in variants:
        model, extra = MODEL_VARIANTS[var]
        for i in range(folds):
            kw = {
                "split": "cv",
                "index": i,
                "model": model,
                "data": data,
                "config": config,
                "overrides": merge(overrides, extra) if model == "nss" else {},
            }
            if save_dir is not None and model == "nss":
                kw["save_dir"] = str(save_dir / f"{var}_fold{i}")
            jobs.append((var, Job("parknss.experiments.folds:fold_job", kw, f"{var} fold {i}")))
    return jobs


def run_cv(
    data: str | None = None,
    config: str | None = None,
    overrides: dict | None = None,
    variants: list[str] | None = None,
    executor: str = "local",
    workers: int | None = None,
    address: str | None = None,
    cache_dir: str | Path | None = None,
    save_dir: str | Path | None = None,
    progress: bool = True,
    plan: FoldPlan | None = None,
) -> CVResult:
    """Run the CV of every variant (default: nss, nss_direct_yaw, linear) on the same folds.

    ``plan``: the campaign's CV fold plan, for the result's ``stratified`` and ``note``
    (computed from the campaign when not given; the fold jobs build the same folds).
    """
    import time

    variants = list(variants or MODEL_VARIANTS)
    for v in variants:
        if v not in MODEL_VARIANTS:
            from parknss.errors import ConfigError

            raise ConfigError(f"unknown CV variant {v!r}; one of {', '.join(MODEL_VARIANTS)}")
    overrides = overrides or {}
    t0 = time.perf_counter()
    pairs = cv_jobs(data, config, overrides, variants, Path(save_dir) if save_dir else None)
    results = run_jobs(
        [j for _, j in pairs],
        executor=executor,
        workers=workers,
        cache_dir=cache_dir,
        address=address,
        progress=progress,
        desc="cv folds",
    )
    folds: dict[str, list[dict]] = {v: [] for v in variants}
    for (var, _), res in zip(pairs, results, strict=True):
        folds[var].append(res)
    if plan is None:
        from parknss.data.splits import cv_plan
        from parknss.nss.campaigns import load_campaign

        plan = cv_plan(load_campaign(data))
    return CVResult(folds, overrides, time.perf_counter() - t0, plan.stratified, plan.note)
