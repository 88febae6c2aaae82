"""Actuator candidates: analytic responses, a recovered time constant, and rollout = step =
NumPy twin for every architecture and input variant."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from helpers.actuators import lag, lagged_trial, tiny_config
from parknss.actuators.candidates import CANDIDATES, build_candidate
from parknss.actuators.config import ArchConfig
from parknss.actuators.envelopes import identify_envelope
from parknss.actuators.fit import fit_candidate, step_metrics
from parknss.actuators.models import Scaling
from parknss.actuators.scan import matrix_scan, scalar_scan
from parknss.actuators.spec import ALL_ARCHS, VARIANTS, CandidateSpec
from parknss.errors import ConfigError
from parknss.signals import DT

torch.set_num_threads(1)
UNIT = Scaling(0.0, 1.0, (), (), 0.0, 1.0)


def _set(model, **vals):
    with torch.no_grad():
        for k, v in vals.items():
            getattr(model, k).fill_(v)


def test_first_order_step_is_one_minus_exp():
    m = build_candidate(CandidateSpec("drive", "lag1"), UNIT, ArchConfig())
    tau = 0.3
    _set(m, k=1.0, b=0.0, log_tau=math.log(tau))
    with torch.no_grad():
        y = m.rollout(torch.ones(1, 200, dtype=torch.float64), None,
                      torch.zeros(1, dtype=torch.float64))
    t = np.arange(200) * DT
    assert np.allclose(y[0].numpy(), 1 - np.exp(-t / tau), atol=1e-12)


def test_second_order_step_matches_the_analytic_response():
    m = build_candidate(CandidateSpec("brake", "lag2"), UNIT, ArchConfig())
    tau2, zeta = 0.05, 0.4
    _set(m, k=1.0, b=0.0, log_tau2=math.log(tau2), log_zeta=math.log(zeta))
    with torch.no_grad():
        y = m.rollout(torch.ones(1, 150, dtype=torch.float64), None,
                      torch.zeros(1, dtype=torch.float64))
    w = 1 / tau2
    wd = w * math.sqrt(1 - zeta**2)
    t = np.arange(150) * DT
    c = zeta / math.sqrt(1 - zeta**2)
    ref = 1 - np.exp(-zeta * w * t) * (np.cos(wd * t) + c * np.sin(wd * t))
    assert np.allclose(y[0].numpy(), ref, atol=1e-10)
    sm = step_metrics(np.r_[np.zeros(10), y[0].numpy()], 10, 1.0)
    assert sm.overshoot_pct == pytest.approx(100 * math.exp(-math.pi * c), rel=0.05)


def test_fitted_time_constant_recovers_the_true_one():
    trials = [lagged_trial(400, seed=s, taus=(0.15, 0.1, 0.08)) for s in range(3)]
    cfg = tiny_config(fit={"iters_linear": 150, "window": 150, "burn_in": 20, "max_windows": 32})
    env = identify_envelope(trials, cfg.envelope)
    model, rep = fit_candidate(CandidateSpec("drive", "lag1"), trials, cfg, env)
    assert model.tau == pytest.approx(0.15, rel=0.03)
    assert rep.loss < 1e-4


def test_scans_equal_the_sequential_recurrence():
    g = torch.Generator().manual_seed(0)
    a = torch.rand(3, 99, generator=g, dtype=torch.float64)
    b = torch.randn(3, 99, generator=g, dtype=torch.float64)
    x0 = torch.randn(3, dtype=torch.float64)
    X = scalar_scan(x0, a, b)
    x = x0.clone()
    for k in range(99):
        x = a[:, k] * x + b[:, k]
        assert torch.allclose(X[:, k + 1], x, atol=1e-12)
    A = 0.5 * torch.randn(2, 50, 2, 2, generator=g, dtype=torch.float64)
    bb = torch.randn(2, 50, 2, generator=g, dtype=torch.float64)
    z0 = torch.randn(2, 2, dtype=torch.float64)
    Z = matrix_scan(z0, A, bb)
    z = z0.clone()
    for k in range(50):
        z = (A[:, k] @ z[..., None])[..., 0] + bb[:, k]
        assert torch.allclose(Z[:, k + 1], z, atol=1e-10)


@pytest.mark.parametrize("arch", ALL_ARCHS)
@pytest.mark.parametrize("variant", VARIANTS)
def test_rollout_step_and_numpy_twin_agree(arch, variant):
    spec = CandidateSpec("drive", arch, variant)
    F = len(spec.features)
    sc = Scaling(10.0, 20.0, (0.1,) * F, (0.5,) * F, 5.0, 30.0)
    torch.manual_seed(1)
    m = build_candidate(spec, sc, ArchConfig(narx_long_lags=30))
    with torch.no_grad():
        for p in m.parameters():
            p.add_(0.3 * torch.randn_like(p))
    rng = np.random.default_rng(0)
    T = 300
    cmd = torch.as_tensor(rng.normal(10, 20, (2, T)))
    feat = torch.as_tensor(rng.normal(size=(2, T, F)))
    y0 = torch.tensor([3.0, 7.0], dtype=torch.float64)
    with torch.no_grad():
        Y = m.rollout(cmd, feat, y0)
        st = m.init_state(cmd[:, 0], y0)
        ys = []
        for k in range(T):
            y, st = m.step(st, cmd[:, k], feat[:, k])
            ys.append(y)
    assert torch.allclose(Y, torch.stack(ys, 1), rtol=0, atol=1e-10)
    s = m.stepper()
    s.reset(float(cmd[1, 0]), 7.0)
    c1, f1 = cmd[1].numpy(), feat[1].numpy()
    yn = np.array([s.step(float(c1[k]), f1[k]) for k in range(T)])
    assert np.max(np.abs(yn - Y[1].numpy())) < 1e-10


def test_every_architecture_name_has_one_implementation():
    """The spec vocabulary and the implementation table agree; each class names its twin
    and its fitting budget (no other lookup table)."""
    assert set(CANDIDATES) == set(ALL_ARCHS)
    for cls in CANDIDATES.values():
        assert cls.fit_family in ("linear", "neural")
        assert callable(cls.stepper_cls)
    assert {a for a, c in CANDIDATES.items() if c.fit_family == "linear"} == {
        "lag1", "lag2", "static", "monolag"}


def test_bad_specs_are_one_line_errors():
    with pytest.raises(ConfigError, match="unknown actuator architecture"):
        CandidateSpec("drive", "transformer")
    with pytest.raises(ConfigError, match="channel/arch/variant"):
        CandidateSpec.parse("drive/lag1")


def test_lag_helper_is_the_exact_recurrence():
    y = lag(np.ones(50), 0.2)
    assert y[-1] == pytest.approx(1 - math.exp(-49 * DT / 0.2))
