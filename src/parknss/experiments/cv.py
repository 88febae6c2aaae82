"""Table II: stratified k-fold cross-validation of the NSS, with two baselines on the same folds.

Every fold of :func:`~parknss.data.splits.stratified_folds` (one trial per maneuver class
held out) is fitted and scored by :func:`~parknss.experiments.folds.fold_job`, for three
models in the same run:

* ``nss``: the physics-informed NSS at the given configuration (the paper's by default);
* ``nss_direct_yaw``: the same with the yaw rate as a plain state (no residual readout);
* ``linear``: the least-squares linear state-space model of :mod:`parknss.nss.linear`.

Rows are the moving-region vx MSE in (km/h)², the reverse-subset vx MSE and the
moving-region yaw-rate MSE in (°/s)², per fold and as mean ± std over the folds, where
std is the sample standard deviation (ddof = 1), as every spread of the studies (the
seed floor, the verdicts' intervals); the paper's 0.108 ± 0.038 is the population std
(ddof = 0) of its four fold values, 0.044 in ddof 1.

A campaign that is not stratifiable (unlabelled trials, a class with fewer trials than
folds, classes of different sizes) is split by plain k-fold instead
(:func:`~parknss.data.splits.cv_plan`); the result says so in ``stratified`` and ``note``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from parknss.data.splits import DEFAULT_FOLDS, FoldPlan, cv_plan
from parknss.errors import ConfigError
from parknss.executor import Job, Store, Tally, run_jobs
from parknss.experiments.config import merge_overrides
from parknss.experiments.folds import fold_config
from parknss.experiments.jobs import FOLD_JOB
from parknss.nss.campaigns import load_campaign
from parknss.nss.checkpoint import load_model
from parknss.nss.predict import predict_trials
from parknss.outputs import run_folder
from parknss.report.nss_figures import draw_history, draw_rollouts, pick_maneuvers

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


def mean_std(values: list[float]) -> tuple[float, float]:
    """Mean and sample std (ddof = 1, as every spread of the studies) ignoring NaN;
    (nan, nan) if nothing is left, std NaN for one value."""
    v = np.asarray([x for x in values if x is not None and not math.isnan(x)], dtype=float)
    if v.size == 0:
        return math.nan, math.nan
    return float(v.mean()), float(v.std(ddof=1)) if v.size > 1 else math.nan


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


def state_folder(variant: str, index: int) -> str:
    """The folder name of a Table II fit: its saved model under the run's models folder,
    its training state under ``OUT/state``."""
    return f"{variant}_fold{index}"


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
                "overrides": merge_overrides(overrides, extra) if model == "nss" else {},
            }
            if save_dir is not None and model == "nss":
                kw["save_dir"] = str(save_dir / state_folder(var, i))
                # the fit's resumable state: a killed run resumes mid-fold, not from epoch 0
                kw["state_dir"] = str(save_dir.parent / "state" / state_folder(var, i))
            jobs.append((var, Job(FOLD_JOB, kw, f"{var} fold {i}")))
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
    store: Store | None = None,
    tally: Tally | None = None,
) -> CVResult:
    """Run the CV of every variant (default: nss, nss_direct_yaw, linear) on the same folds.

    ``plan``: the campaign's CV fold plan, for the result's ``stratified`` and ``note``
    (computed from the campaign when not given; the fold jobs build the same folds).
    ``store``, ``tally``: the result store and the count of where results came from
    (:func:`parknss.executor.run_jobs`).
    """
    variants = list(variants or MODEL_VARIANTS)
    for v in variants:
        if v not in MODEL_VARIANTS:
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
        store=store,
        tally=tally,
    )
    folds: dict[str, list[dict]] = {v: [] for v in variants}
    for (var, _), res in zip(pairs, results, strict=True):
        folds[var].append(res)
    if plan is None:
        plan = cv_plan(load_campaign(data))
    return CVResult(folds, overrides, time.perf_counter() - t0, plan.stratified, plan.note)


@dataclass(frozen=True, kw_only=True)
class CVInputs:
    """``parknss cv``: campaign folder ``data`` (None: default), NSS YAML ``config`` (None:
    shipped), NSS ``overrides``, the model ``variants``, the executor settings, the run
    folder ``out`` (cv.json, table2.txt, figures; fold cache in out/cache, models in
    out/models) and whether an ``out`` holding something else may be replaced
    (``overwrite``)."""

    out: Path
    data: Path | None = None
    config: Path | None = None
    overrides: dict = field(default_factory=dict)
    variants: tuple[str, ...] = tuple(MODEL_VARIANTS)
    executor: str = "local"
    workers: int | None = None
    address: str | None = None
    overwrite: bool = False

    def identity(self) -> dict:
        """What decides the results (the run folder's manifest): not the executor."""
        config = str(self.config) if self.config else None
        return {"data": self.data, "config": self.config, "overrides": self.overrides,
                "variants": list(self.variants),
                "nss_config": fold_config(config, self.overrides).digest()}


def cv_figures(res: CVResult, campaign, out: Path) -> list[str]:
    """Fig. 4 and Fig. 5 from the NSS fold 0 (if its model was saved)."""
    figs = []
    f0 = (res.folds.get("nss") or [None])[0]
    if not f0:
        return figs
    h = f0.get("history") or {}
    if h.get("epochs"):
        figs.append(str(draw_history(h["epochs"], h["raw"], h["smooth"],
                                     out / "fig4_convergence.png", output=h.get("output"),
                                     best_epoch=f0.get("best_epoch"))))
    if f0.get("model_dir"):
        model = load_model(f0["model_dir"]).model
        trials = pick_maneuvers([campaign[i] for i in f0["val"]])
        pred = predict_trials(model, trials)
        figs.append(str(draw_rollouts(trials, pred, out / "fig5_rollouts.png",
                                      f0.get("window_length"))))
    return figs


def _quiet(msg: str) -> None:
    pass


def table2(inputs: CVInputs, log: Callable[[str], None] = _quiet) -> tuple[CVResult, dict]:
    """Table II as ``parknss cv`` runs it: the campaign checked for the NSS channels
    before any job starts, the CV of every variant, Figs. 4 and 5, cv.json and table2.txt
    in the run folder ``out`` (:func:`parknss.outputs.run_folder`: the same arguments
    resume it from its fold cache); (result, its JSON document with the figure paths)."""
    campaign = load_campaign(inputs.data, "nss", "parknss cv")
    plan = cv_plan(campaign)  # stratified, or plain k-fold (says why in plan.note)
    log(plan.note)
    out = inputs.out
    with run_folder(out, command="parknss cv", args=inputs.identity(),
                    overwrite=inputs.overwrite) as run:
        res = run_cv(
            data=str(inputs.data) if inputs.data else None,
            config=str(inputs.config) if inputs.config else None,
            overrides=inputs.overrides,
            variants=list(inputs.variants),
            executor=inputs.executor,
            workers=inputs.workers,
            address=inputs.address,
            cache_dir=out / "cache",
            save_dir=out / "models",
            plan=plan,
        )
        doc = res.to_json()
        doc["figures"] = cv_figures(res, campaign, out)
        run.write_json("cv.json", doc)
        run.write_text("table2.txt", res.table() + "\n")
    log(f"wrote {out / 'cv.json'}, {out / 'table2.txt'} and {len(doc['figures'])} figures")
    return res, doc
