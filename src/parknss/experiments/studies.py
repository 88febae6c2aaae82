"""``parknss study``: the evaluation studies one by one, each with its tables and figure.

:func:`run_study` runs one of :data:`STUDIES` (``quick``: the smoke-test budget of
configs/experiments.yaml) through the executor (``executor`` local or ray, ``workers``,
``address``) with a result cache in ``<out>/cache``, so an interrupted study resumes, and
the result store behind it (:mod:`parknss.experiments.store`: ``store`` a folder or "off",
``refit`` ignores its results; a quick run does not write it); it
writes ``<name>.json`` and the study's figure to ``out`` and returns a :class:`StudyRun`
(the JSON document and the report tables; :func:`study_text` prints them). Studies that
judge effects against the seed-noise floor take it from ``floor``: ``measure`` (run the
seed-noise study, cached in the same folder), ``paper`` (the paper's CVs, labelled as
such) or a seed-noise JSON written by ``parknss study seed-noise``. :func:`estimate`
lists each study's fits, the store's share and the CPU hours of the rest
(:mod:`parknss.experiments.plan`).

``out`` is a run folder of ``parknss study`` (:func:`parknss.outputs.run_folder`) whose
arguments are the budget, the campaign, the configs (their digests too) and the floor,
not the study: the studies share one folder and its cache (``ablations`` and ``limiter``
measure the floor from the seed-noise fits already there), each writing its own files,
and the manifest lists the ``studies`` run in it. A folder of another budget, campaign,
config or floor, or holding anything else, is refused unless ``overwrite``.

Every study refuses, in one line, a campaign that lacks a channel NSS identification needs
(:mod:`parknss.data.workflows`), and says in ``note`` when the campaign is not
stratifiable and its folds are plain k-fold (:mod:`parknss.data.splits`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from parknss.errors import ConfigError

if TYPE_CHECKING:  # the CLI imports STUDIES: keep this module's import light
    from parknss.experiments.results import Table

STUDIES = ("learning-curve", "seed-noise", "ablations", "limiter", "convergence")


def _quiet(msg: str) -> None:
    pass


def checked_campaign(data: Path | None, command: str):
    """The study's campaign, refused (DataError, one line) if it lacks an NSS channel."""
    from parknss.nss.campaigns import load_campaign

    return load_campaign(data, "nss", command)


def fold_note(name: str, campaign, cfg) -> tuple[bool, str]:
    """(stratified, note) of the folds the study ``name`` fits on ``campaign``."""
    if name == "learning-curve":
        from parknss.experiments.learning_curve import grid_note

        return grid_note(campaign, cfg.learning_curve_rs)
    from parknss.data.splits import cv_plan

    plan = cv_plan(campaign)
    return plan.stratified, plan.note


def _floor(spec: str, cfg, quick: bool, sweep, log: Callable[[str], None]):
    from parknss.experiments.noise import NoiseFloor, seed_noise

    if spec == "paper":
        return NoiseFloor.paper(cfg)
    if spec == "measure":
        log("measuring the seed-noise floor (cached in the same folder)")
        return seed_noise(cfg, quick, sweep).floor
    return NoiseFloor.load(spec)


def _judged(make, floor, cfg, quick: bool, sweep) -> list:
    """``make(judge)``'s findings (and their verdicts on the ``beside`` metric): the judge
    reads the per-fold floor fits the store holds (a single study fits none of them) and
    falls back on ``floor``."""
    from parknss.experiments.findings import judged
    from parknss.experiments.judge import Judge, fold_seeds

    seeds = fold_seeds(cfg, quick, sweep, fit=False)
    return judged(Judge(cfg.verdict, seeds, cfg.verdict.metric, floor), make)


