"""The monotone structured brake (``monolag``): a monotone static map, a dead time, a
second-order lag and, in the state-aware variants, a standstill hold.

In scaled units (:mod:`parknss.actuators.models`), with the request r = d·c̃ (d = ±1, the
sign of the static least-squares gain, fixed when the candidate is initialised: the brake
has d = -1, so a deeper deceleration request is a larger r):

* static map m(r) = b + Σ_j w_j·sp(β(r - q_j))/β, w_j = sp(ρ_j) >= 0, knots q_j evenly
  spread over [-1, 1] (``monolag_knots``), sp the softplus, β ``monolag_sharpness``:
  non-decreasing (and convex: a dead zone, then a gain) in r for any weights;
* dead time δ = D·σ(ρ_δ) samples in [0, D] (D = ``monolag_max_delay_s`` / dt), linearly
  interpolated between whole samples: m_d[k] = Σ_i λ_i·m[k - i], λ_i = max(0, 1 - |i - δ|)
  (history before k = 0 repeats m[0]);
* hold (only with a speed feature, ``speed`` or ``vx``: the ``phys`` and ``uniform``
  variants): gate g[k] = σ(β(r[k] - r_h))·σ((v_h - |vx[k]|)/v_w) (armed by a request at
  standstill; v_h = exp(ρ_v), or v_max·σ(ρ_v) below a ceiling ``monolag_hold_speed_max_ms``),
  filtered, g_f[0] = 0: while g[k] > g_f[k] (engaging) g_f[k+1] = a·g_f[k] + (1 - a)·g[k],
  a = exp(-dt/τ_on); else (releasing, as the car ramps its hold out at a launch) the same
  with a = exp(-dt/τ_off) (``monolag_release: exp``), or the linear ramp
  g_f[k+1] = max(g[k], g_f[k] - dt/τ_off) (``ramp``: a full hold is gone after τ_off, the
  shape of a chassis auto-hold's ramp-out); target t = max(m_d, b + H·g_f), H = sp(ρ_H)
  >= 0: the pressure floor of the chassis auto-hold, which no command explains;
* second-order lag p'' = ω²(t - p) - 2ζω p' (the ``lag2`` discretisation) with
  ζ = 1 + sp(ρ_ζ) >= 1 (no oscillation), p[0] = y0, y[k] = p[k] (reacts one sample later,
  like the lag family).

Properties by construction, for any parameter values (tests/actuators/test_monotone.py):
the steady state is non-decreasing in the request (non-negative weights, a non-negative
interpolation kernel, the max of non-decreasing terms, a lag of unit static gain); with
ζ >= 1 the lag's impulse response is non-negative, so a larger request at any time never
gives a lower output at any later time; and the model has no finite window a past command
can leave, so there is no pulse when one does (the 1 s NARX brake's phantom pulse,
docs/closed_loop.md). Every parameter stays free for fitting and co-tuning: the
constraints are the parameterisation, not a clamp.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from scipy.optimize import nnls
from torch import Tensor, nn

from parknss.actuators.lags import lag2_discrete
from parknss.actuators.models import ActuatorModel
from parknss.actuators.scan import matrix_scan
from parknss.actuators.steppers import MonoLagStepper

SPEED_FEATURES: tuple[str, ...] = ("speed", "vx")


def softplus(x: Tensor) -> Tensor:
    """log(1 + e^x), exact for every x (torch's softplus cuts off at x > 20)."""
    return torch.logaddexp(x, torch.zeros_like(x))


def inv_softplus(y: float) -> float:
    """x with softplus(x) = y > 0."""
    return float(y + math.log(-math.expm1(-y)))


def speed_index(features: tuple[str, ...]) -> int | None:
    """Index of the feature the hold gate reads (|vx|), None without one (``cmd``)."""
    for i, n in enumerate(features):
        if n in SPEED_FEATURES:
            return i
    return None


class MonoLag(ActuatorModel):
    """Monotone static map, dead time, second-order lag, standstill hold (module doc)."""

    stepper_cls = MonoLagStepper
    fit_family = "linear"

    def __init__(self, spec, scaling, cfg) -> None:
        super().__init__(spec, scaling, cfg)
        f64 = torch.float64
        K = cfg.monolag_knots
        self.beta = float(cfg.monolag_sharpness)
        self.max_delay = max(1, round(cfg.monolag_max_delay_s / self.dt))
        self.speed_idx = speed_index(spec.features)
        self.hold = self.speed_idx is not None
        self.v_width = float(cfg.monolag_hold_width_ms)
        self.release_ramp = cfg.monolag_release == "ramp"
        self.register_buffer("direction", torch.tensor(1.0, dtype=f64))
        self.register_buffer("knots", torch.linspace(-1.0, 1.0, K, dtype=f64))
        self.rho = nn.Parameter(torch.full((K,), -4.0, dtype=f64))
        self.b = nn.Parameter(torch.tensor(0.0, dtype=f64))
        frac = min(max(cfg.monolag_delay_init_s / self.dt / self.max_delay, 1e-3), 1 - 1e-3)
        self.rho_delay = nn.Parameter(torch.tensor(math.log(frac / (1 - frac)), dtype=f64))
        self.log_tau2 = nn.Parameter(torch.tensor(math.log(cfg.tau2_init_s), dtype=f64))
        self.rho_zeta = nn.Parameter(torch.tensor(inv_softplus(0.05), dtype=f64))
        if self.hold:
            self.rho_hold = nn.Parameter(torch.tensor(inv_softplus(0.5), dtype=f64))
            r_h = 2.0 * cfg.monolag_hold_request - 1.0  # fraction of the domain -> scaled r
            self.r_hold = nn.Parameter(torch.tensor(r_h, dtype=f64))
            self.v_hold_max = cfg.monolag_hold_speed_max_ms
            v0 = float(cfg.monolag_hold_speed_ms)
            if self.v_hold_max is None:
                self.log_v_hold = nn.Parameter(torch.tensor(math.log(v0), dtype=f64))
            else:  # bounded: v_h = v_max·σ(ρ), started at v0 (or near the ceiling)
                frac = min(max(v0 / self.v_hold_max, 1e-3), 1 - 1e-3)
                self.logit_v_hold = nn.Parameter(
                    torch.tensor(math.log(frac / (1 - frac)), dtype=f64))
            self.log_tau_hold = nn.Parameter(
                torch.tensor(math.log(cfg.monolag_hold_tau_s), dtype=f64))
            self.log_tau_release = nn.Parameter(
                torch.tensor(math.log(cfg.monolag_release_tau_s), dtype=f64))

    # ----------------------------------------------------------------- initialisation
    def init_affine(self, k: float, b: float, w: np.ndarray) -> None:
        """Start from the least-squares line: direction = sign(k), one ramp of gain |k|."""
        with torch.no_grad():
            self.direction.fill_(-1.0 if k < 0 else 1.0)
            self.rho.fill_(-4.0)
            self.rho[0] = inv_softplus(max(abs(float(k)), 1e-3))
            self.b.fill_(float(b) - abs(float(k)))

    def init_samples(self, cs: np.ndarray, fs: np.ndarray, ys: np.ndarray) -> None:
        """Refine the static map by non-negative least squares on the training samples
        (scaled command cs (N,), features fs (N, F), actual ys (N,)); the hold's floor
        starts at the median excess of the samples its gate arms."""
        r = float(self.direction) * cs
        q = self.knots.numpy()
        ramps = np.logaddexp(self.beta * (r[:, None] - q[None, :]), 0.0) / self.beta
        A = np.column_stack([ramps, np.ones_like(r), -np.ones_like(r)])
        sol, _ = nnls(A, ys)
        with torch.no_grad():
            self.rho.copy_(torch.as_tensor([inv_softplus(max(v, 1e-3)) for v in sol[:-2]]))
            self.b.fill_(float(sol[-2] - sol[-1]))
            if self.hold:
                speed = np.abs(fs[:, self.speed_idx] * self.scaling.f_sc[self.speed_idx]
                               + self.scaling.f_off[self.speed_idx])
                armed = (speed < float(self.hold_speed())) & (r > float(self.r_hold))
                excess = ys[armed] - float(self.b) if armed.any() else np.zeros(1)
                floor = float(np.median(excess)) if excess.size else 0.0
                self.rho_hold.fill_(inv_softplus(max(floor, 0.05)))

    # ----------------------------------------------------------------- pieces
    def static_map(self, r: Tensor) -> Tensor:
        """m(r), any shape."""
        ramps = softplus(self.beta * (r[..., None] - self.knots)) / self.beta
        return self.b + (ramps * softplus(self.rho)).sum(-1)

    def delay_kernel(self) -> Tensor:
        """λ (D + 1,), oldest first: the weight of m[k - D + j] at position j."""
        delta = self.max_delay * torch.sigmoid(self.rho_delay)
        lags = torch.arange(self.max_delay, -1, -1, dtype=self.b.dtype)
        return torch.clamp(1.0 - torch.abs(lags - delta), min=0.0)

    @property
    def delay_s(self) -> float:
        """The dead time in s."""
        return float(self.max_delay * torch.sigmoid(self.rho_delay)) * self.dt

    def discrete(self) -> tuple[Tensor, Tensor]:
        """(A (2, 2), Bv (2,)) of the lag, ζ = 1 + sp(ρ_ζ)."""
        return lag2_discrete(self.log_tau2, torch.log(1.0 + softplus(self.rho_zeta)), self.dt)

    def hold_speed(self) -> Tensor:
        """The hold gate's standstill threshold v_h in m/s (0-d): exp(ρ_v), or
        v_max·σ(ρ_v) < v_max with a ceiling (``monolag_hold_speed_max_ms``)."""
        if self.v_hold_max is None:
            return torch.exp(self.log_v_hold)
        return self.v_hold_max * torch.sigmoid(self.logit_v_hold)

    def gate(self, r: Tensor, feat: Tensor | None) -> Tensor:
        """The hold's arming gate g (same shape as r) from physical features (..., F)."""
        speed = torch.zeros_like(r) if feat is None else torch.abs(feat[..., self.speed_idx])
        armed = torch.sigmoid(self.beta * (r - self.r_hold))
        still = torch.sigmoid((self.hold_speed() - speed) / self.v_width)
        return armed * still

    def hold_rates(self) -> tuple[Tensor, Tensor]:
        """(a_on, off): the engage pole exp(-dt/τ_on), and the release pole exp(-dt/τ_off)
        (``exp``) or the release slope dt/τ_off per sample (``ramp``)."""
        on = torch.exp(-self.dt * torch.exp(-self.log_tau_hold))
        rate = self.dt * torch.exp(-self.log_tau_release)
        return on, rate if self.release_ramp else torch.exp(-rate)

    def hold_filter(self, gf: Tensor, g: Tensor, a_on: Tensor, off: Tensor) -> Tensor:
        """g_f[k+1] from g_f[k] and g[k] (B,): toward g with the engage pole when g is
        above g_f, else released by the pole or the ramp (continuous at g = g_f and
        non-decreasing in g and g_f either way)."""
        if self.release_ramp:
            up = a_on * gf + (1.0 - a_on) * g
            return torch.where(g > gf, up, torch.maximum(g, gf - off))
        a = torch.where(g > gf, a_on, off)
        return a * gf + (1.0 - a) * g

    def floor(self, gf: Tensor) -> Tensor:
        return self.b + softplus(self.rho_hold) * gf

    # ----------------------------------------------------------------- interface
    def rollout(self, cmd, feat, y0):
        r = self.direction * self.sc_cmd(cmd)
        B, T = r.shape
        if T == 1:
            return y0[:, None].to(r.dtype)
        m = self.static_map(r)
        D = self.max_delay
        win = torch.cat([m[:, :1].expand(-1, D), m], dim=1).unfold(1, D + 1, 1)
        t = (win * self.delay_kernel()).sum(-1)
        if self.hold:
            g = self.gate(r, feat)
            a_on, off = self.hold_rates()
            gfs = [torch.zeros_like(r[:, 0])]
            for k in range(T - 1):  # the asymmetric filter is not a linear scan
                gfs.append(self.hold_filter(gfs[-1], g[:, k], a_on, off))
            t = torch.maximum(t, self.floor(torch.stack(gfs, dim=1)))
        A, Bv = self.discrete()
        x0 = torch.stack([self.sc_y(y0.to(r.dtype)), torch.zeros_like(r[:, 0])], dim=-1)
        X = matrix_scan(x0, A.expand(B, T - 1, 2, 2), t[:, :-1, None] * Bv)
        return self.unsc_y(X[..., 0])

    def init_state(self, cmd0, y0):
        r0 = self.direction * self.sc_cmd(cmd0.to(self.c_off.dtype))
        hist = self.static_map(r0)[:, None].expand(-1, self.max_delay).clone()
        p = self.sc_y(y0.to(self.c_off.dtype))
        return (hist, torch.zeros_like(p), p, torch.zeros_like(p))

    def step(self, state, cmd, feat):
        hist, gf, p, pr = state
        r = self.direction * self.sc_cmd(cmd)
        win = torch.cat([hist, self.static_map(r)[:, None]], dim=1)
        t = (win * self.delay_kernel()).sum(-1)
        if self.hold:
            t = torch.maximum(t, self.floor(gf))
            gf = self.hold_filter(gf, self.gate(r, feat), *self.hold_rates())
        A, Bv = self.discrete()
        p1 = A[0, 0] * p + A[0, 1] * pr + Bv[0] * t
        r1 = A[1, 0] * p + A[1, 1] * pr + Bv[1] * t
        return self.unsc_y(p), (win[:, 1:], gf, p1, r1)
