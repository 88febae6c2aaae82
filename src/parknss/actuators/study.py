"""``parknss actuators study``: Phase A, Phase B, co-tuning, Fig. 6 and Fig. 3 data.

On a stratified split of the campaign (fold ``select.val_fold``: 12 training, 4 held-out
trials), every candidate is fitted on the training trials and scored on the held-out ones
(Phase A), substituted into the chain (Phase B), and the co-tuning target (default the 1 s
NARX brake) is co-tuned on the training trials inside the selected assembly and scored on
the held-out trials before and after. Fig. 6 pairs each command-only core candidate's
signal fidelity (held-out NMSE) with its closed-loop value (per-channel substitution,
full-trajectory vx MSE) and gives their Pearson correlation (raw and of the logarithms).
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from parknss.actuators.config import ActuatorConfig
from parknss.actuators.cotune import cotune
from parknss.actuators.envelopes import Envelope, identify_envelope
from parknss.actuators.evaluate import chain_score, make_chain
from parknss.actuators.fit import signal_score
from parknss.actuators.select import (
    Candidate,
    PhaseB,
    nss_finetune,
    pearson,
    phase_a,
    phase_b,
    shortlist,
    study_specs,
)
from parknss.actuators.spec import CHANNELS, CORE_ARCHS, CandidateSpec
from parknss.data.splits import cv_plan
from parknss.data.trial import Campaign, Trial
from parknss.errors import ConfigError
from parknss.nss.model import NSSModel

Progress = Callable[[str], None]


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


def run_selection(
    nss: NSSModel, campaign: Campaign, cfg: ActuatorConfig, progress: Progress
) -> Selection:
    """Phase A on every candidate, the shortlist, optional NSS-state fine-tunes, Phase B."""
    t0 = time.perf_counter()
    train, val = split(campaign, cfg)
    env = identify_envelope(train, cfg.envelope)
    sc = cfg.select
    if "cmd" not in sc.variants:
        raise ConfigError("select.variants must include 'cmd' (Fig. 6 and co-tuning use it)")
    cands = phase_a(study_specs(sc.archs, sc.long_archs, sc.variants), train, val, cfg, env,
                    progress)
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


@dataclass
class CotuneResult:
    """The co-tuning target before/after: signal score, per-channel and assembled value."""

    target: str
    report: dict
    signal_before: dict
    signal_after: dict
    single_before: dict
    single_after: dict
    assembled_before: dict
    assembled_after: dict
    model: object = field(default=None, repr=False)

    def to_json(self) -> dict:
        d = dict(self.__dict__)
        d.pop("model")
        return d


def run_cotune_study(
    nss: NSSModel, sel: Selection, cfg: ActuatorConfig, progress: Progress
) -> CotuneResult:
    """Co-tune the target inside the selected assembly on the training trials; score on
    the held-out trials."""
    spec = CandidateSpec.parse(cfg.cotune.target)
    base = next((c for c in sel.cands if c.label == spec.name), None)
    if base is None:
        raise ConfigError(f"cotune.target {spec.name!r} is not a study candidate")
    tuned = copy.deepcopy(base.model)
    others = {ch: sel.pool[lb].model for ch, lb in sel.winners().items() if ch != spec.channel}
    chain = make_chain(nss, {**others, spec.channel: tuned}, sel.env)
    rep = cotune(chain, spec.channel, sel.train, cfg.cotune, progress)
    before_chain = make_chain(nss, {**others, spec.channel: base.model}, sel.env)
    return CotuneResult(
        spec.name,
        rep.to_json(),
        base.score.to_json(),
        signal_score(tuned, sel.val, sel.env, cfg.select.step_hold_s).to_json(),
        chain_score(make_chain(nss, {spec.channel: base.model}, sel.env), sel.val).to_json(),
        chain_score(make_chain(nss, {spec.channel: tuned}, sel.env), sel.val).to_json(),
        chain_score(before_chain, sel.val).to_json(),
        chain_score(chain, sel.val).to_json(),
        tuned,
    )


def fidelity_points(sel: Selection) -> list[dict]:
    """Fig. 6: the 15 command-only core candidates, (NMSE, per-channel vx MSE full)."""
    out = []
    for ch in CHANNELS:
        for a in CORE_ARCHS:
            lb = f"{ch}/{a}/cmd"
            if lb not in sel.pool:
                continue
            c = sel.pool[lb]
            out.append({"candidate": lb, "channel": ch, "arch": a, "nmse": c.score.nmse,
                        "vx_full": sel.phase_b.single[lb].vx_full,
                        "vx_moving": sel.phase_b.single[lb].vx_moving})
    return out


def correlations(points: list[dict]) -> dict:
    """Pearson correlation of signal fidelity and closed-loop value (raw and log10)."""
    x = [p["nmse"] for p in points]
    y = [p["vx_full"] for p in points]
    ok = [i for i in range(len(x)) if x[i] > 0 and y[i] > 0 and math.isfinite(x[i] + y[i])]
    return {
        "pearson": pearson(x, y),
        "pearson_log10": pearson(np.log10([x[i] for i in ok]), np.log10([y[i] for i in ok])),
        "n": len(points),
    }


def selected_variants(sel: Selection) -> dict[str, dict]:
    """Per channel: the winner, its variant/architecture, and the paper's choice."""
    paper = {"drive": "uniform state", "brake": "command only",
             "steering": "first-order lag (lag1)"}
    out = {}
    for ch, lb in sel.winners().items():
        s = sel.pool[lb].spec
        out[ch] = {"winner": lb, "arch": s.arch, "variant": s.variant, "paper": paper[ch]}
    return out
