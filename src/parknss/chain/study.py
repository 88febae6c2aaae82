"""The selection study's numbers beyond Phase A/B (paper §III-C, §V-E, Fig. 6).

On the selection split (:func:`parknss.chain.selection.run_selection`: fold
``select.val_fold``, 12 training and 4 held-out trials), :func:`run_cotune_study` co-tunes
the co-tuning target (default the 1 s NARX brake) on the training trials inside the
selected assembly and scores it on the held-out trials before and after. Fig. 6 pairs each
command-only core candidate's signal fidelity (held-out NMSE) with its closed-loop value
(per-channel substitution, full-trajectory vx MSE) and gives their Pearson correlation (raw
and of the logarithms). The command, its figures and files are
:mod:`parknss.experiments.actuator_study`.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from parknss.actuators.config import ActuatorConfig
from parknss.actuators.fit import signal_score
from parknss.actuators.models import ActuatorModel
from parknss.actuators.spec import CHANNELS, CORE_ARCHS, CandidateSpec
from parknss.chain.cotune import cotune
from parknss.chain.score import chain_score, make_chain
from parknss.chain.selection import Selection
from parknss.errors import ConfigError
from parknss.nss.model import NSSModel

Progress = Callable[[str], None]


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
    model: ActuatorModel | None = field(default=None, repr=False)

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


def pearson(x: Sequence[float], y: Sequence[float]) -> float:
    """Pearson correlation of two equally long sequences (NaN if degenerate)."""
    a, b = np.asarray(x, float), np.asarray(y, float)
    if len(a) < 2 or np.std(a) == 0 or np.std(b) == 0:
        return float("nan")
    return float(np.corrcoef(a, b)[0, 1])


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
