"""``parknss identify``: from logs (or an imported campaign) to a plant and its model card.

:func:`run_identify` runs the stages of :data:`~.config.STAGES` in order through the stage
book (:mod:`.stages`: a finished stage whose inputs are unchanged is skipped, an
interrupted one resumes, a changed one runs again), each writing into the car folder
CAR (claimed as the run folder of ``parknss identify`` with its source,
:func:`parknss.outputs.run_folder`):

======== ================================================================== ==================
stage    what (library call)                                                product in CAR/
======== ================================================================== ==================
data     import + describe; refuse early unless every workflow is supported data/ (imported)
nss      the deployment fit (:func:`~parknss.experiments.training.           nss/model
         train_deployment`, resumable from nss/state), or a given ``--nss``
         reused after :func:`.reuse.check_nss`
selection the actuator study (:func:`~parknss.experiments.actuator_study.     selection/
         run_actuator_study`) or given winners (``--selection``)
chain    fit, co-tune, Table IV, the artefact (:func:`parknss.chain.build.    chain/
         run_build`, with the monolithic row)
rating   ISO/TS 18571 (:func:`~parknss.experiments.rating.rate_run`) and the  rating/
         open-loop errors of the NSS and the chain (``evaluate``)
tune     the interface gains on the chain (:func:`parknss.sim.tuning.          tune/
         tune_gains`) on the car's own geometry
grid     Table V on the car's grid (:func:`parknss.sim.grid.run_grid_report`) grid/
fidelity the chain against the truth on a small grid, where a truth exists    fidelity/
         (:func:`~parknss.experiments.fidelity.run_fidelity`)
export   the FMU and the ONNX step (:mod:`parknss.export`)                   export/
card     the model card (:mod:`.card`)                                        model_card.*
======== ================================================================== ==================

The actuator study's Phase A needs no NSS: with ``--workers N`` (N >= 2, local executor)
its fits run in N - 1 background processes while the NSS fits (:meth:`Pipeline.
phase_a_ahead`, ``phase_a_ahead`` in configs/identify.yaml), into the cache
``phase_a/<data hash>/`` that the selection stage reads, fit by fit (which also resumes
an interrupted study's Phase A). The fits seed themselves from their names, so the
selection is the same whichever process fitted them.
"""

from __future__ import annotations

import contextlib
import hashlib
import shutil
from collections.abc import Callable
from pathlib import Path

import yaml

from parknss.config import shipped_config
from parknss.errors import ConfigError
from parknss.experiments.identify.config import (
    RECIPES,
    STAGES,
    IdentifyConfig,
    IdentifyInputs,
    load_identify_config,
)
from parknss.experiments.identify.stages import StageBook, StageOutcome, StageRecord
from parknss.outputs import interrupt_note, keep_on_interrupt, run_folder, write_text_atomic

Say = Callable[[str], None]


def _quiet(msg: str) -> None:
    pass


def _identity_of(recorded: object) -> dict | None:
    """:func:`~parknss.nss.config.fit_identity` of a config recorded as JSON by an older
    stage record (which kept every field), or None when it no longer validates."""
    from parknss.nss.config import NSSConfig, fit_identity

    try:
        return fit_identity(NSSConfig.model_validate(recorded))
    except ValueError:
        return None


def manifest_digest(folder: Path) -> str:
    """SHA-256 of an artefact's SHA256SUMS (its content, as the loader verifies it)."""
    return hashlib.sha256((Path(folder) / "SHA256SUMS").read_bytes()).hexdigest()[:16]


def _resume_line(inputs: IdentifyInputs) -> str:
    src = (f"{inputs.logs} --mapping {inputs.mapping}" if inputs.logs is not None
           else f"--data {inputs.data}")
    return f"parknss identify {src} --out {inputs.out} (and the same options)"


