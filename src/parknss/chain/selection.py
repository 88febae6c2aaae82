"""Phase B of the selection and the whole two-phase selection (paper §III-C, §V-E).

Phase A (:mod:`parknss.actuators.phase_a`) fits every channel x architecture x variant on
the training trials and scores it against the recorded actual on the held-out trials; the
best ``shortlist`` per channel by held-out MSE are shortlisted. Phase B substitutes
candidates into the chain one channel at a time (the others measured) and then assembles
the ``assembly_top`` best per channel in every combination; the assembled chain with all
submodels active is the final authority. The criterion is the full-trajectory plus the
moving-region vx MSE against the logged trials, the all-measured chain being the
reference. Phase B always includes the command-only candidates of every core
architecture (Fig. 6) and the long-memory brakes.

State-aware candidates are fitted on measured states and read NSS-predicted states in the
chain; with ``nss_state_finetune_iters > 0`` each shortlisted state-aware candidate also
gets a short signal-level fine-tune on streams in which the frozen NSS supplies the states
(its chain with that candidate substituted), entered in Phase B as ``<name>+nssft``.

:func:`run_selection` runs both phases on the stratified split of a campaign folder.
"""

from __future__ import annotations

import copy
import itertools
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from parknss.actuators.config import ActuatorConfig
from parknss.actuators.envelopes import Envelope, identify_envelope
from parknss.actuators.fit import fit_candidate, signal_score
from parknss.actuators.models import ActuatorModel
from parknss.actuators.phase_a import (
    Candidate,
    Fanout,
    phase_a_jobs,
    run_phase_a,
    shortlist,
    study_specs,
)
from parknss.actuators.spec import CHANNELS, CandidateSpec
from parknss.chain.score import ChainScore, chain_score, make_chain
from parknss.chain.trials import chain_predictions
from parknss.data.splits import cv_plan
from parknss.data.trial import Campaign, Trial
from parknss.errors import ConfigError
from parknss.executor import Job
from parknss.nss.model import NSSModel

Progress = Callable[[str], None]


def _quiet(msg: str) -> None:
    pass


