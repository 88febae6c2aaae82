"""Structured candidates: first-order lag, second-order lag, Hammerstein, static affine map.

All work in scaled units (see :mod:`parknss.actuators.models`) around one target

    t[k] = k·c̃[k] + b + w·f̃[k] (+ ψ(c̃[k], f̃[k]) for Hammerstein),

the static gain and offset a scalar lag needs to map a command to a different quantity
(decel m/s² -> pressure bar); w = 0 and no τ modulation in the command-only variant.

* lag1: τ ẏ = t - y, exactly discretised: y[k+1] = a[k]·y[k] + (1 - a[k])·t[k],
  a = exp(-dt/τ), τ[k] = exp(log τ + v·f̃[k]) (state-aware variants modulate τ).
* lag2: p'' = ω²(t - p) - 2ζω p', ω = 1/τ2, zero-order-hold exact (matrix exponential);
  parameters (τ2, ζ, K = k). Output p, initial [y0, 0].
* hammerstein: a 1x8x8x1 tanh perceptron ψ (input [c̃, f̃]) plus the affine bypass,
  then the first-order lag.
* static: y[k] = t[k], no dynamics (the "static affine maps" row of Table IV).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor, nn

from parknss.actuators.models import ActuatorModel
from parknss.actuators.scan import matrix_scan, scalar_scan
from parknss.actuators.steppers import Lag1Stepper, Lag2Stepper, StaticStepper
from parknss.nss.nets import tanh_mlp


def lag2_discrete(log_tau2: Tensor, log_zeta: Tensor, dt: float) -> tuple[Tensor, Tensor]:
    """(A (2, 2), Bv (2,)) of the zero-order-hold exact second-order lag
    p'' = ω²(t - p) - 2ζω p', ω = exp(-log_tau2), ζ = exp(log_zeta), state [p, p']."""
    w = torch.exp(-log_tau2)
    z = torch.exp(log_zeta)
    zero = torch.zeros((), dtype=w.dtype)
    one = torch.ones((), dtype=w.dtype)
    row0 = torch.stack([zero, one, zero])
    row1 = torch.stack([-w * w, -2.0 * z * w, w * w])
    m = torch.stack([row0, row1, torch.zeros(3, dtype=w.dtype)]) * dt
    e = torch.linalg.matrix_exp(m)
    return e[:2, :2], e[:2, 2]


class _Affine(ActuatorModel):
    """The shared target t = k·c̃ + b + w·f̃."""

    fit_family = "linear"

    def __init__(self, spec, scaling, cfg) -> None:
        super().__init__(spec, scaling, cfg)
        f64 = torch.float64
        self.k = nn.Parameter(torch.tensor(1.0, dtype=f64))
        self.b = nn.Parameter(torch.tensor(0.0, dtype=f64))
        self.w = nn.Parameter(torch.zeros(self.n_feat, dtype=f64))

    def init_affine(self, k: float, b: float, w: np.ndarray) -> None:
        with torch.no_grad():
            self.k.fill_(float(k))
            self.b.fill_(float(b))
            self.w.copy_(torch.as_tensor(np.asarray(w, float).reshape(-1)))

    def target(self, c: Tensor, f: Tensor) -> Tensor:
        """Target (...) from scaled command (...) and scaled features (..., F)."""
        t = self.k * c + self.b
        if self.n_feat:
            t = t + (f * self.w).sum(-1)
        return t


class Static(_Affine):
    """y = affine(command, features): no dynamics."""

    stepper_cls = StaticStepper

    def rollout(self, cmd, feat, y0):
        c = self.sc_cmd(cmd)
        return self.unsc_y(self.target(c, self.features_or_empty(feat, c.shape)))

    def init_state(self, cmd0, y0):
        return ()

    def step(self, state, cmd, feat):
        c = self.sc_cmd(cmd)
        return self.unsc_y(self.target(c, self.features_or_empty(feat, c.shape))), ()


class Lag1(_Affine):
    """First-order lag with one learnable time constant (see the module doc)."""

    stepper_cls = Lag1Stepper

    def __init__(self, spec, scaling, cfg) -> None:
        super().__init__(spec, scaling, cfg)
        f64 = torch.float64
        self.log_tau = nn.Parameter(torch.tensor(float(np.log(cfg.tau_init_s)), dtype=f64))
        self.v = nn.Parameter(torch.zeros(self.n_feat, dtype=f64))

    @property
    def tau(self) -> float:
        """The base time constant in s."""
        return float(torch.exp(self.log_tau))

    def drive(self, c: Tensor, f: Tensor) -> Tensor:
        """The lag's input t[k] (Hammerstein adds ψ)."""
        return self.target(c, f)

    def pole(self, f: Tensor) -> Tensor:
        """a[k] = exp(-dt/τ[k]) from scaled features (..., F) -> (...)."""
        lt = self.log_tau + ((f * self.v).sum(-1) if self.n_feat else 0.0)
        return torch.exp(-self.dt * torch.exp(-lt))

    def rollout(self, cmd, feat, y0):
        c = self.sc_cmd(cmd)
        f = self.features_or_empty(feat, c.shape)
        if c.shape[1] == 1:
            return y0[:, None].to(c.dtype)
        a = self.pole(f[:, :-1]) * torch.ones_like(c[:, :-1])
        u = self.drive(c[:, :-1], f[:, :-1])
        return self.unsc_y(scalar_scan(self.sc_y(y0.to(c.dtype)), a, (1.0 - a) * u))

    def init_state(self, cmd0, y0):
        return (self.sc_y(y0.to(self.c_off.dtype)),)

    def step(self, state, cmd, feat):
        (y,) = state
        c = self.sc_cmd(cmd)
        f = self.features_or_empty(feat, c.shape)
        a = self.pole(f)
        return self.unsc_y(y), (a * y + (1.0 - a) * self.drive(c, f),)