@dataclass(frozen=True, kw_only=True)
class StudyInputs:
    """One study: its ``name`` (one of :data:`STUDIES`), the ``quick`` budget, the folder
    ``out`` (and cache), the executor settings, the campaign ``data`` (None: default), the
    experiments YAML ``config`` (None: shipped), the noise ``floor`` spec, whether an
    ``out`` holding something else may be replaced (``overwrite``), the result ``store``
    (a folder or "off"; None: $PARKNSS_RESULTS, else the config's), ``refit`` and, for
    the ablations, the Table III ``axes`` to run (empty: every axis of the config)."""

    name: str
    out: Path
    quick: bool = False
    executor: str = "local"
    workers: int | None = None
    address: str | None = None
    data: Path | None = None
    config: Path | None = None
    floor: str = "measure"
    progress: bool = True
    overwrite: bool = False
    store: str | None = None
    refit: bool = False
    axes: tuple[str, ...] = ()

    def identity(self, cfg) -> dict:
        """What decides the results (the run folder's manifest; not the study, so the
        studies share a folder and its cache), with the digests of the experiments config
        ``cfg`` and of the NSS base config the fold jobs load."""
        from parknss.experiments.folds import fold_config

        floor = Path(self.floor) if self.floor not in ("measure", "paper") else self.floor
        return {"quick": self.quick, "data": self.data, "config": self.config,
                "floor": floor, "experiments_config": cfg.digest(),
                "nss_config": fold_config(None, None).digest(),
                **({"axes": list(self.axes)} if self.axes else {})}


@dataclass
class StudyRun:
    """A finished study: the JSON document written to ``<name>.json`` and its report
    tables."""

    doc: dict
    tables: list[Table]


def run_study(inputs: StudyInputs, log: Callable[[str], None] = _quiet) -> StudyRun:
    """Run one study; write its JSON and figure to ``out`` (see the module doc)."""
    from parknss.executor import Tally
    from parknss.experiments import findings as fnd
    from parknss.experiments import study_tables as st
    from parknss.experiments.config import load_experiments_config
    from parknss.experiments.store import open_store
    from parknss.experiments.sweep import Sweep
    from parknss.outputs import run_folder
    from parknss.report import study_figures as fig

    name, quick, out, data = inputs.name, inputs.quick, inputs.out, inputs.data
    if name not in STUDIES:
        raise ConfigError(f"unknown study {name!r}; one of {', '.join(STUDIES)}")
    cfg = load_experiments_config(inputs.config)
    if inputs.axes:
        if name != "ablations":
            raise ConfigError(f"axes select Table III axes: the ablations study, not {name!r}")
        cfg = cfg.with_axes(inputs.axes)
    stratified, note = fold_note(name, checked_campaign(data, f"parknss study {name}"), cfg)
    if inputs.progress:
        log(note)
    with run_folder(out, command="parknss study", args=inputs.identity(cfg),
                    overwrite=inputs.overwrite) as run:
        tally = Tally()
        sweep = Sweep(inputs.executor, inputs.workers, inputs.address, out / "cache",
                      str(data) if data else None, inputs.progress,
                      open_store(inputs.store, cfg, quick, inputs.refit), tally,
                      state_root=out / "state")  # a killed fit resumes mid-fit
        floor = inputs.floor
        t0 = time.perf_counter()
        if name == "learning-curve":
            from parknss.experiments.learning_curve import learning_curve

            res = learning_curve(cfg, quick, sweep)
            fl = _floor(floor, cfg, quick, sweep, log)
            found = _judged(lambda j: fnd.learning_curve_findings(res, j), fl, cfg, quick, sweep)
            tables = st.learning_curve_tables(res)
            figure = fig.draw_learning_curve(res, out / "learning_curve.png")
        elif name == "seed-noise":
            from parknss.experiments.noise import seed_noise

            res = seed_noise(cfg, quick, sweep)
            tables, found = st.seed_noise_tables(res), _judged(
                lambda j: fnd.seed_noise_findings(res, j), res.floor, cfg, quick, sweep)
            figure = fig.draw_seed_noise(res, out / "seed_noise.png")
        elif name == "ablations":
            from parknss.experiments.ablations import ablations

            res = ablations(cfg, quick, sweep, _floor(floor, cfg, quick, sweep, log))
            tables, found = st.ablation_tables(res), _judged(
                lambda j: fnd.ablation_findings(res, j), res.floor, cfg, quick, sweep)
            figure = fig.draw_ablations(res, out / "table3_effects.png")
        elif name == "limiter":
            from parknss.experiments.limiter_study import limiter_study

            res = limiter_study(cfg, quick, sweep, _floor(floor, cfg, quick, sweep, log))
            tables, found = st.limiter_tables(res), _judged(
                lambda j: fnd.limiter_findings(res, j), res.floor, cfg, quick, sweep)
            figure = fig.draw_limiter(res, out / "limiter.png")
        else:
            from parknss.experiments.convergence import convergence
            from parknss.report.nss_figures import draw_history

            res = convergence(cfg, quick, sweep)
            tables, found = st.convergence_tables(res), []
            figure = draw_history(
                res.epochs,
                res.raw,
                res.smooth,
                out / "fig4_convergence.png",
                res.output,
                res.best_epoch,
            )
        doc = {
            "study": name,
            "quick": quick,
            "executor": inputs.executor,
            "wall_s": round(time.perf_counter() - t0, 2),
            "sources": {"run_cache": tally.cache, "store": tally.store, "fitted": tally.computed},
            "result": res.to_json(),
            "findings": [
                {"claim": f.claim, "measured": f.measured, "verdict": f.verdict,
                 "beside": f.beside} for f in found
            ],
            "figure": str(figure),
            "config": cfg.model_dump(mode="json"),
            "stratified": stratified,
            "note": note,
        }
        log(f"{name}: {tally.total} fits: {tally.cache} from the run cache, {tally.store} "
            f"from the store, {tally.computed} fitted")
        doc["json"] = str(run.write_json(f"{name}.json", doc, default=str))
        run.manifest["studies"] = sorted({*run.manifest.get("studies", []), name})
    return StudyRun(doc, tables)