class Pipeline:
    """One identify run: its inputs, config, stage book and the records so far."""

    def __init__(self, inputs: IdentifyInputs, cfg: IdentifyConfig, say: Say) -> None:
        self.inp, self.cfg, self.say = inputs, cfg, say
        # absolute, so that the stage records name the same files from any working folder
        self.car = Path(inputs.out).resolve()
        self.recipe = inputs.recipe or cfg.recipe
        if self.recipe not in RECIPES:
            raise ConfigError(f"--recipe {self.recipe!r}: one of {', '.join(RECIPES)}")
        self.rec: dict[str, StageRecord] = {}
        self.book = StageBook(self.car, say, {}, STAGES)
        self.campaign = None
        self.truth: tuple[Path | None, str] | None = None

    # ------------------------------------------------------------------ helpers
    def nss_overrides(self) -> dict:
        """The NSS config overrides of this run: ``--set``, the recipe, and the fused
        kernels of the config's ``kernels`` unless ``--set model.fused_kernels`` names them."""
        over = {k: dict(v) for k, v in self.inp.nss_overrides.items()}
        over.setdefault("train", {})["recipe"] = self.recipe
        over.setdefault("model", {}).setdefault("fused_kernels", self.cfg.kernels)
        return over

    def nss_config(self):
        from parknss.experiments.folds import fold_config

        return fold_config(None, self.nss_overrides())

    def estimates(self, wanted: tuple[str, ...]) -> dict[str, float]:
        e = self.cfg.estimate_s
        cfg = self.nss_config()
        nss = {"paper": e.nss_paper_epoch * cfg.train.epochs, "fast": e.nss_fast,
               "coarse": e.nss_coarse}[self.recipe]
        if self.inp.nss is not None:
            nss = 5.0
        table = {s: getattr(e, s, 0.0) for s in STAGES if s != "nss"}
        table["nss"] = nss
        if self.inp.selection is not None:
            table["selection"] = 1.0
        if self.inp.interface is not None:
            table["tune"] = 1.0
        return {s: (table[s] if s in wanted else 0.0) for s in STAGES}

    def campaign_dir(self) -> Path:
        return Path(self.rec["data"].product["campaign"])

    def model_dir(self) -> Path:
        return Path(self.rec["nss"].product["model"])

    def chain_dir(self) -> Path:
        return Path(self.rec["chain"].product["chain"])

    def sim_files(self, interface: str | None = None):
        """The closed-loop config of this car (its chain, its truth vehicle) as files."""
        from parknss.config import read_yaml_mapping
        from parknss.sim.closed_loop import SimConfigFiles

        doc = read_yaml_mapping(shipped_config("closed_loop.yaml"))
        doc["chain_path"] = str(self.chain_dir().resolve())
        veh = self.truth[0] if self.truth else None
        doc["reference_vehicle"] = str(Path(veh).resolve()) if veh is not None else None
        path = self.car / "configs" / "closed_loop.yaml"
        text = "# parknss identify: closed loop of this car (shipped values, its chain)\n"
        write_text_atomic(path, text + yaml.safe_dump(doc, sort_keys=False))
        return SimConfigFiles(closed_loop=str(path), interface=interface)

    def phase_a_cache(self) -> Path:
        """The Phase A fits of this campaign (one folder per data hash: the executor's
        cache keys name the campaign folder, not its content)."""
        return self.car / "phase_a" / self.rec["data"].product["facts"]["data_hash"][:16]

    def phase_a_ahead(self):
        """While the NSS fits: the actuator study's Phase A (which needs no NSS) fitted in
        the background processes the NSS fit leaves free (``workers`` less the fit's
        ``train.processes``) into :meth:`phase_a_cache`, when this run will run the study
        itself with a local pool of 2 or more workers and at least one is free
        (``phase_a_ahead`` in configs/identify.yaml); else nothing."""
        inp = self.inp
        free = inp.workers - self.nss_config().train.processes
        if not (self.cfg.phase_a_ahead and inp.selection is None and inp.executor == "local"
                and inp.workers >= 2 and free >= 1 and "selection" in wanted_stages(inp)):
            return contextlib.nullcontext()
        from parknss.actuators.config import load_actuator_config
        from parknss.chain.selection import phase_a_plan
        from parknss.executor import Prefetch

        plan = phase_a_plan(self.campaign, str(self.campaign_dir()),
                            load_actuator_config(inp.actuator_config))
        self.say(f"  [actuators] Phase A ahead: {len(plan.jobs)} fits in {free} "
                 "background process(es) beside the NSS fit")
        return _Ahead(Prefetch(plan.jobs, self.phase_a_cache(), free), self.say)

    def plants(self) -> list[str]:
        return ["kinematic", "chain", *(["reference"] if self.truth else [])]

    # ------------------------------------------------------------------ stages
    def stage_data(self) -> StageRecord:
        from parknss.data.io import import_folder, read_campaign, write_campaign
        from parknss.experiments.identify.data_stage import (
            campaign_facts,
            logs_digest,
            refuse_early,
        )
        from parknss.experiments.identify.reuse import truth_vehicle

        inp = self.inp
        if inp.logs is not None:
            inputs = {"logs": logs_digest(inp.logs, inp.mapping)}
        else:
            given = read_campaign(inp.data)
            refuse_early(given, f"parknss identify --data {inp.data}")  # before any work
            inputs = {"data": given.data_hash()}
        target = self.car / "data" if inp.logs is not None else Path(inp.data).resolve()

        def body(fresh: bool) -> StageOutcome:
            if inp.logs is not None:
                campaign = import_folder(inp.logs, mapping=inp.mapping)
                refuse_early(campaign, f"parknss identify {inp.logs}")
                write_campaign(campaign, target, overwrite=True)
            campaign = read_campaign(target)
            refuse_early(campaign, f"parknss identify --data {target}")
            from parknss.data.describe import describe_campaign

            summary = describe_campaign(campaign)
            write_text_atomic(self.car / "describe.json",
                              _json({**summary.to_json()}))
            facts = campaign_facts(campaign)
            truth = truth_vehicle(campaign.meta)
            facts["truth"] = None if truth is None else {
                "vehicle_yaml": None if truth[0] is None else str(truth[0]), "note": truth[1]}
            facts["yaw_r2"], facts["steer_ratio_fit"] = summary.yaw_r2, summary.steer_ratio_fit
            return StageOutcome({"campaign": str(target), "facts": facts})

        rec = self.book.run("data", inputs, body)
        from parknss.data.io import read_campaign as _read

        self.campaign = _read(rec.product["campaign"])
        t = rec.product["facts"].get("truth")
        self.truth = None if t is None else (
            None if t["vehicle_yaml"] is None else Path(t["vehicle_yaml"]), t["note"])
        return rec

    def stage_nss(self) -> StageRecord:
        from parknss.experiments.identify.reuse import check_nss
        from parknss.experiments.lineage import accepted_versions
        from parknss.experiments.store import code_version, store_dir
        from parknss.experiments.training import TrainInputs, train_deployment
        from parknss.nss import train_state
        from parknss.nss.config import fit_identity

        cfg = self.nss_config()
        wanted = cfg.model_dump(mode="json")
        data_hash = self.rec["data"].product["facts"]["data_hash"]
        given = None if self.inp.nss is None else str(Path(self.inp.nss).resolve())
        # the fields that decide the fit's numbers (a new option at its default, which
        # keeps the old behaviour, is not a change), and the training-code version
        inputs = {"data_hash": data_hash, "config": fit_identity(cfg),
                  "code_version": code_version(),
                  "nss": None if given is None else {"path": given,
                                                     "sha": manifest_digest(given)},
                  "allow_code_change": self.inp.allow_code_change}
        out = self.car / "nss"

        def body(fresh: bool) -> StageOutcome:
            if given is not None:
                check = check_nss(Path(given), data_hash, wanted,
                                  allow_code_change=self.inp.allow_code_change,
                                  store_root=store_dir(None))
                return StageOutcome({"model": check.path, "code": check.code,
                                     "fitted_code_version": check.fitted_code_version,
                                     "recipe": self.recipe, "config": wanted},
                                    reused=check.reason)
            resume = not fresh and train_state.exists(out / "state")
            with self.phase_a_ahead():
                doc, text = train_deployment(TrainInputs(
                    out=out, data=self.campaign_dir(), overrides=self.nss_overrides(),
                    resume=resume, overwrite=True))
            self.say(text)
            return StageOutcome({"model": doc["model"], "code": "current",
                                 "fitted_code_version": code_version(),
                                 "recipe": self.recipe, "config": wanted,
                                 "training": {k: v for k, v in doc.items()
                                              if k not in ("train_trials", "val_trials")}})

        root = store_dir(None)
        return self.book.run("nss", inputs, body, equivalent={
            "code_version": lambda rec, now: (root is not None
                                              and rec in accepted_versions(root, now)),
            "config": lambda rec, now: _identity_of(rec) == now})

    def stage_selection(self) -> StageRecord:
        from parknss.actuators.phase_a import Fanout
        from parknss.experiments.actuator_study import StudyInputs, run_actuator_study
        from parknss.experiments.identify.reuse import selection_winners

        given = self.inp.selection
        out = self.car / "selection"
        inputs = {"nss": manifest_digest(self.model_dir()),
                  "data_hash": self.rec["data"].product["facts"]["data_hash"],
                  "actuator_config": _file_sha(self.inp.actuator_config),
                  "given": None if given is None else selection_winners(given)[0]}

        def body(fresh: bool) -> StageOutcome:
            if given is not None:
                winners, src = selection_winners(given)
                if out.exists():
                    shutil.rmtree(out)
                path = write_text_atomic(out / "selection.json",
                                         _json({"winners": winners, "from": str(given)}))
                return StageOutcome({"selection": str(path), "winners": winners},
                                    reused=f"winners taken from {src}: "
                                           + ", ".join(f"{k} {v}" for k, v in winners.items()))
            doc = run_actuator_study(StudyInputs(
                out=out, nss=self.model_dir(), data=self.campaign_dir(),
                config=self.inp.actuator_config, overwrite=fresh,
                fanout=Fanout(self.inp.executor, self.inp.workers, self.inp.address,
                              cache_dir=str(self.phase_a_cache()))),
                lambda m: self.say(f"  [actuators] {m}"))
            return StageOutcome({"selection": str(out / "selection.json"),
                                 "winners": doc["winners"],
                                 "phase_b_reference": doc["phase_b"]["reference"]})

        return self.book.run("selection", inputs, body)

    def stage_chain(self) -> StageRecord:
        from parknss.chain.build import BuildInputs, run_build

        sel = self.rec["selection"].product
        inputs = {"nss": manifest_digest(self.model_dir()), "winners": sel["winners"],
                  "data_hash": self.rec["data"].product["facts"]["data_hash"],
                  "actuator_config": _file_sha(self.inp.actuator_config)}
        out = self.car / "chain"

        def body(fresh: bool) -> StageOutcome:
            doc = run_build(BuildInputs(nss=self.model_dir(), data=self.campaign_dir(),
                                        config=self.inp.actuator_config,
                                        selection=Path(sel["selection"]), out=out,
                                        monolithic=True, overwrite=True, command="build"),
                            lambda m: self.say(f"  [actuators] {m}"))
            return StageOutcome({"chain": str(out), "rows": doc["rows"],
                                 "winners": sel["winners"], "envelope": doc.get("envelope")})

        return self.book.run("chain", inputs, body)

    def stage_rating(self) -> StageRecord:
        from parknss.chain.rating import RateInputs
        from parknss.experiments.evaluate import EvaluateInputs, evaluate_open_loop
        from parknss.experiments.rating import rate_run

        inputs = {"chain": manifest_digest(self.chain_dir()),
                  "nss": manifest_digest(self.model_dir()),
                  "data_hash": self.rec["data"].product["facts"]["data_hash"]}
        out = self.car / "rating"

        def body(fresh: bool) -> StageOutcome:
            run = rate_run(RateInputs(data=self.campaign_dir(), chain=self.chain_dir()),
                           out / "iso", overwrite=fresh)
            nss_doc, _ = evaluate_open_loop(EvaluateInputs(
                out=out / "nss_open_loop", model=self.model_dir(), data=self.campaign_dir(),
                overwrite=fresh))
            chain_doc, _ = evaluate_open_loop(EvaluateInputs(
                out=out / "chain_open_loop", chain=self.chain_dir(), data=self.campaign_dir(),
                overwrite=fresh))
            return StageOutcome({"iso": run.doc["summary"], "nss_open_loop": nss_doc,
                                 "chain_open_loop": chain_doc,
                                 "iso_json": run.doc["files"]["json"]})

        return self.book.run("rating", inputs, body)

    def _sim_inputs(self) -> dict:
        return {"chain": manifest_digest(self.chain_dir()),
                "truth": None if not self.truth else self.truth[1]}

    def stage_tune(self) -> StageRecord:
        from parknss.sim.tuning import tune_gains

        given = self.inp.interface
        inputs = {**self._sim_inputs(), "rounds": self.cfg.tune_rounds,
                  "given": _file_sha(given)}

        def body(fresh: bool) -> StageOutcome:
            if given is not None:
                from parknss.sim.control.interface import load_interface_config
                from parknss.sim.tuning import TuningConfig

                icfg = load_interface_config(given)
                tuned = TuningConfig().gains
                return StageOutcome({"interface": str(Path(given).resolve()),
                                     "gains": {k: getattr(icfg, k) for k in tuned}},
                                    reused=f"interface gains given by --interface {given}, "
                                           "not tuned here")
            doc = tune_gains("chain", self.car / "tune", rounds=self.cfg.tune_rounds,
                             files=self.sim_files(), executor=self.inp.executor,
                             workers=self.inp.workers, address=self.inp.address,
                             log=lambda m: self.say(f"  [sim] {m}"), overwrite=fresh)
            return StageOutcome({"interface": doc["yaml"], "gains": doc["gains"],
                                 "objective": [doc["initial_objective"], doc["objective"]],
                                 "evaluations": doc["evaluations"]})

        return self.book.run("tune", inputs, body)

    def _interface(self) -> str | None:
        t = self.rec.get("tune")
        return t.product["interface"] if t is not None else None

    def stage_grid(self) -> StageRecord:
        from parknss.sim.grid import run_grid_report

        iface = self._interface()
        inputs = {**self._sim_inputs(), "grid": self.cfg.grid, "cells": self.cfg.grid_cells,
                  "interface": _file_sha(iface), "plants": self.plants()}

        def body(fresh: bool) -> StageOutcome:
            doc = run_grid_report(self.cfg.grid, self.plants(), self.car / "grid",
                                  cells=self.cfg.grid_cells, files=self.sim_files(iface),
                                  executor=self.inp.executor, workers=self.inp.workers,
                                  address=self.inp.address, overwrite=fresh)
            return StageOutcome({k: doc[k] for k in ("grid", "plants", "cells", "summary",
                                                     "wall_s", "csv") if k in doc})

        return self.book.run("grid", inputs, body)

    def stage_fidelity(self) -> StageRecord:
        from parknss.experiments.fidelity import fidelity_specs, run_fidelity

        iface = self._interface()
        inputs = {**self._sim_inputs(), "grid": self.cfg.fidelity_grid,
                  "cells": self.cfg.fidelity_cells, "interface": _file_sha(iface)}

        def body(fresh: bool) -> StageOutcome:
            if not self.truth:
                return StageOutcome({"skipped": "no truth: the campaign is not a synthetic "
                                     "one of a reference vehicle found here"})
            specs = fidelity_specs(self.cfg.fidelity_grid, self.cfg.fidelity_cells)
            doc = run_fidelity(specs, self.car / "fidelity", files=self.sim_files(iface),
                               label=f"grid {self.cfg.fidelity_grid} cells "
                                     f"{self.cfg.fidelity_cells}", figures=False,
                               executor=self.inp.executor, workers=self.inp.workers,
                               address=self.inp.address, overwrite=fresh, progress=False)
            return StageOutcome({"summary": doc["summary"], "text": doc["text"],
                                 "cells": len(specs)})

        return self.book.run("fidelity", inputs, body)

    def stage_export(self) -> StageRecord:
        from parknss.chain.deployed import load_chain
        from parknss.export.config import load_export_config
        from parknss.export.fmu import export_fmu, identified_domain
        from parknss.export.onnx_step import export_onnx

        inputs = {"chain": manifest_digest(self.chain_dir())}
        out = self.car / "export"

        def body(fresh: bool) -> StageOutcome:
            fmu = export_fmu(out / "chain.fmu", self.chain_dir(), overwrite=True).to_json()
            onnx = export_onnx(out / "chain_step.onnx", None, self.chain_dir(),
                               overwrite=True).to_json()
            dom = identified_domain(load_chain(self.chain_dir()), load_export_config().fmu)
            return StageOutcome({"fmu": fmu, "onnx": onnx, "domain": _domain(dom)})

        return self.book.run("export", inputs, body)

    def stage_card(self) -> StageRecord:
        from parknss.experiments.identify.card import build_card
        from parknss.experiments.identify.card_html import card_html

        inputs = {s: r.digest for s, r in self.rec.items()}

        def body(fresh: bool) -> StageOutcome:
            card = build_card(self.rec, self.recipe, self.inp)
            js = write_text_atomic(self.car / "model_card.json", _json(card.to_json()) + "\n")
            page = write_text_atomic(self.car / "model_card.html", card_html(card))
            return StageOutcome({"json": str(js), "html": str(page)})

        return self.book.run("card", inputs, body)


