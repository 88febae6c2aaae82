"""Design ablations (paper §V-C, Table III): one factor varied per axis.

Every option of every axis is fitted on the budget's CV folds at the matched epoch
budget with the paper's configuration elsewhere; the table reports the fold-mean
moving-region vx and ω_z errors, the mean wall clock per fit and, per option, its
relative effect against the axis's deployed option and whether that effect exceeds the
seed-noise floor. Axes marked ``lr_sweep`` (the loss) fit each option at every LR of the
budget and report it at its best LR (by ``loss_lr_metric``, the held-out fold mean);
axes marked ``cost`` (the integrator) also report the wall-clock ratio to the deployed
option. Identical option configurations across axes are one cached job.

A run that may only read stored results (``parknss reproduce --stored-only``) builds the
axes whose fits the store holds and lists the others as :class:`UnmeasuredAxis` (how many
of their fits are missing), so a study run axis by axis across sittings reports what it
has; with no axis measured the study is not measured at all
(:class:`~parknss.errors.MissingResultsError`).

Window rules resolve per fold from its training-trial lengths n_i: ``shortest`` =
min n_i, ``longest`` = max n_i (every trial one padded sequence), ``padding:F`` = the
smallest L whose tiling (:func:`parknss.data.windows.tile`) pads at least a fraction F of
the sequence samples.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace

from parknss.errors import MissingResultsError
from parknss.executor import Job
from parknss.experiments.config import (
    AblationAxis,
    AblationOption,
    Budget,
    ExperimentsConfig,
    Overrides,
    merge_overrides,
)
from parknss.experiments.folds import make_fold
from parknss.experiments.noise import NoiseFloor
from parknss.experiments.sweep import FoldScore, Sweep, fold_spec, nanmean, relative_effect


def padding_fraction(lengths: list[int], L: int) -> float:
    """Fraction of padded samples when trials of ``lengths`` are tiled into windows of L."""
    total = pad = 0
    for n in lengths:
        windows = 1 if n <= L else math.ceil(n / L)
        total += windows * L
        pad += max(0, L - n)
    return pad / total


def resolve_window(rule: str, lengths: list[int]) -> int:
    """The window length (samples) of a rule for training trials of ``lengths``."""
    lo, hi = min(lengths), max(lengths)
    if rule == "shortest":
        return lo
    if rule == "longest":
        return hi
    target = float(rule.partition(":")[2])
    for L in range(lo, hi + 1):
        if padding_fraction(lengths, L) >= target:
            return L
    return hi


@dataclass
class OptionResult:
    """One option: per-fold scores at the chosen LR, and the LR sweep if any."""

    axis: str
    label: str
    deployed: bool
    scores: list[FoldScore]
    windows: list[int] = field(default_factory=list)
    lr: float | None = None
    lr_sweep: dict[float, float] = field(default_factory=dict)  # lr -> fold-mean metric

    def mean(self, channel: str) -> float:
        return nanmean([getattr(s, channel) for s in self.scores])

    def wall_s(self) -> float:
        """Mean wall clock per fit, s."""
        return nanmean([s.wall_s for s in self.scores])

    def wall_per_epoch(self) -> float:
        """Mean wall clock per epoch, s (independent of the epoch cap)."""
        return nanmean([s.wall_per_epoch for s in self.scores])

    def cpu_per_epoch(self) -> float:
        """Mean CPU time per epoch, s; NaN unless every fold's fit has its CPU time."""
        per = [s.cpu_per_epoch for s in self.scores]
        return nanmean(per) if per and all(math.isfinite(c) for c in per) else math.nan

    def per_epoch(self, basis: str) -> float:
        """Mean cost per epoch, s, on ``basis`` "CPU" or "wall"."""
        return self.cpu_per_epoch() if basis == "CPU" else self.wall_per_epoch()


