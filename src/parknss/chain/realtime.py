"""The chain in real time: NumPy float64, one vehicle, one 10 ms sample per call.

:class:`NumpyNSS` is the NSS vehicle model's forward-Euler step and readout in NumPy
(weights copied once in float64); :class:`RealtimeChain` strings the input envelope, the
gear rule (:mod:`parknss.actuators.shift`), the three actuator steppers
(:mod:`parknss.actuators.steppers`), the output envelope
(:class:`parknss.actuators.envelopes.EnvelopeState`) and the NSS together with exactly the
arithmetic of :meth:`parknss.chain.model.Chain.rollout`, so the two agree to rounding over
whole trials (tests/chain/test_chain.py asserts 1e-10 in float64). :class:`NumpyNSS` is tested
on its own against :meth:`parknss.nss.model.NSSModel.step`, the one source of the NSS's
Euler step and yaw readout (tests/chain/test_chain.py).

Timing of one call ``step(gear, torque_cmd, decel_cmd, steer_cmd)`` at sample k: the
features of sample k are read from the NSS state x̂(k), and so is the vx of the gear rule
(the engaged gear of sample k; the drive command is 0 while a shift waits; a chain with
a measured drive channel takes the gear as given, see :mod:`parknss.chain.model`); the submodels
give the actuals
u(k); the outputs of sample k are the readout at (x̂(k), u(k)); the state advances to
x̂(k+1) = x̂(k) + dt·f(x̂(k), u(k)). This is the alignment of the logs (a command and the
state logged at the same sample), so ``step`` reproduces the batched rollout sample by
sample.
"""

from __future__ import annotations

import math

import numpy as np

from parknss.actuators.envelopes import Envelope, EnvelopeState
from parknss.actuators.models import ActuatorModel
from parknss.actuators.spec import CHANNELS, feature_values
from parknss.errors import CheckpointError
from parknss.nss.model import NSSModel
from parknss.nss.nets import numpy_layers, numpy_tanh_mlp


class NumpyNSS:
    """Forward-Euler step and readout of an :class:`~parknss.nss.model.NSSModel` in NumPy
    float64 (weights and scalings copied once): the real-time twin of
    :meth:`NSSModel.step`."""

    def __init__(self, model: NSSModel) -> None:
        if model.cfg.integrator != "euler":
            raise CheckpointError("the real-time chain implements the forward-Euler NSS only")
        self.dt = float(model.dt)
        self.state = numpy_layers(model.state_net)
        self.output = numpy_layers(model.output_net)
        self._z = np.zeros(self.state[0][0].shape[1])  # [x, u_s] buffer of the first layer
        self._g = np.zeros(5)  # [vx_s, yaw_s, torque_s, pressure_s, steer_s] output input

        def buf(name):
            return getattr(model, name).detach().double().numpy().copy()

        self.in_off, self.in_sc = buf("in_off"), buf("in_sc")
        self.in_lo, self.in_hi = buf("in_lo"), buf("in_hi")
        self.st_off, self.st_sc = buf("st_off"), buf("st_sc")
        self.st_lo, self.st_hi = buf("st_lo"), buf("st_hi")
        self.out_off, self.out_sc = buf("out_off"), buf("out_sc")
        g = model.geometry
        self.L, self.ratio = float(g.wheelbase), float(g.steer_ratio)
        self.residual = bool(model.cfg.residual_yaw)

        self._lo, self._hi = self.in_lo.tolist(), self.in_hi.tolist()
        self._off, self._sc = self.in_off.tolist(), self.in_sc.tolist()

    def scale_u(self, u) -> np.ndarray:
        """Scaled (clipped) input of physical u (4,); Python floats, one array at the end."""
        lo, hi, off, sc = self._lo, self._hi, self._off, self._sc
        return np.array([(min(max(u[i], lo[i]), hi[i]) - off[i]) / sc[i] for i in range(4)])

    def yaw_ref(self, vx_s: float, steer_s: float) -> float:
        """ω_ref in rad/s from scaled vx and scaled steering angle."""
        vx = vx_s * self.st_sc[0] + self.st_off[0]
        steer = steer_s * self.in_sc[3] + self.in_off[3]
        return vx / self.L * math.tan(steer / self.ratio * (math.pi / 180.0))

    def initial_state(self, x0: np.ndarray, u0: np.ndarray) -> np.ndarray:
        """Internal state from physical [vx, yaw] and physical u(0)."""
        x0s = (np.minimum(np.maximum(x0, self.st_lo), self.st_hi) - self.st_off) / self.st_sc
        if not self.residual:
            return x0s
        ref = self.yaw_ref(x0s[0], self.scale_u(u0)[3])
        ref_s = (ref - self.st_off[1]) / self.st_sc[1]
        return np.array([x0s[0], x0s[1] - ref_s])

    def yaw(self, x: np.ndarray, steer_s: float) -> tuple[float, float]:
        """(reconstructed scaled yaw, physical yaw) at state x and scaled steering."""
        if self.residual:
            ref_s = (self.yaw_ref(x[0], steer_s) - self.st_off[1]) / self.st_sc[1]
            ys = ref_s + x[1]
        else:
            ys = x[1]
        return ys, ys * self.st_sc[1] + self.st_off[1]

    def vx(self, x: np.ndarray) -> float:
        return x[0] * self.st_sc[0] + self.st_off[0]

    def readout(self, x: np.ndarray, us: np.ndarray) -> tuple[float, float, float, float]:
        """(vx m/s, yaw rad/s, ax, ay m/s²) at state x and scaled input us."""
        ys, yaw = self.yaw(x, us[3])
        h = self._g
        h[0], h[1] = x[0], ys
        h[2:] = us[1:]
        y = numpy_tanh_mlp(self.output, h)
        return (self.vx(x), yaw, y[0] * self.out_sc[0] + self.out_off[0],
                y[1] * self.out_sc[1] + self.out_off[1])

    def advance(self, x: np.ndarray, us: np.ndarray) -> np.ndarray:
        """x̂(k+1) = x̂(k) + dt·f([x̂(k), u(k)])."""
        z = self._z
        z[:2] = x
        z[2:] = us
        return x + self.dt * numpy_tanh_mlp(self.state, z)