class _Ahead:
    """A :class:`~parknss.executor.Prefetch` that says how far it got when it stops."""

    def __init__(self, prefetch, say: Say) -> None:
        self.prefetch, self.say = prefetch, say

    def __enter__(self):
        self.prefetch.__enter__()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.prefetch.__exit__(exc_type, exc, tb)
        if exc_type is None:
            self.say(f"  [actuators] Phase A ahead: {self.prefetch.computed} of "
                     f"{len(self.prefetch.jobs)} fits done beside the NSS fit")


def _json(doc) -> str:
    import json

    return json.dumps(doc, indent=2, default=str)


def _file_sha(path) -> str | None:
    if path is None:
        return None
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def _domain(dom) -> dict:
    return {"cmd_lo": list(dom.cmd_lo), "cmd_hi": list(dom.cmd_hi),
            "state_lo": list(dom.state_lo), "state_hi": list(dom.state_hi),
            "cmd_names": ["torque_cmd N·m", "decel_cmd m/s²", "steer_cmd deg"],
            "state_names": ["vx m/s", "yaw_rate rad/s"]}


def wanted_stages(inputs: IdentifyInputs) -> tuple[str, ...]:
    """The stages this run computes, in order (``stages`` less ``export`` when skipped;
    ``data``, cheap and skipped when unchanged, always opens a run and the card closes
    it)."""
    chosen = set(inputs.stages) if inputs.stages else set(STAGES)
    unknown = sorted(chosen - set(STAGES))
    if unknown:
        raise ConfigError(f"--stages: unknown {', '.join(unknown)} (stages: {', '.join(STAGES)})")
    if inputs.skip_export:
        chosen.discard("export")
    chosen |= {"data", "card"}
    return tuple(s for s in STAGES if s in chosen)


