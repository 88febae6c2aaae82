"""NumPy float64 real-time twins of the candidates: one sample per call, ring buffers.

``model.stepper()`` (each candidate class names its twin in ``stepper_cls``) copies a
fitted candidate's parameters into plain float64 arrays and returns a :class:`Stepper`:
``reset(c0, y0)`` (first command and measured actual, physical units) and
``step(c, f) -> y`` (command float, features (F,) array or None; returns the actual in
physical units). The arithmetic is the candidate's ``step`` written in NumPy (perceptrons
through :func:`parknss.nss.nets.numpy_tanh_mlp`), so a whole-trial replay equals
``rollout`` to rounding (tests/actuators/test_models.py, every architecture and variant).
No torch in the loop: a sample costs microseconds.
"""

from __future__ import annotations

import math

import numpy as np

from parknss.nss.nets import numpy_layers, numpy_tanh_mlp


class Stepper:
    """Base of the twins: the candidate's scalings as floats (subclasses add the dynamics)."""

    def __init__(self, model) -> None:
        p = model.numpy_params()
        self.p = p
        self.c_off, self.c_sc = float(p["c_off"]), float(p["c_sc"])
        self.f_off, self.f_sc = p["f_off"], p["f_sc"]
        self.y_off, self.y_sc = float(p["y_off"]), float(p["y_sc"])
        self.n_feat = model.n_feat
        self.dt = float(model.dt)
        self._fo, self._fs = self.f_off.tolist(), self.f_sc.tolist()

    def feats(self, f) -> np.ndarray:
        if self.n_feat == 0:
            return np.zeros(0)
        return (np.asarray(f, dtype=np.float64) - self.f_off) / self.f_sc

    def feats_list(self, f) -> list[float]:
        """Scaled features as Python floats (cheaper than NumPy for F <= 3)."""
        if self.n_feat == 0:
            return []
        return [(float(f[i]) - self._fo[i]) / self._fs[i] for i in range(self.n_feat)]

    def reset(self, c0: float, y0: float) -> None:
        """Start from the first command c0 and the measured actual y0 (physical units)."""
        raise NotImplementedError

    def step(self, c: float, f=None) -> float:
        """One sample: command c, features f (F,) or None -> the actual (physical units)."""
        raise NotImplementedError


def _dot(a: list[float], b: list[float]) -> float:
    return math.fsum(x * y for x, y in zip(a, b, strict=True))


class StaticStepper(Stepper):
    def __init__(self, model) -> None:
        super().__init__(model)
        self.k, self.b = float(self.p["k"]), float(self.p["b"])
        self.w = self.p["w"].tolist()

    def target(self, c: float, f: list[float]) -> float:
        t = self.k * c + self.b
        if self.n_feat:
            t = t + _dot(f, self.w)
        return t

    def reset(self, c0: float, y0: float) -> None:
        pass

    def step(self, c: float, f=None) -> float:
        cs = (c - self.c_off) / self.c_sc
        return self.target(cs, self.feats_list(f)) * self.y_sc + self.y_off


class Lag1Stepper(StaticStepper):
    def __init__(self, model) -> None:
        super().__init__(model)
        self.log_tau, self.v = float(self.p["log_tau"]), self.p["v"].tolist()
        psi = getattr(model, "psi", None)  # the Hammerstein perceptron
        self.psi = numpy_layers(psi) if psi is not None else None
        self.y = 0.0

    def reset(self, c0: float, y0: float) -> None:
        self.y = (y0 - self.y_off) / self.y_sc

    def step(self, c: float, f=None) -> float:
        cs = (c - self.c_off) / self.c_sc
        fs = self.feats_list(f)
        lt = self.log_tau + (_dot(fs, self.v) if self.n_feat else 0.0)
        a = math.exp(-self.dt * math.exp(-lt))
        u = self.target(cs, fs)
        if self.psi is not None:
            u = u + float(numpy_tanh_mlp(self.psi, np.array([cs, *fs]))[0])
        out = self.y * self.y_sc + self.y_off
        self.y = a * self.y + (1.0 - a) * u
        return out


class Lag2Stepper(StaticStepper):
    def __init__(self, model) -> None:
        super().__init__(model)
        A, Bv = model.discrete()
        self.A = A.detach().numpy().astype(np.float64)
        self.Bv = Bv.detach().numpy().astype(np.float64)
        self.pos = self.rate = 0.0

    def reset(self, c0: float, y0: float) -> None:
        self.pos, self.rate = (y0 - self.y_off) / self.y_sc, 0.0

    def step(self, c: float, f=None) -> float:
        t = self.target((c - self.c_off) / self.c_sc, self.feats_list(f))
        (a00, a01), (a10, a11) = self.A
        p, r = self.pos, self.rate
        out = p * self.y_sc + self.y_off
        self.pos = a00 * p + a01 * r + self.Bv[0] * t
        self.rate = a10 * p + a11 * r + self.Bv[1] * t
        return out


class NARXStepper(Stepper):
    """Ring buffer of the last n+1 scaled commands, kept twice so a window is one slice."""

    def __init__(self, model) -> None:
        super().__init__(model)
        self.n = model.lags + 1
        self.net = numpy_layers(model.net)
        self.skip_w, self.skip_b = self.p["skip.weight"][0], float(self.p["skip.bias"][0])
        self.buf = np.zeros(2 * self.n)
        self.i = 0

    def reset(self, c0: float, y0: float) -> None:
        self.buf[:] = (c0 - self.c_off) / self.c_sc
        self.i = 0

    def step(self, c: float, f=None) -> float:
        cs = (c - self.c_off) / self.c_sc
        self.buf[self.i] = self.buf[self.i + self.n] = cs
        self.i = (self.i + 1) % self.n
        win = self.buf[self.i : self.i + self.n]  # oldest .. newest
        z = np.concatenate([win, self.feats(f)]) if self.n_feat else win
        y = float(numpy_tanh_mlp(self.net, z)[0]) + float(self.skip_w @ z) + self.skip_b
        return y * self.y_sc + self.y_off


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-x))