_REST = np.zeros(2)  # [vx, yaw rate] of a car held at rest


class RealtimeChain:
    """Envelopes -> steppers -> NSS, one sample per call (see the module doc). ``gear_rule``
    (default True: a Plant's gear is a request) gates the gear by the shift-by-wire rule and
    applies the brake-hold latch (:mod:`parknss.actuators.envelopes`); False replays a
    log's engaged gear and the NSS as given (:mod:`parknss.chain.model`)."""

    def __init__(
        self,
        nss_model: NSSModel,
        models: dict[str, ActuatorModel | None],
        envelope: Envelope,
        gear_rule: bool = True,
    ) -> None:
        self.nss = NumpyNSS(nss_model)
        self.specs = {c: (m.spec if m is not None else None) for c, m in models.items()}
        self.steppers = {c: (m.stepper() if m is not None else None) for c, m in models.items()}
        self.env = EnvelopeState(envelope)
        # the gear rule gates a requested gear (closed loop); a replayed log's gear is engaged
        self.shift = (envelope.shift_rule() if gear_rule and models.get("drive") is not None
                      else None)
        self.gear = 0.0  # the engaged gear of the last sample
        self.dt = self.nss.dt
        self.full = all(m is not None for m in models.values())

    def _output_partial(self, ys: list[float]) -> tuple[float, float, float]:
        """Output envelope on the modelled channels only (measured ones pass as logged)."""
        t, p, s = self.env.output(*ys)
        out = (t, p, s)
        if self.specs["steering"] is None:
            self.env.steer_prev = ys[2]
        return tuple(o if self.specs[ch] is not None else y
                     for o, y, ch in zip(out, ys, CHANNELS, strict=True))

    def start(self, x0, y0, cmd0) -> None:
        """Initial state: x0 [vx, yaw], actuals y0 [torque, pressure, steer], command cmd0
        [gear, torque_cmd, decel_cmd, steer_cmd] that fills the histories; its gear (NaN: 0,
        as :func:`~parknss.actuators.envelopes.clean_commands` fills it) is engaged."""
        g0 = float(cmd0[0]) if math.isfinite(float(cmd0[0])) else 0.0
        self.env.reset(steer=float(y0[2]), gear=g0)
        g, c = self.env.command(g0, [float(v) for v in cmd0[1:]])
        self.env.reset(steer=float(y0[2]), gear=g)
        if self.shift is not None:
            self.shift.reset(g)
        self.gear = g
        for i, ch in enumerate(CHANNELS):
            s = self.steppers[ch]
            if s is not None:
                s.reset(c[i], float(y0[i]))
        self._x0 = np.asarray(x0, dtype=np.float64)
        self.x = None
        self.yaw_prev = float(x0[1])
        self.vx_now = float(x0[0])

    def step(
        self, gear: float, torque_cmd: float, decel_cmd: float, steer_cmd: float,
        measured=None,
    ):
        """One sample: returns (actuals (3,), (vx, yaw, ax, ay)). ``measured`` (3,) supplies
        the actuals of channels without a submodel (Phase B substitution)."""
        request, c = self.env.command(gear, [torque_cmd, decel_cmd, steer_cmd])
        vx, yaw = self.vx_now, self.yaw_prev
        g = request
        if self.shift is not None:
            g = self.shift.step(request, vx)
            if self.shift.shifting:
                c[0] = 0.0
        self.gear = g
        ys = []
        for i, ch in enumerate(CHANNELS):
            spec = self.specs[ch]
            if spec is None:
                ys.append(float(measured[i]))
                continue
            f = np.array(feature_values(spec.features, vx, yaw, g)) if spec.features else None
            ys.append(self.steppers[ch].step(c[i], f))
        act = self.env.output(*ys) if self.full else self._output_partial(ys)
        u = np.array([g, act[0], act[1], act[2]])
        us = self.nss.scale_u(u)
        if self.x is None:
            self.x = self.nss.initial_state(self._x0, u)
        out = self.nss.readout(self.x, us)
        self.x = self.nss.advance(self.x, us)
        self.vx_now = self.nss.vx(self.x)
        env = self.env.env
        if self.shift is not None and (env.held(act[1], self.vx_now)
                                       or env.stops(act[1], g, self.vx_now)):
            self.x = self.nss.initial_state(_REST, u)  # the brake latches (envelopes)
            self.vx_now = self.nss.vx(self.x)
        self.yaw_prev = self.nss.yaw(self.x, us[3])[1]
        return act, out