NEEDS: dict[str, tuple[str, ...]] = {
    "nss": ("data",), "selection": ("data", "nss"), "chain": ("data", "nss", "selection"),
    "rating": ("data", "nss", "chain"), "tune": ("data", "chain"),
    "grid": ("data", "chain"), "fidelity": ("data", "chain"), "export": ("chain",),
    "card": ("data",),
}


def run_identify(inputs: IdentifyInputs, say: Say = _quiet) -> dict:
    """Run the pipeline (module doc); the JSON document: the car folder, each stage's
    action (ran, resumed, skipped, reused, not run) and the model card's paths."""
    if (inputs.logs is None) == (inputs.data is None):
        raise ConfigError("give the logs folder (LOGS --mapping M.yaml) or --data CAMPAIGN, "
                          "not both")
    if inputs.logs is not None and not Path(inputs.logs).is_dir():
        raise ConfigError(f"{inputs.logs}: logs folder not found")
    cfg = load_identify_config(inputs.config, **inputs.overrides)
    wanted = wanted_stages(inputs)
    pipe = Pipeline(inputs, cfg, say)
    pipe.nss_config()  # a bad --set is refused before any work, and so are bad cells
    from parknss.sim.scenarios import grid_cells

    grid_cells(cfg.grid, None, cfg.grid_cells)
    grid_cells(cfg.fidelity_grid, None, cfg.fidelity_cells)
    pipe.book.estimates = pipe.estimates(wanted)
    source = {"logs": inputs.logs, "mapping": inputs.mapping, "data": inputs.data}
    with run_folder(inputs.out, command="parknss identify", args=source,
                    overwrite=inputs.overwrite) as run:
        stage = ["data"]

        def note() -> str:
            return (f"identify stopped in stage {stage[0]}; finished stages and the stage's "
                    f"own state kept in {inputs.out}; resume with `{_resume_line(inputs)}`")

        with keep_on_interrupt(note):
            try:
                for name in STAGES:
                    stage[0] = name
                    if name not in wanted:
                        old = pipe.book.read(name)
                        if old is not None and old.status == "done":
                            pipe.rec[name] = old
                        continue
                    missing = [n for n in NEEDS.get(name, ()) if n not in pipe.rec]
                    if missing:
                        raise ConfigError(f"stage {name} needs stage {', '.join(missing)}, "
                                          "which has not finished here: add it to --stages")
                    pipe.rec[name] = getattr(pipe, f"stage_{name}")()
            except KeyboardInterrupt:
                interrupt_note(clear=True)  # the identify line, not an inner command's
                raise
        run.manifest["stages"] = pipe.book.log
    actions = {e["stage"]: e for e in pipe.book.log}
    return {"car": str(inputs.out), "recipe": pipe.recipe,
            "stages": {s: actions.get(s, {"stage": s, "action": "not run"}) for s in STAGES},
            "card": pipe.rec["card"].product if "card" in pipe.rec else None}


def summary_text(doc: dict) -> str:
    """What ``parknss identify`` prints: each stage's action and the card's files."""
    lines = [f"car folder {doc['car']} (NSS recipe {doc['recipe']})"]
    for s, e in doc["stages"].items():
        what = e["action"]
        if e.get("wall_s") is not None:
            what += f" in {e['wall_s']:.0f} s"
        if e.get("reused"):
            what += f": {e['reused']}"
        lines.append(f"  {s:<10} {what}")
    if doc.get("card"):
        lines.append(f"model card: {doc['card'].get('html')} and {doc['card'].get('json')}")
    return "\n".join(lines)