def nss_states(
    nss: NSSModel, model: ActuatorModel, env: Envelope, trials: Sequence[Trial]
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """trial id -> (vx m/s, yaw rad/s), each (T,), predicted by the chain with ``model``
    substituted alone (the other channels measured)."""
    chain = make_chain(nss, {model.spec.channel: model}, env)
    pred = chain_predictions(chain, trials)
    return {tid: (p["vx"], p["yaw_rate"]) for tid, p in pred.items()}


def nss_finetune(
    nss: NSSModel, cand: Candidate, train, val, cfg: ActuatorConfig, env: Envelope
) -> Candidate:
    """The §III-C fine-tune of a state-aware candidate on NSS-supplied states."""
    states = nss_states(nss, cand.model, env, train)
    model, rep = fit_candidate(
        cand.spec, train, cfg, env, states=states, init=copy.deepcopy(cand.model),
        iters=cfg.select.nss_state_finetune_iters,
    )
    score = signal_score(model, val, env, cfg.select.step_hold_s)
    return Candidate(cand.spec, model, rep, score, label=cand.spec.name + "+nssft")


@dataclass
class PhaseB:
    """Reference, per-channel substitutions, assemblies and the selected winners."""

    reference: ChainScore
    single: dict[str, ChainScore] = field(default_factory=dict)  # label -> score
    assemblies: list[tuple[dict[str, str], ChainScore]] = field(default_factory=list)
    winners: dict[str, str] = field(default_factory=dict)  # channel -> label

    def to_json(self) -> dict:
        return {
            "reference": self.reference.to_json(),
            "single": {k: v.to_json() for k, v in self.single.items()},
            "assemblies": [{"labels": a, **s.to_json()} for a, s in self.assemblies],
            "winners": self.winners,
        }


def phase_b(
    nss: NSSModel,
    pool: dict[str, Candidate],
    short: dict[str, list[Candidate]],
    val: Sequence[Trial],
    cfg: ActuatorConfig,
    env: Envelope,
    progress: Progress = _quiet,
) -> PhaseB:
    """Per-channel substitution of every candidate in ``pool`` (label -> candidate), then
    assemblies of the best ``assembly_top`` per channel among the shortlisted and
    fine-tuned ones; winners = the best assembly."""
    res = PhaseB(chain_score(make_chain(nss, {}, env), val))
    progress(f"B reference (all measured): vx full {res.reference.vx_full:.4f} (km/h)^2")
    for label, c in pool.items():
        res.single[label] = chain_score(make_chain(nss, {c.spec.channel: c.model}, env), val)
        progress(f"B {label}: vx full {res.single[label].vx_full:.4f}, "
                 f"moving {res.single[label].vx_moving:.4f}")
    eligible = {ch: [c.label for c in short.get(ch, [])] for ch in CHANNELS}
    for label, c in pool.items():
        if label.endswith("+nssft"):
            eligible[c.spec.channel].append(label)
    tops = {
        ch: sorted(labels, key=lambda lb: res.single[lb].criterion)[: cfg.select.assembly_top]
        for ch, labels in eligible.items()
    }
    for combo in itertools.product(*(tops[ch] for ch in CHANNELS)):
        labels = dict(zip(CHANNELS, combo, strict=True))
        models = {ch: pool[lb].model for ch, lb in labels.items()}
        s = chain_score(make_chain(nss, models, env), val)
        res.assemblies.append((labels, s))
        progress(f"B assembly {' + '.join(combo)}: vx full {s.vx_full:.4f}")
    best = min(res.assemblies, key=lambda a: a[1].criterion)
    res.winners = dict(best[0])
    return res



@dataclass
class Selection:
    """Everything the selection produced (models kept for figures and the build)."""

    train: list[Trial]
    val: list[Trial]
    env: Envelope
    cands: list[Candidate]
    short: dict[str, list[Candidate]]
    pool: dict[str, Candidate]
    phase_b: PhaseB
    wall_s: float = 0.0

    def winners(self) -> dict[str, str]:
        return dict(self.phase_b.winners)

    def to_json(self) -> dict:
        return {
            "train": [t.id for t in self.train],
            "val": [t.id for t in self.val],
            "envelope": self.env.to_json(),
            "phase_a": [
                {"candidate": c.label, "channel": c.spec.channel, "arch": c.spec.arch,
                 "variant": c.spec.variant, "fit_s": c.fit.wall_s, **c.score.to_json()}
                for c in self.cands
            ],
            "shortlist": {ch: [c.label for c in cs] for ch, cs in self.short.items()},
            "phase_b": self.phase_b.to_json(),
            "winners": self.winners(),
            "wall_s": self.wall_s,
        }


def split(campaign: Campaign, cfg: ActuatorConfig) -> tuple[list[Trial], list[Trial]]:
    """The selection split: fold ``select.val_fold`` of the CV plan (stratified, or plain
    k-fold on a campaign that is not stratifiable: :func:`parknss.data.splits.cv_plan`)."""
    folds = cv_plan(campaign).folds
    if cfg.select.val_fold >= len(folds):
        raise ConfigError(f"select.val_fold {cfg.select.val_fold}: only {len(folds)} folds")
    f = folds[cfg.select.val_fold]
    return [campaign[i] for i in f.train], [campaign[i] for i in f.val]


@dataclass(frozen=True)
class PhaseAPlan:
    """What Phase A of :func:`run_selection` fits: the split, the envelope identified on
    its training trials, the candidate specs and their executor jobs."""

    train: list[Trial]
    val: list[Trial]
    env: Envelope
    specs: list[CandidateSpec]
    jobs: list[Job]


def phase_a_plan(campaign: Campaign, data: str | None, cfg: ActuatorConfig) -> PhaseAPlan:
    """Phase A of :func:`run_selection` on ``campaign`` (the folder ``data``), planned
    but not fitted: it needs no NSS, so a caller may fit it ahead
    (:class:`parknss.executor.Prefetch`; ``parknss identify`` does, beside the NSS fit)."""
    train, val = split(campaign, cfg)
    env = identify_envelope(train, cfg.envelope)
    sc = cfg.select
    if "cmd" not in sc.variants:
        raise ConfigError("select.variants must include 'cmd' (Fig. 6 and co-tuning use it)")
    specs = study_specs(sc.archs, sc.long_archs, sc.variants)
    jobs = phase_a_jobs(specs, data, [t.id for t in train], [t.id for t in val], cfg, env)
    return PhaseAPlan(train, val, env, specs, jobs)


def run_selection(
    nss: NSSModel,
    campaign: Campaign,
    data: str | None,
    cfg: ActuatorConfig,
    progress: Progress = _quiet,
    fanout: Fanout = Fanout(),
) -> Selection:
    """Phase A on every candidate, the shortlist, optional NSS-state fine-tunes, Phase B.

    ``campaign`` is the campaign folder ``data`` loaded (None: the default campaign); the
    Phase A fits run as executor jobs on that folder (``fanout``)."""
    t0 = time.perf_counter()
    plan = phase_a_plan(campaign, data, cfg)
    train, val, env = plan.train, plan.val, plan.env
    sc = cfg.select
    cands = run_phase_a(plan.jobs, cfg, progress, fanout)
    short = shortlist(cands, cfg.select.shortlist)
    by_name = {c.label: c for c in cands}
    pool: dict[str, Candidate] = {c.label: c for cs in short.values() for c in cs}
    for ch in CHANNELS:
        for a in sc.archs:
            pool.setdefault(f"{ch}/{a}/cmd", by_name[f"{ch}/{a}/cmd"])
    for a in sc.long_archs:
        pool.setdefault(f"brake/{a}/cmd", by_name[f"brake/{a}/cmd"])
    if cfg.select.nss_state_finetune_iters > 0:
        for cs in short.values():
            for c in cs:
                if c.spec.state_aware:
                    ft = nss_finetune(nss, c, train, val, cfg, env)
                    progress(f"fine-tuned {c.label} on NSS states: MSE {ft.score.mse:.4g}")
                    pool[ft.label] = ft
    pb = phase_b(nss, pool, short, val, cfg, env, progress)
    return Selection(train, val, env, cands, short, pool, pb, time.perf_counter() - t0)