def study_text(run: StudyRun) -> str:
    """What ``parknss study`` prints: the note (plain k-fold), the tables, the findings."""
    from parknss.experiments.study_tables import text_table

    doc = run.doc
    parts = [doc["note"] + "\n"] if not doc["stratified"] else []
    parts += [text_table(t) + "\n" for t in run.tables]
    parts += [f"[{f['verdict']}] {f['claim']}\n    measured: {f['measured']}"
              + (f"\n    beside: {f['beside']}" if f.get("beside") else "")
              for f in doc["findings"]]
    parts.append(f"wall {doc['wall_s']} s; wrote {doc['json']}, {doc['figure']}")
    return "\n".join(parts)


def estimate(
    quick: bool, config: Path | None, data: Path | None, store: str | None,
    sec_per_epoch: float | None = None, sec_per_update: float | None = None,
    log: Callable[[str], None] = _quiet,
):
    """``parknss study estimate``: every study's fits at the budget, the result store's
    share and the CPU hours of the rest (:func:`parknss.experiments.plan.estimate`)."""
    from parknss.experiments.config import load_experiments_config
    from parknss.experiments.plan import estimate as plan_estimate
    from parknss.experiments.store import open_store
    from parknss.experiments.sweep import Sweep

    cfg = load_experiments_config(config)
    checked_campaign(data, "parknss study estimate")
    sweep = Sweep(data=str(data) if data else None, progress=False)
    return plan_estimate(cfg, quick, sweep, open_store(store, cfg, quick, False, log), log,
                         sec_per_epoch, sec_per_update)


def run_progress_of(out: Path) -> list:
    """:func:`~parknss.experiments.progress.run_progress` of a run folder, at the budget,
    studies config and campaign its manifest (``run.json``) records."""
    from parknss.errors import ConfigError
    from parknss.experiments.config import load_experiments_config
    from parknss.experiments.progress import run_progress
    from parknss.outputs import RUN_MANIFEST, read_manifest

    args = (read_manifest(out) or {}).get("args")
    if not isinstance(args, dict):
        raise ConfigError(f"{Path(out) / RUN_MANIFEST}: not a run folder manifest (missing, "
                          "unreadable or without the run's arguments)")
    cfg = load_experiments_config(args.get("config"))
    data = args.get("data")
    return run_progress(Path(out), cfg, bool(args.get("quick")), str(data) if data else None)