class Hammerstein(Lag1):
    """Static 1x8x8x1 perceptron (plus the affine bypass), then the first-order lag."""

    fit_family = "neural"  # its twin is Lag1Stepper with the perceptron

    def __init__(self, spec, scaling, cfg) -> None:
        super().__init__(spec, scaling, cfg)
        self.psi = tanh_mlp(1 + self.n_feat, tuple(cfg.hammerstein_hidden)).double()
        with torch.no_grad():  # start at the affine map: ψ's head off
            self.psi[-1].weight.mul_(0.1)
            self.psi[-1].bias.zero_()

    def drive(self, c, f):
        z = torch.cat([c[..., None], f], dim=-1)
        return self.target(c, f) + self.psi(z)[..., 0]


class Lag2(_Affine):
    """Second-order lag (τ2, ζ, K), exact zero-order-hold discretisation."""

    stepper_cls = Lag2Stepper

    def __init__(self, spec, scaling, cfg) -> None:
        super().__init__(spec, scaling, cfg)
        f64 = torch.float64
        self.log_tau2 = nn.Parameter(torch.tensor(float(np.log(cfg.tau2_init_s)), dtype=f64))
        self.log_zeta = nn.Parameter(torch.tensor(float(np.log(cfg.zeta_init)), dtype=f64))

    def discrete(self) -> tuple[Tensor, Tensor]:
        """(A (2, 2), Bv (2,)) of x[k+1] = A x[k] + Bv t[k], x = [p, p']."""
        return lag2_discrete(self.log_tau2, self.log_zeta, self.dt)

    def rollout(self, cmd, feat, y0):
        c = self.sc_cmd(cmd)
        B, T = c.shape
        if T == 1:
            return y0[:, None].to(c.dtype)
        f = self.features_or_empty(feat, c.shape)
        A, Bv = self.discrete()
        t = self.target(c[:, :-1], f[:, :-1])
        x0 = torch.stack([self.sc_y(y0.to(c.dtype)), torch.zeros_like(c[:, 0])], dim=-1)
        X = matrix_scan(x0, A.expand(B, T - 1, 2, 2), t[..., None] * Bv)
        return self.unsc_y(X[..., 0])

    def init_state(self, cmd0, y0):
        y = self.sc_y(y0.to(self.c_off.dtype))
        return (y, torch.zeros_like(y))

    def step(self, state, cmd, feat):
        p, r = state
        c = self.sc_cmd(cmd)
        t = self.target(c, self.features_or_empty(feat, c.shape))
        A, Bv = self.discrete()
        p1 = A[0, 0] * p + A[0, 1] * r + Bv[0] * t
        r1 = A[1, 0] * p + A[1, 1] * r + Bv[1] * t
        return self.unsc_y(p), (p1, r1)