@dataclass
class AxisResult:
    name: str
    options: list[OptionResult]
    cost: bool
    recipe: str = "paper"  # the training recipe of the axis's fits (train.recipe)

    def baseline(self) -> OptionResult:
        return next(o for o in self.options if o.deployed)

    def effect(self, label: str, channel: str) -> float:
        """Relative effect of an option against the deployed one."""
        return relative_effect(self._option(label).mean(channel), self.baseline().mean(channel))

    def best(self, channel: str) -> OptionResult:
        return min(self.options, key=lambda o: (math.isnan(o.mean(channel)), o.mean(channel)))

    def cost_basis(self, label: str, ref: str | None = None) -> str:
        """"CPU" when both options (``ref``: default the deployed one) have every fold's
        CPU time, else "wall": CPU time is the cost measure, as a fit's wall clock grows
        with whatever else shares its core; results without CPU times fall back to wall."""
        pair = [self._option(label), self._option(ref) if ref else self.baseline()]
        return "CPU" if all(math.isfinite(o.cpu_per_epoch()) for o in pair) else "wall"

    def cost_ratio(self, label: str, ref: str | None = None) -> float:
        """Cost per epoch of an option over ``ref``'s (default the deployed option's), on
        :meth:`cost_basis`."""
        basis = self.cost_basis(label, ref)
        base = self._option(ref) if ref else self.baseline()
        return relative_effect(self._option(label).per_epoch(basis), base.per_epoch(basis)) + 1.0

    def _option(self, label: str) -> OptionResult:
        return next(o for o in self.options if o.label == label)


@dataclass
class UnmeasuredAxis:
    """An axis a stored-only run could not build: ``missing`` of its ``total`` fits are
    not in the result store."""

    name: str
    missing: int
    total: int

    def describe(self) -> str:
        return f"not measured: {self.missing} of {self.total} fits are not stored"


@dataclass
class AblationResult:
    axes: list[AxisResult]
    floor: NoiseFloor
    epochs: int
    folds: list[int]
    unmeasured: list[UnmeasuredAxis] = field(default_factory=list)
    recipe: str = "paper"  # the budget's recipe: that of the seed-noise fits of the floor

    def axis(self, name: str) -> AxisResult | None:
        return next((a for a in self.axes if a.name == name), None)

    def unmeasured_axis(self, name: str) -> UnmeasuredAxis | None:
        return next((a for a in self.unmeasured if a.name == name), None)

    def to_json(self) -> dict:
        return {
            "epochs": self.epochs,
            "folds": self.folds,
            "recipe": self.recipe,
            "floor": self.floor.to_json(),
            "unmeasured": [asdict(u) for u in self.unmeasured],
            "axes": [
                {
                    "name": a.name,
                    "recipe": a.recipe,
                    "options": [
                        {
                            **{k: v for k, v in asdict(o).items() if k != "lr_sweep"},
                            "lr_sweep": {str(k): v for k, v in o.lr_sweep.items()},
                        }
                        for o in a.options
                    ],
                }
                for a in self.axes
            ],
        }


def option_overrides(
    opt: AblationOption, budget: Budget, quick: bool, recipe: str | None = None
) -> Overrides:
    """The option's NSS overrides on the budget's study overrides, with ``recipe`` (the
    axis's; None: the budget's)."""
    own = opt.quick_overrides if quick and opt.quick_overrides is not None else opt.overrides
    return merge_overrides(budget.study_overrides(recipe), own)


def _base_lr(ov: Overrides) -> float:
    """The LR a fit with these overrides uses (so the default LR adds no override)."""
    from parknss.nss.config import TrainConfig

    return float(ov.get("train", {}).get("lr", TrainConfig().lr))


def ablation_plan(cfg: ExperimentsConfig, quick: bool, sweep: Sweep):
    """(axis, option, lr, fold, window, job) for every fit of the study."""
    budget = cfg.budget(quick)
    campaign = sweep.campaign()
    lengths = {}
    for k in budget.ablation_folds:
        fold = make_fold(campaign, "cv", k)
        lengths[k] = [campaign[i].n for i in fold.train]
    plan = []
    for axis in cfg.axes:
        lrs: list[float | None] = list(budget.loss_lrs) if axis.lr_sweep else [None]
        for opt in axis.options:
            base = option_overrides(opt, budget, quick, axis.recipe)
            for lr in lrs:
                for k in budget.ablation_folds:
                    ov = merge_overrides(base)
                    win = None
                    if opt.window is not None:
                        win = resolve_window(opt.window, lengths[k])
                        # "shortest" is the default rule: then the job equals the baseline
                        if opt.window != "shortest" or "window" in ov.get("data", {}):
                            ov = merge_overrides(ov, {"data": {"window": win}})
                    if lr is not None and lr != _base_lr(ov):
                        ov = merge_overrides(ov, {"train": {"lr": lr}})
                    at = "" if lr is None else f" LR {lr:g}"
                    job = fold_spec(sweep, "cv", k, ov, name=f"{axis.name}/{opt.label}{at} f{k}")
                    plan.append((axis, opt, lr, k, win, job))
    return plan


