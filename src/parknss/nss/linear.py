"""The linear state-space baseline of Table II, fitted by least squares.

    x[k+1] = A x[k] + B u[k] + c,     y[k] = C x[k] + D u[k] + d

with x = [vx, ω_z], u = [gear, torque, brake_pressure, steer], y = [ax, ay], in schema
units. (A, B, c) minimise the one-step prediction error over all consecutive sample
pairs of the training trials and (C, D, d) the output error over all their samples
(ordinary least squares, columns scaled to unit RMS for conditioning). The offsets c, d
let the model represent sensor offsets; on exactly linear data they come out zero. The
model is then rolled out open loop from the true initial state, like the NSS.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from parknss.data.trial import Trial
from parknss.errors import DataError
from parknss.signals import ACTUAL_CHANNELS, OUTPUT_CHANNELS, STATE_CHANNELS


def _lstsq(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """argmin ||X·Θ - Y|| with column scaling; Θ (n_in, n_out)."""
    s = np.sqrt(np.mean(X * X, axis=0))
    s[s == 0.0] = 1.0
    theta, *_ = np.linalg.lstsq(X / s, Y, rcond=None)
    return theta / s[:, None]


@dataclass
class LinearSSM:
    """Affine discrete-time state-space model (see the module docstring); float64."""

    A: np.ndarray
    B: np.ndarray
    c: np.ndarray
    C: np.ndarray
    D: np.ndarray
    d: np.ndarray

    @classmethod
    def fit(cls, trials: Iterable[Trial]) -> LinearSSM:
        trials = list(trials)
        if not trials:
            raise DataError("no trials to fit the linear baseline on")
        xs, us, xn, ys, xa, ua = [], [], [], [], [], []
        for tr in trials:
            x, u, y = tr.array(STATE_CHANNELS), tr.array(ACTUAL_CHANNELS), tr.array(OUTPUT_CHANNELS)
            xs.append(x[:-1])
            us.append(u[:-1])
            xn.append(x[1:])
            xa.append(x)
            ua.append(u)
            ys.append(y)
        X1 = np.concatenate(xs)
        one = np.ones((len(X1), 1))
        th = _lstsq(np.hstack([X1, np.concatenate(us), one]), np.concatenate(xn))
        Xa = np.concatenate(xa)
        th_y = _lstsq(
            np.hstack([Xa, np.concatenate(ua), np.ones((len(Xa), 1))]), np.concatenate(ys)
        )
        nx = X1.shape[1]
        return cls(A=th[:nx].T, B=th[nx:-1].T, c=th[-1], C=th_y[:nx].T, D=th_y[nx:-1].T, d=th_y[-1])

    def rollout(self, x0: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Open loop from x0 (2,) over u (T, 4): states (T, 2) and outputs (T, 2)."""
        T = len(u)
        drive = u @ self.B.T + self.c
        x = np.empty((T, len(x0)))
        x[0] = x0
        for k in range(T - 1):
            x[k + 1] = self.A @ x[k] + drive[k]
        y = x @ self.C.T + u @ self.D.T + self.d
        return x, y

    def predict_trials(self, trials: Iterable[Trial]) -> dict[str, dict[str, np.ndarray]]:
        """Open-loop predictions {trial id: {vx, yaw_rate, ax, ay}} from the true x(0)."""
        out = {}
        for tr in trials:
            x, y = self.rollout(tr.array(STATE_CHANNELS)[0], tr.array(ACTUAL_CHANNELS))
            out[tr.id] = {"vx": x[:, 0], "yaw_rate": x[:, 1], "ax": y[:, 0], "ay": y[:, 1]}
        return out

    def spectral_radius(self) -> float:
        return float(np.max(np.abs(np.linalg.eigvals(self.A))))
