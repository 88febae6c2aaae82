"""Two-phase selection (paper §III-C, §V-E).

Phase A fits every channel x architecture x variant on the training trials and scores it
against the recorded actual on the held-out trials (MSE, MAE, step response); the best
``shortlist`` per channel by held-out MSE are shortlisted. Phase B substitutes candidates
into the chain one channel at a time (the others measured) and then assembles the
``assembly_top`` best per channel in every combination; the assembled chain with all
submodels active is the final authority. The criterion is the full-trajectory plus the
moving-region vx MSE against the logged trials, the all-measured chain being the
reference. Phase B always includes the command-only candidates of every core
architecture (Fig. 6) and the long-memory brakes.

State-aware candidates are fitted on measured states and read NSS-predicted states in the
chain; with ``nss_state_finetune_iters > 0`` each shortlisted state-aware candidate also
gets a short signal-level fine-tune on streams in which the frozen NSS supplies the states
(its chain with that candidate substituted), entered in Phase B as ``<name>+nssft``.
"""

from __future__ import annotations

import copy
import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from parknss.actuators.config import ActuatorConfig
from parknss.actuators.envelopes import Envelope
from parknss.actuators.evaluate import ChainScore, chain_score, make_chain
from parknss.actuators.fit import FitReport, SignalScore, fit_candidate, signal_score
from parknss.actuators.models import ActuatorModel
from parknss.actuators.spec import CHANNELS, CORE_ARCHS, LONG_ARCHS, VARIANTS, CandidateSpec
from parknss.chain import chain_predictions
from parknss.data.trial import Trial
from parknss.nss.model import NSSModel

Progress = Callable[[str], None]


def _quiet(msg: str) -> None:
    pass


@dataclass
class Candidate:
    """A fitted candidate with its Phase A score (label adds '+nssft' when fine-tuned)."""

    spec: CandidateSpec
    model: ActuatorModel
    fit: FitReport
    score: SignalScore
    label: str = ""

    def __post_init__(self) -> None:
        self.label = self.label or self.spec.name


def study_specs(
    archs: Sequence[str] = CORE_ARCHS,
    long_archs: Sequence[str] = LONG_ARCHS,
    variants: Sequence[str] = VARIANTS,
) -> list[CandidateSpec]:
    """Every channel x core architecture x variant, plus the long-memory brakes."""
    out = [CandidateSpec(c, a, v) for c in CHANNELS for a in archs for v in variants]
    return out + [CandidateSpec("brake", a, v) for a in long_archs for v in variants]


def phase_a(
    specs: Sequence[CandidateSpec],
    train: Sequence[Trial],
    val: Sequence[Trial],
    cfg: ActuatorConfig,
    env: Envelope,
    progress: Progress = _quiet,
) -> list[Candidate]:
    """Fit every spec on ``train`` and score it on ``val``."""
    out = []
    for i, spec in enumerate(specs):
        model, rep = fit_candidate(spec, train, cfg, env)
        score = signal_score(model, val, env, cfg.select.step_hold_s)
        progress(f"A {i + 1}/{len(specs)} {spec.name}: held-out MSE {score.mse:.4g} "
                 f"({rep.wall_s:.1f} s)")
        out.append(Candidate(spec, model, rep, score))
    return out


def shortlist(cands: Sequence[Candidate], k: int) -> dict[str, list[Candidate]]:
    """The k best per channel by held-out MSE."""
    out = {}
    for ch in CHANNELS:
        pool = sorted((c for c in cands if c.spec.channel == ch), key=lambda c: c.score.mse)
        if pool:
            out[ch] = pool[:k]
    return out


def nss_states(nss: NSSModel, cand: Candidate, env: Envelope, trials) -> dict:
    """trial id -> (vx, yaw) predicted by the chain with ``cand`` substituted alone."""
    chain = make_chain(nss, {cand.spec.channel: cand.model}, env)
    pred = chain_predictions(chain, trials)
    return {tid: (p["vx"], p["yaw_rate"]) for tid, p in pred.items()}


def nss_finetune(
    nss: NSSModel, cand: Candidate, train, val, cfg: ActuatorConfig, env: Envelope
) -> Candidate:
    """The §III-C fine-tune of a state-aware candidate on NSS-supplied states."""
    states = nss_states(nss, cand, env, train)
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


def pearson(x: Sequence[float], y: Sequence[float]) -> float:
    """Pearson correlation of two equally long sequences (NaN if degenerate)."""
    a, b = np.asarray(x, float), np.asarray(y, float)
    if len(a) < 2 or np.std(a) == 0 or np.std(b) == 0:
        return float("nan")
    return float(np.corrcoef(a, b)[0, 1])
