"""The least-squares linear baseline recovers a known affine state-space system exactly."""

from __future__ import annotations

import numpy as np
import pytest

from parknss.data.trial import Trial
from parknss.errors import DataError
from parknss.nss.linear import LinearSSM
from parknss.signals import DT

A = np.array([[0.97, 0.02], [-0.01, 0.93]])
B = np.array([[0.01, 2e-4, -3e-4, 1e-5], [0.002, -1e-5, 2e-5, 4e-4]])
c = np.array([0.003, -0.001])
C = np.array([[1.5, -0.2], [0.3, 2.0]])
D = np.array([[0.1, 0.004, -0.02, 1e-3], [-0.05, 1e-3, 5e-3, 2e-3]])
d = np.array([0.05, -0.02])


def _system_trial(n, seed, tid):
    rng = np.random.default_rng(seed)
    u = np.column_stack(
        [
            rng.integers(-1, 2, n).astype(float),  # gear
            rng.normal(50.0, 40.0, n),  # torque N·m
            np.abs(rng.normal(0.0, 10.0, n)),  # brake bar
            rng.normal(0.0, 200.0, n),  # steer deg
        ]
    )
    x = np.empty((n, 2))
    x[0] = rng.normal(0.0, 0.5, 2)
    for k in range(n - 1):
        x[k + 1] = A @ x[k] + B @ u[k] + c
    y = x @ C.T + u @ D.T + d
    names = ("gear", "torque", "brake_pressure", "steer")
    ch = {"t": np.arange(n) * DT, **{nm: u[:, j] for j, nm in enumerate(names)}}
    ch.update(vx=x[:, 0], yaw_rate=x[:, 1], ax=y[:, 0], ay=y[:, 1])
    return Trial(tid, "park_in_left", seed, ch), x, u, y


def test_recovers_the_system():
    trials = [_system_trial(300, s, f"t{s}")[0] for s in (1, 2, 3)]
    m = LinearSSM.fit(trials)
    for got, want in ((m.A, A), (m.B, B), (m.c, c), (m.C, C), (m.D, D), (m.d, d)):
        assert got.shape == want.shape
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-8)
    assert m.spectral_radius() == pytest.approx(max(abs(np.linalg.eigvals(A))), abs=1e-9)


def test_rollout_matches_a_hand_loop_and_the_data():
    tr, x, u, y = _system_trial(250, 4, "t4")
    m = LinearSSM.fit([_system_trial(300, 5, "t5")[0]])
    xs, ys = m.rollout(x[0], u)
    xh = [x[0]]
    for k in range(len(u) - 1):
        xh.append(m.A @ xh[-1] + m.B @ u[k] + m.c)
    xh = np.array(xh)
    np.testing.assert_allclose(xs, xh, rtol=0, atol=1e-13)
    np.testing.assert_allclose(ys, xh @ m.C.T + u @ m.D.T + m.d, rtol=0, atol=1e-13)
    # identified on another trial, it predicts this one open loop
    p = m.predict_trials([tr])["t4"]
    np.testing.assert_allclose(p["vx"], x[:, 0], atol=1e-7)
    np.testing.assert_allclose(p["ay"], y[:, 1], atol=1e-7)


def test_no_trials():
    with pytest.raises(DataError):
        LinearSSM.fit([])