class GRUStepper(Stepper):
    def __init__(self, model) -> None:
        super().__init__(model)
        p = self.p
        self.Wi, self.bi = p["rnn.weight_ih_l0"], p["rnn.bias_ih_l0"]
        self.Wh, self.bh = p["rnn.weight_hh_l0"], p["rnn.bias_hh_l0"]
        self.Wo, self.bo = p["out.weight"][0], float(p["out.bias"][0])
        self.H = model.hidden
        self.h = np.zeros(self.H)

    def reset(self, c0: float, y0: float) -> None:
        self.h = np.zeros(self.H)

    def inputs(self, c: float, f) -> np.ndarray:
        cs = (c - self.c_off) / self.c_sc
        return np.concatenate([[cs], self.feats(f)]) if self.n_feat else np.array([cs])

    def step(self, c: float, f=None) -> float:
        H, h = self.H, self.h
        gi = self.Wi @ self.inputs(c, f) + self.bi
        gh = self.Wh @ h + self.bh
        r = _sigmoid(gi[:H] + gh[:H])
        z = _sigmoid(gi[H : 2 * H] + gh[H : 2 * H])
        n = np.tanh(gi[2 * H :] + r * gh[2 * H :])
        self.h = (1.0 - z) * n + z * h
        return (float(self.Wo @ self.h) + self.bo) * self.y_sc + self.y_off


class LSTMStepper(GRUStepper):
    def reset(self, c0: float, y0: float) -> None:
        self.h = np.zeros(self.H)
        self.c = np.zeros(self.H)

    def step(self, c: float, f=None) -> float:
        H = self.H
        g = (self.Wi @ self.inputs(c, f) + self.bi) + (self.Wh @ self.h + self.bh)
        i = _sigmoid(g[:H])
        fg = _sigmoid(g[H : 2 * H])
        gg = np.tanh(g[2 * H : 3 * H])
        o = _sigmoid(g[3 * H :])
        self.c = fg * self.c + i * gg
        self.h = o * np.tanh(self.c)
        return (float(self.Wo @ self.h) + self.bo) * self.y_sc + self.y_off


def _softplus(x: float) -> float:
    return float(np.logaddexp(x, 0.0))


class MonoLagStepper(Stepper):
    """The monotone brake (:mod:`parknss.actuators.monotone`): the static map's last D + 1
    values in a doubled ring buffer, the hold filter, the lag's position and rate."""

    def __init__(self, model) -> None:
        super().__init__(model)
        p = self.p
        self.d = float(p["direction"])
        self.beta = model.beta
        self.knots = p["knots"]
        self.w = np.logaddexp(p["rho"], 0.0)
        self.b = float(p["b"])
        self.n = model.max_delay + 1
        self.lam = model.delay_kernel().detach().numpy().astype(np.float64)
        A, Bv = model.discrete()
        self.A = A.detach().numpy().astype(np.float64)
        self.Bv = Bv.detach().numpy().astype(np.float64)
        self.hold = model.hold
        if self.hold:
            self.idx = model.speed_idx
            self.H = _softplus(float(p["rho_hold"]))
            self.r_h = float(p["r_hold"])
            self.v_h = float(model.hold_speed().detach())
            self.v_w = model.v_width
            self.a_on = math.exp(-self.dt * math.exp(-float(p["log_tau_hold"])))
            self.ramp = model.release_ramp
            rate = self.dt * math.exp(-float(p["log_tau_release"]))
            self.off = rate if self.ramp else math.exp(-rate)  # slope or pole (monotone.py)
        self.buf = np.zeros(2 * self.n)
        self.i = 0
        self.gf = self.pos = self.rate = 0.0

    def static_map(self, r: float) -> float:
        ramps = np.logaddexp(self.beta * (r - self.knots), 0.0) / self.beta
        return self.b + float(np.sum(ramps * self.w))

    def reset(self, c0: float, y0: float) -> None:
        self.buf[:] = self.static_map(self.d * (c0 - self.c_off) / self.c_sc)
        self.i = 0
        self.gf, self.pos, self.rate = 0.0, (y0 - self.y_off) / self.y_sc, 0.0

    def step(self, c: float, f=None) -> float:
        r = self.d * (c - self.c_off) / self.c_sc
        m = self.static_map(r)
        self.buf[self.i] = self.buf[self.i + self.n] = m
        self.i = (self.i + 1) % self.n
        t = float(np.sum(self.buf[self.i : self.i + self.n] * self.lam))
        if self.hold:
            t = max(t, self.b + self.H * self.gf)
            speed = 0.0 if f is None else abs(float(f[self.idx]))
            g = (1.0 / (1.0 + math.exp(-self.beta * (r - self.r_h)))) * (
                1.0 / (1.0 + math.exp(-(self.v_h - speed) / self.v_w)))
            if g > self.gf:
                self.gf = self.a_on * self.gf + (1.0 - self.a_on) * g
            elif self.ramp:
                self.gf = max(g, self.gf - self.off)
            else:
                self.gf = self.off * self.gf + (1.0 - self.off) * g
        (a00, a01), (a10, a11) = self.A
        p, q = self.pos, self.rate
        out = p * self.y_sc + self.y_off
        self.pos = a00 * p + a01 * q + self.Bv[0] * t
        self.rate = a10 * p + a11 * q + self.Bv[1] * t
        return out
