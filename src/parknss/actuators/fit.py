"""Signal-level fitting and Phase A scoring of one candidate (paper §III-C).

:func:`fit_candidate` fits a candidate to the recorded actual by full-batch Adam on the
training windows (:func:`parknss.actuators.data.windows`), mean squared error in scaled
units, after initialising its affine part by least squares; the lowest-loss parameters
are kept. :func:`signal_score` scores it on held-out whole trials (MSE, MAE, normalised
MSE) replayed through the output envelope, and :func:`step_response` gives its delay,
10-90 % rise time and overshoot for a command step.
"""

from __future__ import annotations

import math
import time
import zlib
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np
import torch

from parknss.actuators.candidates import build_candidate
from parknss.actuators.config import ActuatorConfig
from parknss.actuators.data import ChannelData, channel_data, windows
from parknss.actuators.envelopes import Envelope, limit_outputs_torch
from parknss.actuators.models import ActuatorModel, Scaling, parameter_count
from parknss.actuators.spec import CHANNEL_INDEX, CandidateSpec
from parknss.data.trial import Trial
from parknss.errors import ParknssError
from parknss.signals import DT


@dataclass
class FitReport:
    """How a fit went: final training loss (scaled MSE), Adam steps, seconds."""

    loss: float
    iters: int
    wall_s: float


def candidate_seed(spec: CandidateSpec, base: int) -> int:
    """A seed per candidate, stable across runs and processes."""
    return base + zlib.crc32(spec.name.encode()) % 100_000


def _affine_init(model: ActuatorModel, d: ChannelData) -> None:
    """Least-squares ỹ ≈ k·c̃ + b + w·f̃ on the training samples."""
    c, f, y = d.cat()
    cs = (c - model.scaling.c_off) / model.scaling.c_sc
    fs = (f - np.asarray(model.scaling.f_off)) / np.asarray(model.scaling.f_sc) if f.size else f
    ys = (y - model.scaling.y_off) / model.scaling.y_sc
    A = np.column_stack([cs, np.ones_like(cs), fs.reshape(len(cs), -1)])
    sol, *_ = np.linalg.lstsq(A, ys, rcond=None)
    model.init_affine(sol[0], sol[1], sol[2:])
    model.init_samples(cs, fs.reshape(len(cs), -1), ys)


def fit_candidate(
    spec: CandidateSpec,
    trials: Sequence[Trial],
    cfg: ActuatorConfig,
    env: Envelope,
    *,
    states: dict | None = None,
    init: ActuatorModel | None = None,
    iters: int | None = None,
) -> tuple[ActuatorModel, FitReport]:
    """Fit ``spec`` on ``trials`` (or continue from ``init``: the §III-C fine-tune on
    NSS-supplied ``states``, trial id -> (vx, yaw))."""
    t0 = time.perf_counter()
    d = channel_data(spec, trials, env, states)
    torch.manual_seed(candidate_seed(spec, cfg.fit.seed))
    if init is None:
        c, f, y = d.cat()
        model = build_candidate(spec, Scaling.fit(c, f, y, spec.features), cfg.arch)
        _affine_init(model, d)
    else:
        model = init
        model.requires_grad_(True)
    linear = model.fit_family == "linear"
    n_iter = iters if iters is not None else (
        cfg.fit.iters_linear if linear else cfg.fit.iters_neural)
    lr = cfg.fit.lr_linear if linear else cfg.fit.lr_neural
    w = windows(d, cfg.fit)
    cmd, feat = torch.as_tensor(w.cmd), torch.as_tensor(w.feat)
    y0, mask = torch.as_tensor(w.y0), torch.as_tensor(w.mask)
    target = model.sc_y(torch.as_tensor(w.y))
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    best, best_loss = None, math.inf
    model.train()
    for _ in range(n_iter):
        opt.zero_grad(set_to_none=True)
        pred = model.sc_y(model.rollout(cmd, feat, y0))
        loss = ((pred - target) ** 2)[mask].mean()
        if not torch.isfinite(loss):
            raise ParknssError(f"fitting {spec.name} diverged (loss {float(loss)})")
        lv = float(loss.detach())
        if lv < best_loss:
            best_loss = lv
            best = {k: v.detach().clone() for k, v in model.state_dict().items()}
        loss.backward()
        opt.step()
    if best is not None:
        model.load_state_dict(best)
    model.eval()
    model.requires_grad_(False)
    return model, FitReport(best_loss, n_iter, time.perf_counter() - t0)


