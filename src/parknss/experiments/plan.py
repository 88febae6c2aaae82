"""What each study fits, and what the fits the result store lacks will cost.

Every study builds its fits with one function (``seed_jobs``, ``curve_jobs``,
``ablation_jobs``, ``limiter_jobs``, ``convergence_jobs``, ``tta_jobs``, the verdicts'
per-fold ``floor_jobs`` and Table II's ``cv_jobs``); :func:`study_jobs` collects them
per study, so the plan is the run's own job list, not a recount. A fit several studies
share (the seed-noise fits and the floor, Fig. 4 and the fold-0 Table II and
time-to-accuracy paper fits) is one entry of the store and is counted once in the total.

Cost of a fit, CPU s (one torch thread): from its resolved NSS config and training
trials,

    paper recipe:  epochs x s_epoch(engine) x S / S_ref
    fast recipe:   updates x s_update(engine)
                   + finish_epochs x s_epoch(engine) x S / S_ref
    coarse recipe: coarse.epochs x s_epoch(engine) x S_m / S_ref
                   + finish_epochs x s_epoch(engine) x S / S_ref

with S the samples of one paper epoch (the training trials tiled into the fit's windows,
padding included: ``sum ceil(n_i / L) x L``) and S_ref those of the fit the rates were
timed on (CV fold 0), S_m those of the coarse phase's epoch (the trials decimated by
``coarse.factor``: a coarse step costs what a full-rate step costs, and there are 1/m as
many); ``s_epoch(engine)`` per (integrator, engine) pair the plan holds
(fused Euler, eager Euler, midpoint, RK4), timed by paper-size fits of 1 and n epochs
after a warm-up (the difference removes loading and the first validation: process CPU
time, since the wall clock of a shared machine measures the neighbours), and
``s_update(engine)`` per engine class the plan's fast-recipe fits use, by fast fits of 1
and 1 + k phase-1 updates. The two are timed apart because they scale apart: a phase-1
update is a minibatch of short windows, where an eager engine's per-op overhead weighs
more than in a full-batch epoch (measured on the AMD core: a midpoint fast fit costs
~4.8x a fused Euler one, its paper epoch ~2.5x). A fused rate given (``--sec-per-epoch``,
``--sec-per-update``, e.g. the means of the stored fits, validation included) replaces the
timed one, and every other engine class keeps its timed ratio to it: a given rate costs a
midpoint or RK4 fit at the midpoint or RK4 price, not at the fused Euler one. Capacity
variants are costed at the deployed net's rate (an upper bound for the smaller nets); the
linear baseline is a least-squares fit of a few seconds and counted as free.

A fit that the store lacks but holds a parked state of (:mod:`parknss.experiments.parked`:
``<store>/inflight/<store key>/``, at step s) costs what its remaining steps cost: a
paper-recipe fit's epochs after s; a fast-recipe fit's steps are its updates and then its
finish epochs, so a state at step s has done ``min(s, updates)`` updates and
``clip(s - updates, 0, finish_epochs)`` finish epochs (a coarse fit likewise, its coarse
epochs in the place of the updates). A state in a run folder that was
not parked is not credited (run folders are scratch).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

from parknss.errors import ConfigError
from parknss.executor import Job, Store
from parknss.experiments.config import ExperimentsConfig
from parknss.experiments.sweep import Sweep

PLANNED: tuple[str, ...] = (
    "table2",
    "time_to_accuracy",
    "convergence",
    "seed-noise",
    "floor",
    "learning-curve",
    "limiter",
    "ablations",
)
"""The studies :func:`study_jobs` knows, in report order (Table II first: it is the fit
the others share most)."""

FUSED: tuple[str, str] = ("euler", "fused")


def study_jobs(name: str, cfg: ExperimentsConfig, quick: bool, sweep: Sweep) -> list[Job]:
    """The fit jobs of study ``name`` (one of :data:`PLANNED`) at the budget."""
    if name == "table2":
        from parknss.experiments.cv import MODEL_VARIANTS, cv_jobs

        ov = cfg.budget(quick).deployment_overrides()
        return [j for _, j in cv_jobs(sweep.data, None, ov, list(MODEL_VARIANTS))]
    if name == "time_to_accuracy":
        from parknss.experiments.time_to_accuracy import tta_jobs

        return tta_jobs(cfg, quick, sweep)
    if name == "convergence":
        from parknss.experiments.convergence import convergence_jobs

        return convergence_jobs(cfg, quick, sweep)
    if name == "seed-noise":
        from parknss.experiments.noise import seed_jobs

        return seed_jobs(cfg, cfg.budget(quick), sweep)
    if name == "floor":  # the per-fold floor of the verdicts, the seed-noise fold aside
        from parknss.experiments.judge import floor_jobs

        ref = cfg.seed_noise_split
        return [j for k, _, j in floor_jobs(cfg, quick, sweep)
                if not (ref.split == "cv" and k == ref.index)]
    if name == "learning-curve":
        from parknss.experiments.learning_curve import curve_jobs

        return [j for _, j in curve_jobs(cfg, quick, sweep)]
    if name == "limiter":
        from parknss.experiments.limiter_study import limiter_jobs

        return limiter_jobs(cfg, quick, sweep)
    if name == "ablations":
        from parknss.experiments.ablations import ablation_jobs

        return ablation_jobs(cfg, quick, sweep)
    raise ValueError(f"no plan for study {name!r}; one of {', '.join(PLANNED)}")


def plan_rows(
    cfg: ExperimentsConfig, quick: bool, sweep: Sweep, studies: tuple[str, ...] = PLANNED
) -> dict[str, list[Job]]:
    """The jobs of each study, Table III split into one row per axis (``ablations: loss``
    ...; the deployed baseline is in every axis's row, as the axis compares against it)."""
    rows: dict[str, list[Job]] = {}
    for name in studies:
        if name != "ablations":
            rows[name] = study_jobs(name, cfg, quick, sweep)
            continue
        from parknss.experiments.ablations import ablation_plan

        for axis, *_, job in ablation_plan(cfg, quick, sweep):
            rows.setdefault(f"ablations: {axis.name}", []).append(job)
    return rows


@dataclass(frozen=True)
class FitShape:
    """What a fit's cost depends on: model, recipe, engine class, step counts (``updates``:
    the phase-1 steps of a fast or coarse fit; ``epochs``: the full-rate epochs), samples
    of one paper epoch (S in the module text) and of one coarse epoch (S_m)."""

    model: str
    recipe: str = "paper"
    engine: tuple[str, str] = FUSED
    epochs: int = 0
    updates: int = 0
    samples: int = 0
    coarse_samples: int = 0

    @property
    def phases(self) -> tuple[tuple[str, int], ...]:
        """The recipe's phases in order, (name, steps), named as the fit's history rows
        name them (:mod:`parknss.nss.recipes`): paper epochs, or a fast fit's phase-1
        updates ("short") or a coarse fit's coarse epochs ("coarse"), then the finish
        epochs ("full")."""
        if self.recipe in ("fast", "coarse"):
            return (("short" if self.recipe == "fast" else "coarse", self.updates),
                    ("full", self.epochs))
        return (("paper", self.epochs),)


def fit_shape(job: Job, campaign) -> FitShape:
    """The :class:`FitShape` of a fold job (its config resolved, its fold's trials tiled)."""
    from parknss.data.windows import tile, window_length
    from parknss.experiments.folds import fold_config, make_fold

    kw = job.kwargs
    model = kw.get("model", "nss")
    if model != "nss":
        return FitShape(model)
    cfg = fold_config(kw.get("config"), kw.get("overrides"))
    fold = make_fold(campaign, kw.get("split", "cv"), kw.get("index", 0), kw.get("r", 1),
                     kw.get("split_seed"))
    lengths = [campaign[i].n for i in fold.train]
    L = window_length(lengths, cfg.data.window)
    samples = sum(len(tile(n, L)) * L for n in lengths)
    integrator = cfg.model.integrator
    engine = cfg.model.engine if cfg.model.engine != "auto" else (
        "fused" if integrator == "euler" else "eager")
    if cfg.train.recipe == "fast":
        return FitShape(model, "fast", (integrator, engine), cfg.fast.finish_epochs,
                        cfg.fast.updates, samples)
    if cfg.train.recipe == "coarse":
        from parknss.data.decimate import grid_length

        m = cfg.coarse.factor
        Lm = grid_length(L, m)
        coarse = sum(len(tile(grid_length(n, m), Lm)) * Lm for n in lengths)
        return FitShape(model, "coarse", (integrator, engine), cfg.coarse.finish_epochs,
                        cfg.coarse.epochs, samples, coarse)
    return FitShape(model, "paper", (integrator, engine), cfg.train.epochs, 0, samples)


@dataclass
class Rates:
    """CPU s per paper epoch (at ``ref_samples`` samples per epoch) and per fast-recipe
    phase-1 update of each engine class; ``timed``: some measured here (False: all given
    on the command line)."""

    epoch: dict[tuple[str, str], float]
    update: dict[tuple[str, str], float]
    ref_samples: int
    timed: bool = True

    def epoch_rate(self, engine: tuple[str, str]) -> float:
        """s/epoch of an engine class; one not timed is counted at the fused rate."""
        return self.epoch.get(engine, self.epoch[FUSED])

    def update_rate(self, engine: tuple[str, str]) -> float:
        """s/update of an engine class; one not timed is counted at the fused update rate
        times the class's epoch ratio to fused Euler."""
        if engine in self.update:
            return self.update[engine]
        return self.update[FUSED] * self.epoch_rate(engine) / self.epoch[FUSED]

    def cost(self, shape: FitShape, step: int | None = None) -> float:
        """CPU s of a fit of this shape, or of its first ``step`` steps (module text)."""
        if shape.model != "nss":
            return 0.0
        scale = shape.samples / self.ref_samples if self.ref_samples else 1.0
        epoch = self.epoch_rate(shape.engine) * scale  # s per full-rate epoch of this fit
        updates, epochs = shape.updates, shape.epochs
        if step is not None:
            updates = min(max(step, 0), shape.updates)
            epochs = min(max(step - shape.updates, 0), shape.epochs)
        if shape.recipe == "coarse":  # a coarse epoch: the full one scaled by its samples
            per = epoch * shape.coarse_samples / shape.samples if shape.samples else 0.0
        else:
            per = self.update_rate(shape.engine)
        return updates * per + epochs * epoch


def paper_fit(integrator: str, engine: str, epochs: int) -> dict:
    """The overrides of a paper-recipe timing fit on one engine class."""
    return {"model": {"integrator": integrator, "engine": engine},
            "train": {"recipe": "paper", "epochs": epochs}}


def fast_fit(integrator: str, engine: str, updates: int) -> dict:
    """The overrides of a fast-recipe timing fit of ``updates`` phase-1 updates and one
    finish epoch on one engine class."""
    return {"model": {"integrator": integrator, "engine": engine},
            "train": {"recipe": "fast"}, "fast": {"updates": updates, "finish_epochs": 1}}


TIMING_RETRIES = 3
"""Times a class is timed again when its longer fit did not cost more CPU than its
one-step fit (the machine's noise exceeded the timed steps); each fit's CPU time is then
the minimum over the tries, the usual estimate of a deterministic job's cost under noise."""


def time_rates(
    data: str | None, overrides: dict, engines: set[tuple[str, str]], campaign,
    log: Callable[[str], None], sec_per_epoch: float | None = None,
    sec_per_update: float | None = None, fast_engines: set[tuple[str, str]] | None = None,
) -> Rates:
    """Time the rates the plan needs (module text) on CV fold 0 with the budget's
    ``overrides``: the epoch rate of fused Euler and of each class in ``engines``, the
    update rate of fused Euler and of each class in ``fast_engines`` (the engines of the
    plan's fast-recipe fits). A rate given is the fused Euler one and is not timed unless
    another class needs its ratio to it; each other class costs the given rate times its
    timed ratio to fused Euler."""
    from parknss.experiments.config import merge_overrides
    from parknss.experiments.folds import fold_job
    from parknss.experiments.jobs import FOLD_JOB

    warm: list[bool] = []

    def cpu_of(ov: dict) -> float:
        if not warm:  # imports, scripting
            warm.append(True)
            fold_job("cv", 0, data=data, overrides=merge_overrides(overrides, ov))
        cpu0 = time.process_time()
        fold_job("cv", 0, data=data, overrides=merge_overrides(overrides, ov))
        return time.process_time() - cpu0

    def timed(classes: set[tuple[str, str]], given: float | None, what: str,
              fit: Callable[[str, str, int], dict], n_fused: int, n_other: int,
              ) -> dict[tuple[str, str], float]:
        rate: dict[tuple[str, str], float] = {}
        if given is None or classes - {FUSED}:
            for integ, eng in sorted({FUSED, *classes}):
                n = n_fused if (integ, eng) == FUSED else n_other
                log(f"timing {what} of 1 and {n} ({integ}, {eng}) ...")
                one = cpu_of(fit(integ, eng, 1))
                many = cpu_of(fit(integ, eng, n))
                for _ in range(TIMING_RETRIES):  # noise: each time's minimum over tries
                    if many > one:
                        break
                    log(f"timing {what} ({integ}, {eng}) again: noise exceeded the steps")
                    one = min(one, cpu_of(fit(integ, eng, 1)))
                    many = min(many, cpu_of(fit(integ, eng, n)))
                rate[(integ, eng)] = (many - one) / (n - 1)
        if given is None:
            return rate
        fused = rate.get(FUSED)  # None: nothing timed (fused Euler only)
        if fused is not None and not fused > 0.0:
            raise ConfigError(f"timing gave a non-positive fused rate ({fused}): the "
                              "machine's noise exceeds the timed steps")
        return {e: given * (rate[e] / fused if fused else 1.0) for e in {FUSED, *classes}}

    ref = fit_shape(Job(FOLD_JOB, {"data": data, "overrides": overrides}), campaign).samples
    epoch = timed(engines, sec_per_epoch, "paper-size fits, epochs", paper_fit, 6, 3)
    update = timed(set(fast_engines or ()), sec_per_update,
                   "fast-recipe fits, phase-1 updates", fast_fit, 21, 11)
    bad = {f"{'/'.join(k)} {kind}": v for kind, rates in (("epoch", epoch), ("update", update))
           for k, v in rates.items() if not v > 0.0}
    if bad:
        raise ConfigError(f"timing gave non-positive rates ({bad}): the machine's noise "
                          "exceeds the timed steps; pass --sec-per-epoch and --sec-per-update")
    return Rates(epoch, update, ref, bool(warm))


@dataclass
class StudyCost:
    """One study at the budget: its fits, those the store holds, the CPU hours of the
    rest (one core per fit) and their recipes."""

    study: str
    fits: int
    stored: int
    cpu_h: float
    recipes: dict[str, int] = field(default_factory=dict)
    parked: int = 0

    def to_json(self) -> dict:
        return {"study": self.study, "fits": self.fits, "stored": self.stored,
                "parked": self.parked, "cpu_h_left": self.cpu_h, "recipes": self.recipes}


@dataclass
class Estimate:
    """The per-study costs, the rates and the distinct fits of the whole plan."""

    studies: list[StudyCost]
    total: StudyCost
    rates: Rates

    def to_json(self) -> dict:
        return {
            "sec_per_epoch": {"/".join(k): v for k, v in self.rates.epoch.items()},
            "sec_per_update": {"/".join(k): v for k, v in self.rates.update.items()},
            "ref_samples": self.rates.ref_samples,
            "studies": [s.to_json() for s in self.studies],
            "total": self.total.to_json(),
        }

    def text(self) -> str:
        """The table ``parknss study estimate`` prints."""
        epochs = ", ".join(f"{'/'.join(k)} {v:.2f}" for k, v in sorted(self.rates.epoch.items()))
        updates = ", ".join(f"{'/'.join(k)} {v:.3f}"
                            for k, v in sorted(self.rates.update.items()))
        lines = [
            f"CPU s per paper epoch: {epochs}; per fast update: {updates or '-'}"
            + ("" if self.rates.timed else " (given)"),
            f"{'study':<28}{'fits':>6}{'stored':>8}{'parked':>8}{'CPU h left':>12}   recipes",
        ]
        for s in [*self.studies, self.total]:
            mix = ", ".join(f"{k} {v}" for k, v in sorted(s.recipes.items()))
            lines.append(f"{s.study:<28}{s.fits:>6}{s.stored:>8}{s.parked:>8}"
                         f"{s.cpu_h:>12.1f}   {mix}")
        return "\n".join(lines)


def estimate(
    cfg: ExperimentsConfig, quick: bool, sweep: Sweep, store: Store | None,
    log: Callable[[str], None], sec_per_epoch: float | None = None,
    sec_per_update: float | None = None, studies: tuple[str, ...] = PLANNED,
) -> Estimate:
    """Every study's fits at the budget, the store's share and the cost of the rest (net
    of the parked states' progress, module text)."""
    campaign = sweep.campaign()
    shapes: dict[str, FitShape] = {}
    held: dict[str, bool] = {}
    step: dict[str, int] = {}  # the step of each fit's parked state (0: none)
    rows: dict[str, list[str]] = {}  # the distinct fits of each row, by fit key
    planned = plan_rows(cfg, quick, sweep, studies)
    ids = {_identity(job) for jobs in planned.values() for job in jobs}
    for name, jobs in planned.items():
        keys = rows[name] = []
        for job in jobs:
            key = _identity(job, ids)
            if key not in keys:
                keys.append(key)
            if key not in shapes:
                shapes[key] = fit_shape(job, campaign)
                held[key] = store is not None and store.get(job)[0]
                step[key] = 0 if held[key] else parked_step(store, job)
    left = [s for k, s in shapes.items() if s.model == "nss" and not held[k]]
    rates = time_rates(sweep.data, cfg.budget(quick).overrides, {s.engine for s in left},
                       campaign, log, sec_per_epoch, sec_per_update,
                       {s.engine for s in left if s.recipe == "fast"})

    def cost(name: str, keys: list[str]) -> StudyCost:
        recipes: dict[str, int] = {}
        for k in keys:
            tag = shapes[k].recipe if shapes[k].model == "nss" else shapes[k].model
            recipes[tag] = recipes.get(tag, 0) + 1
        left = sum(rates.cost(shapes[k]) - rates.cost(shapes[k], step[k])
                   for k in keys if not held[k])
        return StudyCost(name, len(keys), sum(held[k] for k in keys), left / 3600.0, recipes,
                         sum(step[k] > 0 for k in keys))

    per = [cost(name, keys) for name, keys in rows.items()]
    return Estimate(per, cost("total (distinct)", list(shapes)), rates)


def parked_step(store: Store | None, job: Job) -> int:
    """The step of the state parked for ``job`` in the result ``store``
    (:meth:`~parknss.experiments.store.ResultStore.parked_step`: its own state or that of
    the job that answers it); 0 with no parked state or a store that does not park."""
    from parknss.experiments.store import ResultStore

    return store.parked_step(job) if isinstance(store, ResultStore) else 0


def _identity(job: Job, planned: set[str] | None = None) -> str:
    """The fit a job makes (:func:`~parknss.experiments.store.fit_key`): shared fits meet,
    and a job that a ``planned`` job answers (:data:`~parknss.experiments.jobs.ALIASES`:
    the limiter fit of a fold is its fold fit) is that job's fit."""
    from parknss.experiments.jobs import ALIASES
    from parknss.experiments.store import fit_key

    own = fit_key(job.fn, job.kwargs)
    if planned and job.fn in ALIASES:
        twin = fit_key(ALIASES[job.fn][0], job.kwargs)
        return twin if twin in planned else own
    return own

