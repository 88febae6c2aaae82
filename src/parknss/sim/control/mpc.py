"""Spatial preview MPC of the path-error dynamics with a first-order steering lag.

Along the travelled distance s (m) of one gear segment, in the *motion frame* (heading of
travel φ = heading, +π in reverse; motion curvature k = dφ/ds = direction·κ), the
linearised error dynamics of the rear axle about the reference path are

    d e_y / ds = e_φ,    d e_φ / ds = k_a - k_r(s),    d k_a / ds = (u - k_a) / λ,

with e_y the lateral offset (m, left of the travel direction), e_φ the heading error
(rad), k_a the executed motion curvature (1/m), u the commanded one and k_r the
reference's. The steering lag appears in distance: λ = T_s·|v| + σ (a steering-wheel lag
T_s in s at speed v, plus the tyre relaxation length σ), so the same model covers every
speed. Discretised exactly (zero-order hold in s over ``ds``), stacked over the horizon
N, the unconstrained quadratic cost

    Σ_k q_y e_y[k]² + q_φ e_φ[k]² + Σ_j r_u (u_j - k_r,j)² + r_Δ (u_j - u_{j-1})²,
    u_{-1} = k_a (the measured curvature),

has a closed-form minimiser linear in the state and the previewed reference curvature;
only its first move is applied (receding horizon). :class:`PreviewMpc` precomputes that
first-move gain for a geometric grid of λ, so a step costs one small dot product.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from parknss.config import StrictModel


class MpcConfig(StrictModel):
    """Weights and model of the preview MPC (lengths m, curvature 1/m)."""

    ds_m: float = Field(0.05, gt=0, description="spatial step of the prediction, m")
    horizon: int = Field(40, ge=2, description="prediction steps (preview = horizon·ds)")
    q_lateral: float = Field(20.0, ge=0, description="weight of e_y², 1/m²")
    q_heading: float = Field(2.0, ge=0, description="weight of e_φ², 1/rad²")
    r_curvature: float = Field(1.0, ge=0, description="weight of (u - k_r)², m²")
    r_rate: float = Field(10.0, ge=0, description="weight of (u_j - u_{j-1})², m²")
    steer_lag_s: float = Field(0.1, ge=0, description="assumed steering lag T_s, s")
    relaxation_m: float = Field(0.04, ge=0, description="assumed relaxation length σ, m")
    lag_min_m: float = Field(0.005, gt=0, description="smallest λ of the gain table, m")
    lag_max_m: float = Field(0.6, gt=0, description="largest λ of the gain table, m")
    lag_points: int = Field(32, ge=2, description="λ values in the gain table")


def discretise(lag_m: float, ds: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation over ``ds``: (A (3,3), B (3,), E (3,))."""
    from scipy.linalg import expm  # here: importing the closed loop (and its configs) for
    # `parknss plan` needs no scipy.linalg (0.2-0.4 s)
    lam = max(float(lag_m), 1e-9)
    m = np.zeros((5, 5))
    m[0, 1] = 1.0
    m[1, 2] = 1.0
    m[2, 2] = -1.0 / lam
    m[2, 3] = 1.0 / lam
    m[1, 4] = -1.0
    md = expm(m * ds)
    return md[:3, :3], md[:3, 3], md[:3, 4]


def first_move_gains(lag_m: float, cfg: MpcConfig) -> tuple[np.ndarray, np.ndarray]:
    """Gains (g_x (3,), g_r (N,)) with u_0 = g_x·[e_y, e_φ, k_a] + g_r·k_r[0:N]."""
    n = cfg.horizon
    a, b, e = discretise(lag_m, cfg.ds_m)
    phi = np.zeros((3 * n, 3))
    gam = np.zeros((3 * n, n))
    lam = np.zeros((3 * n, n))
    powers = [np.eye(3)]
    for _ in range(n):
        powers.append(a @ powers[-1])
    for k in range(1, n + 1):
        rows = slice(3 * (k - 1), 3 * k)
        phi[rows] = powers[k]
        for j in range(k):
            gam[rows, j] = powers[k - 1 - j] @ b
            lam[rows, j] = powers[k - 1 - j] @ e
    q = np.tile([cfg.q_lateral, cfg.q_heading, 0.0], n)
    d = np.eye(n) - np.eye(n, k=-1)
    h = gam.T @ (q[:, None] * gam) + cfg.r_curvature * np.eye(n) + cfg.r_rate * d.T @ d
    h0 = np.linalg.solve(h, np.eye(n)[:, 0])  # first row of H^-1 (H is symmetric)
    g_x = -h0 @ (gam.T @ (q[:, None] * phi))
    g_x[2] += cfg.r_rate * h0[0]
    g_r = h0 @ (cfg.r_curvature * np.eye(n) - gam.T @ (q[:, None] * lam))
    return g_x, g_r


_TABLES: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}


def gain_table(cfg: MpcConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(λ grid (L,), g_x (L, 3), g_r (L, N)) for ``cfg``, computed once per process."""
    key = cfg.digest()
    if key not in _TABLES:
        lags = np.geomspace(cfg.lag_min_m, max(cfg.lag_max_m, cfg.lag_min_m * 1.01), cfg.lag_points)
        gains = [first_move_gains(lag, cfg) for lag in lags]
        _TABLES[key] = (lags, np.array([g[0] for g in gains]), np.array([g[1] for g in gains]))
    return _TABLES[key]


class PreviewMpc:
    """First-move gains of the preview MPC, tabulated over the lag distance λ."""

    def __init__(self, cfg: MpcConfig | None = None) -> None:
        self.cfg = cfg or MpcConfig()
        c = self.cfg
        self.lags, self.g_x, self.g_r = gain_table(c)
        self._log_lags = np.log(self.lags)
        self.preview = np.arange(c.horizon) * c.ds_m

    def lag_distance(self, speed: float) -> float:
        """λ = T_s·|v| + σ, m, for a speed in m/s."""
        return self.cfg.steer_lag_s * abs(speed) + self.cfg.relaxation_m

    def command(self, state: np.ndarray, k_ref: np.ndarray, speed: float) -> float:
        """First motion-curvature command (1/m) for state [e_y, e_φ, k_a] and k_r (N,)."""
        lam = min(max(self.lag_distance(speed), self.lags[0]), self.lags[-1])
        i = int(np.argmin(np.abs(self._log_lags - np.log(lam))))
        return float(self.g_x[i] @ state + self.g_r[i] @ k_ref)