# ------------------------------------------------------------------------ scoring


@dataclass
class StepMetrics:
    """Response to a command step: delay to 10 %, 10-90 % rise time (s), overshoot (%)."""

    level: float
    delay_s: float
    rise_s: float
    overshoot_pct: float


@dataclass
class SignalScore:
    """Phase A score on held-out whole trials (physical units squared / absolute)."""

    mse: float
    mae: float
    nmse: float
    step: StepMetrics
    n_params: int

    def to_json(self) -> dict:
        d = asdict(self)
        return {k: _nan_none(v) for k, v in {**d, **d.pop("step")}.items() if k != "step"}


def _nan_none(v):
    return None if isinstance(v, float) and not math.isfinite(v) else v


def replay(model: ActuatorModel, d: ChannelData, env: Envelope) -> list[np.ndarray]:
    """Open-loop replay of every trial through the output envelope; physical (T,) each."""
    out = []
    with torch.no_grad():
        for c, f, y in zip(d.cmd, d.feat, d.y, strict=True):
            ct, ft = torch.as_tensor(c)[None], torch.as_tensor(f)[None]
            y0 = torch.tensor([y[0]], dtype=torch.float64)
            p = model.rollout(ct, ft, y0)
            j = CHANNEL_INDEX[model.spec.channel]
            modelled = tuple(i == j for i in range(3))
            p = limit_outputs_torch(env, p, p, p, y0, modelled)[j]
            out.append(p[0].numpy())
    return out


def step_response(model: ActuatorModel, env: Envelope, hold_s: float) -> StepMetrics:
    """Step from the rest command (0) to half the domain's far end (decel: its lower
    bound) after 2 s at rest, features at standstill in drive (vx = 0, ω = 0, gear = +1)."""
    j = CHANNEL_INDEX[model.spec.channel]
    lo, hi = env.cmd_lo[j], env.cmd_hi[j]
    level = lo if model.spec.channel == "brake" else 0.5 * hi
    n0, n1 = round(2.0 / DT), round(hold_s / DT)
    rest = min(max(0.0, lo), hi)
    cmd = np.r_[np.full(n0, rest), np.full(n1, level)]
    names = model.spec.features
    feat = np.array([[1.0 if n == "gear" else 0.0 for n in names]] * len(cmd)).reshape(len(cmd), -1)
    with torch.no_grad():
        y = model.rollout(torch.as_tensor(cmd)[None], torch.as_tensor(feat)[None],
                          torch.zeros(1, dtype=torch.float64))[0].numpy()
    return step_metrics(y, n0, level)


def step_metrics(y: np.ndarray, k_step: int, level: float, tail: int = 50) -> StepMetrics:
    """Delay, rise time and overshoot of response y (T,) to a step at sample k_step."""
    y_before, y_final = y[k_step - 1], float(np.mean(y[-tail:]))
    delta = y_final - y_before
    if not math.isfinite(delta) or abs(delta) < 1e-9:
        return StepMetrics(level, math.nan, math.nan, math.nan)
    frac = (y[k_step:] - y_before) / delta
    i10 = np.flatnonzero(frac >= 0.1)
    i90 = np.flatnonzero(frac >= 0.9)
    delay = float(i10[0] * DT) if i10.size else math.nan
    rise = float((i90[0] - i10[0]) * DT) if i10.size and i90.size else math.nan
    over = float(max(0.0, np.max(frac) - 1.0) * 100.0)
    return StepMetrics(level, delay, rise, over)


def signal_score(
    model: ActuatorModel, trials: Sequence[Trial], env: Envelope, hold_s: float = 4.0
) -> SignalScore:
    """Held-out MSE, MAE, NMSE (MSE / variance of the actual) and step metrics."""
    d = channel_data(model.spec, trials, env)
    pred = np.concatenate(replay(model, d, env))
    y = np.concatenate(d.y)
    e = pred - y
    mse = float(np.mean(e**2))
    var = float(np.var(y))
    return SignalScore(
        mse, float(np.mean(np.abs(e))), mse / var if var > 0 else math.nan,
        step_response(model, env, hold_s), parameter_count(model),
    )