def ablation_jobs(cfg: ExperimentsConfig, quick: bool, sweep: Sweep) -> list[Job]:
    """Every fit of the study, shared configurations once (the first spelling kept)."""
    jobs: dict[str, Job] = {}
    for *_, job in ablation_plan(cfg, quick, sweep):
        jobs.setdefault(job.key(), job)
    return list(jobs.values())


def _metric(res: dict, key: str) -> float:
    """The held-out error ``key`` of a fold result, or for ``criterion`` the fit's best
    smoothed selection criterion (on the trials it chose its checkpoint on: the inner
    split under ``train.selection: inner``, so the LR is never chosen on scored trials)."""
    if key == "criterion":
        smooth = [x for x in (res.get("history") or {}).get("smooth") or [] if x is not None]
        return min(smooth) if smooth else math.nan
    v = res["errors"].get(key)
    return math.nan if v is None else float(v)


def _option(axis: AblationAxis, opt: AblationOption, rows, metric: str) -> OptionResult:
    by_lr: dict = {}
    for _, _, lr, _, win, res in rows:
        by_lr.setdefault(lr, []).append((win, res))
    sweep_means = {
        lr: nanmean([_metric(r, metric) for _, r in items]) for lr, items in by_lr.items()
    }
    best_lr = min(sweep_means, key=lambda lr: (math.isnan(sweep_means[lr]), sweep_means[lr]))
    chosen = by_lr[best_lr]
    return OptionResult(
        axis=axis.name,
        label=opt.label,
        deployed=opt.deployed,
        scores=[FoldScore.from_json(r) for _, r in chosen],
        windows=[w for w, _ in chosen if w is not None],
        lr=best_lr,
        lr_sweep={lr: v for lr, v in sweep_means.items() if lr is not None},
    )


def ablations(
    cfg: ExperimentsConfig, quick: bool, sweep: Sweep, floor: NoiseFloor
) -> AblationResult:
    """Run every axis of ``cfg.axes`` (see the module doc)."""
    budget = cfg.budget(quick)
    plan = ablation_plan(cfg, quick, sweep)
    stored_only = sweep.store is not None and not sweep.store.fit_missing
    if stored_only:
        results, unmeasured = _stored_axes(cfg, plan, sweep)
    else:  # one sweep over every fit: the pool keeps all workers busy across axes
        results, unmeasured = sweep.run([p[-1] for p in plan], "ablations"), []
    axes = []
    for axis in cfg.axes:
        if any(u.name == axis.name for u in unmeasured):
            continue
        opts = []
        for opt in axis.options:
            rows = [
                (*p[:-1], res)
                for p, res in zip(plan, results, strict=True)
                if p[0] is axis and p[1] is opt
            ]
            opts.append(_option(axis, opt, rows, cfg.loss_lr_metric))
        axes.append(AxisResult(axis.name, opts, axis.cost, axis.recipe or budget.recipe))
    return AblationResult(axes, floor, budget.epochs, list(budget.ablation_folds), unmeasured,
                          budget.recipe)


def _stored_axes(cfg: ExperimentsConfig, plan, sweep: Sweep):
    """Results of ``plan`` (None for the fits of an axis the store cannot build) and those
    axes; raises when it can build none."""
    probe = replace(sweep, tally=None, progress=False)  # the run's tally counts each fit once
    unmeasured: list[UnmeasuredAxis] = []
    for axis in cfg.axes:
        try:
            probe.run([p[-1] for p in plan if p[0] is axis], f"ablations: {axis.name}")
        except MissingResultsError as exc:
            unmeasured.append(UnmeasuredAxis(axis.name, len(exc.missing), exc.total))
    skip = {u.name for u in unmeasured}
    idx = [i for i, p in enumerate(plan) if p[0].name not in skip]
    # with no axis measured, this raises what the whole study lacks
    got = sweep.run([plan[i][-1] for i in idx] if idx else [p[-1] for p in plan], "ablations")
    results: list = [None] * len(plan)
    for i, r in zip(idx, got, strict=True):
        results[i] = r
    return results, unmeasured
