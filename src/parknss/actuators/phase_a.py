"""Phase A of the selection (paper §III-C): every candidate fitted and scored on its own.

Every channel x architecture x variant (:func:`study_specs`) is fitted on the training
trials and scored against the recorded actual on the held-out trials (MSE, MAE, NMSE, step
response); :func:`shortlist` keeps the best ``select.shortlist`` per channel by held-out
MSE. Phase B, which needs the chain, is :mod:`parknss.chain.selection`.

The fits are independent, so :func:`run_phase_a` runs them as jobs of the one executor
(:func:`parknss.executor.run_jobs`: in-process with one worker, a local process pool, or
Ray). A job (:func:`fit_job`) names its campaign folder, its split by trial id, the
actuator config and the envelope, all JSON; it returns the fitted weights, the scaling, the
fit report and the score as JSON, from which :func:`decode_candidate` rebuilds the exact
float64 model. Each fit seeds torch from its candidate name
(:func:`parknss.actuators.fit.candidate_seed`), so the result does not depend on the order
or the process in which the jobs run.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import torch

from parknss.actuators.candidates import build_candidate
from parknss.actuators.config import ActuatorConfig
from parknss.actuators.envelopes import Envelope
from parknss.actuators.fit import FitReport, SignalScore, StepMetrics, fit_candidate, signal_score
from parknss.actuators.models import ActuatorModel, Scaling
from parknss.actuators.spec import CHANNELS, CORE_ARCHS, LONG_ARCHS, VARIANTS, CandidateSpec
from parknss.executor import Job, run_jobs

Progress = Callable[[str], None]
FIT_JOB = "parknss.actuators.phase_a:fit_job"


def _quiet(msg: str) -> None:
    pass


@dataclass(frozen=True)
class Fanout:
    """How independent fits run (:func:`parknss.executor.run_jobs`): ``executor`` "local"
    or "ray", ``workers`` (1: in-process), Ray ``address`` (None: a local Ray);
    ``cache_dir`` a folder of finished fits (:class:`parknss.executor.ResultCache`, keyed
    by each job's arguments) read before fitting and written after, or None. The caller
    owns the cache's validity: its key names the campaign folder, not its content
    (``parknss identify`` keeps one per campaign data hash)."""

    executor: str = "local"
    workers: int | None = 1
    address: str | None = None
    cache_dir: str | None = None


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


# ------------------------------------------------------------------------ the job


def _num_out(v: float) -> float | None:
    return None if not math.isfinite(v) else v


def _num_in(v: float | None) -> float:
    return math.nan if v is None else float(v)


def encode_candidate(model: ActuatorModel, rep: FitReport, score: SignalScore) -> dict:
    """A fitted candidate as plain JSON (weights as float64 lists, exact in JSON)."""
    st = score.step
    return {
        "spec": model.spec.name,
        "scaling": model.scaling.to_json(),
        "state": {k: v.detach().to(torch.float64).tolist() for k, v in model.state_dict().items()},
        "fit": {"loss": rep.loss, "iters": rep.iters, "wall_s": rep.wall_s},
        "score": {
            "mse": score.mse, "mae": score.mae, "nmse": _num_out(score.nmse),
            "n_params": score.n_params,
            "step": [st.level, *(_num_out(v) for v in (st.delay_s, st.rise_s, st.overshoot_pct))],
        },
    }


def decode_candidate(doc: dict, cfg: ActuatorConfig) -> Candidate:
    """The :class:`Candidate` of :func:`encode_candidate`'s document (global torch RNG
    untouched)."""
    spec = CandidateSpec.parse(doc["spec"])
    with torch.random.fork_rng(devices=[]):
        model = build_candidate(spec, Scaling.from_json(doc["scaling"]), cfg.arch)
    model.load_state_dict({k: torch.tensor(v, dtype=torch.float64)
                           for k, v in doc["state"].items()})
    model.eval()
    model.requires_grad_(False)
    f, s = doc["fit"], doc["score"]
    level, *rest = s["step"]
    step = StepMetrics(float(level), *(_num_in(v) for v in rest))
    score = SignalScore(float(s["mse"]), float(s["mae"]), _num_in(s["nmse"]), step,
                        int(s["n_params"]))
    return Candidate(spec, model, FitReport(float(f["loss"]), int(f["iters"]),
                                            float(f["wall_s"])), score)


def fit_job(
    spec: str, data: str | None, train: list[str], val: list[str], config: dict,
    envelope: dict,
) -> dict:
    """One Phase A fit as an executor job: fit ``spec`` on the trials ``train`` (ids) of the
    campaign folder ``data`` (None: the default campaign), score it on ``val``; the
    :func:`encode_candidate` document."""
    from parknss.nss.campaigns import load_campaign

    cfg = ActuatorConfig.model_validate(config)
    env = Envelope.from_json(envelope)
    campaign = load_campaign(data)
    by_id = {tr.id: tr for tr in campaign}
    tr_trials, val_trials = [by_id[i] for i in train], [by_id[i] for i in val]
    model, rep = fit_candidate(CandidateSpec.parse(spec), tr_trials, cfg, env)
    score = signal_score(model, val_trials, env, cfg.select.step_hold_s)
    return encode_candidate(model, rep, score)


def phase_a_jobs(
    specs: Sequence[CandidateSpec],
    data: str | None,
    train: Sequence[str],
    val: Sequence[str],
    cfg: ActuatorConfig,
    env: Envelope,
) -> list[Job]:
    """The executor jobs of Phase A: one :func:`fit_job` per spec, fitted on the trials
    ``train`` and scored on ``val`` (trial ids of the campaign folder ``data``), all JSON."""
    common = {"data": data, "train": list(train), "val": list(val),
              "config": cfg.model_dump(mode="json"), "envelope": env.to_json()}
    return [Job(FIT_JOB, {"spec": s.name, **common}, name=s.name) for s in specs]


def run_phase_a(
    jobs: Sequence[Job], cfg: ActuatorConfig, progress: Progress = _quiet,
    fanout: Fanout = Fanout(),
) -> list[Candidate]:
    """The candidates of the :func:`phase_a_jobs` ``jobs``, fitted through the executor
    (or read from ``fanout.cache_dir``), in the order of ``jobs``."""
    docs = run_jobs(jobs, executor=fanout.executor, workers=fanout.workers,
                    address=fanout.address, progress=False, desc="phase A",
                    cache_dir=fanout.cache_dir)
    out = []
    for i, doc in enumerate(docs):
        c = decode_candidate(doc, cfg)
        progress(f"A {i + 1}/{len(jobs)} {c.spec.name}: held-out MSE {c.score.mse:.4g} "
                 f"({c.fit.wall_s:.1f} s)")
        out.append(c)
    return out


def shortlist(cands: Sequence[Candidate], k: int) -> dict[str, list[Candidate]]:
    """The k best per channel by held-out MSE."""
    out = {}
    for ch in CHANNELS:
        pool = sorted((c for c in cands if c.spec.channel == ch), key=lambda c: c.score.mse)
        if pool:
            out[ch] = pool[:k]
    return out
