"""``parknss export onnx``: one 10 ms step of the chain (or of the NSS alone) as an ONNX graph.

The graph has two float32 inputs and two outputs:

* chain (``--chain``): ``state`` (S,) and ``command`` (4,) [gear, torque_cmd N·m,
  decel_cmd m/s², steer_cmd deg] -> ``next_state`` (S,) and ``outputs`` (8,) [torque N·m,
  brake_pressure bar, steer deg, vx m/s, yaw_rate rad/s, ax, ay m/s², engaged gear];
* NSS (``--model``): ``state`` (2,) the NSS's scaled internal state and ``command`` (4,) the
  physical input u [gear, torque N·m, pressure bar, steer deg] -> ``next_state`` (2,) and
  ``outputs`` (4,) [vx, yaw_rate, ax, ay].

The chain state is laid out by :class:`StateLayout` (names in the graph's metadata
``state_names``): the input envelope's held commands and gear, the steering angle of the
output envelope, the gear rule's engaged gear and counter, whether the NSS has started,
the initial [vx, yaw], the NSS state and the previous vx and yaw rate, then each channel's
stepper state (lag: y; lag2: pos, rate; NARX: the command window, oldest first; GRU: h;
LSTM: h, c; the monotone brake: its static map's window, oldest first, the hold gate, pos,
rate). :func:`chain_state` packs a :class:`~parknss.chain.realtime.RealtimeChain`
(after ``start``: the initial state) into it; :func:`nss_initial_state` gives the NSS's.

The step is a torch module written from the real-time twin's float64 numbers
(:class:`ChainStep`, the same statements as :mod:`parknss.chain.ccode`, in float32 with
``where`` for the branches) and exported by torch's TorchScript ONNX exporter, then
checked by ``onnx.checker``. tests/export/test_onnx.py holds onnxruntime against the
NumPy twin at 1e-5.
"""

from __future__ import annotations

import io
import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import Tensor, nn

from parknss.actuators.spec import CHANNELS
from parknss.actuators.steppers import (
    GRUStepper,
    Lag1Stepper,
    Lag2Stepper,
    LSTMStepper,
    MonoLagStepper,
    NARXStepper,
    StaticStepper,
    Stepper,
)
from parknss.chain.realtime import NumpyNSS, RealtimeChain
from parknss.errors import CheckpointError, ParknssError
from parknss.nss.nets import NumpyLayers
from parknss.outputs import atomic_file, check_file_target
from parknss.signals import DT, kmh_to_ms

OPSET = 17
CORE: tuple[str, ...] = ("last_torque_cmd", "last_decel_cmd", "last_steer_cmd", "gear_request",
                         "steer_prev", "gear", "shift_count", "started", "vx0", "yaw0",
                         "x_vx", "x_yaw", "vx_now", "yaw_prev")


def _t(a) -> Tensor:
    return torch.as_tensor(np.asarray(a, dtype=np.float64), dtype=torch.float32)


def _stepper_names(ch: str, st: Stepper) -> list[str]:
    if isinstance(st, MonoLagStepper):
        return [*(f"{ch}.window{i}" for i in range(st.n)), f"{ch}.gate", f"{ch}.pos",
                f"{ch}.rate"]
    if isinstance(st, NARXStepper):
        return [f"{ch}.window{i}" for i in range(st.n)]
    if isinstance(st, LSTMStepper):
        return [f"{ch}.h{i}" for i in range(st.H)] + [f"{ch}.c{i}" for i in range(st.H)]
    if isinstance(st, GRUStepper):
        return [f"{ch}.h{i}" for i in range(st.H)]
    if isinstance(st, Lag2Stepper):
        return [f"{ch}.pos", f"{ch}.rate"]
    if isinstance(st, Lag1Stepper):
        return [f"{ch}.y"]
    if isinstance(st, StaticStepper):
        return []
    raise CheckpointError(f"no ONNX template for the {type(st).__name__} stepper")


@dataclass(frozen=True)
class StateLayout:
    """Names of the chain state vector's entries, in order."""

    names: tuple[str, ...]

    @classmethod
    def of(cls, rt: RealtimeChain) -> StateLayout:
        names = list(CORE)
        for ch in CHANNELS:
            names += _stepper_names(ch, rt.steppers[ch])
        return cls(tuple(names))

    def slice(self, prefix: str) -> slice:
        idx = [i for i, n in enumerate(self.names) if n.startswith(prefix + ".")]
        return slice(idx[0], idx[-1] + 1) if idx else slice(0, 0)


def chain_state(rt: RealtimeChain) -> np.ndarray:
    """The state vector (float64, :class:`StateLayout`) of a started RealtimeChain."""
    if not rt.full or rt.shift is None:
        raise CheckpointError("ONNX export needs a chain with all three submodels")
    env, sh = rt.env, rt.shift
    x = rt.x if rt.x is not None else np.zeros(2)
    v = [*env.last, env.gear, env.steer_prev, sh.gear, float(sh._count),
         float(rt.x is not None), *rt._x0, *x, rt.vx_now, rt.yaw_prev]
    for ch in CHANNELS:
        st = rt.steppers[ch]
        if isinstance(st, MonoLagStepper):
            v += [*st.buf[st.i : st.i + st.n].tolist(), st.gf, st.pos, st.rate]
        elif isinstance(st, NARXStepper):
            v += st.buf[st.i : st.i + st.n].tolist()
        elif isinstance(st, LSTMStepper):
            v += [*st.h, *st.c]
        elif isinstance(st, GRUStepper):
            v += list(st.h)
        elif isinstance(st, Lag2Stepper):
            v += [st.pos, st.rate]
        elif isinstance(st, Lag1Stepper):
            v.append(st.y)
    return np.asarray(v, dtype=np.float64)


class _MLP(nn.Module):
    def __init__(self, layers: NumpyLayers) -> None:
        super().__init__()
        self.w = [_t(W) for W, _ in layers]
        self.b = [_t(b) for _, b in layers]

    def forward(self, h: Tensor) -> Tensor:
        for W, b in zip(self.w[:-1], self.b[:-1], strict=True):
            h = torch.tanh(W @ h + b)
        return self.w[-1] @ h + self.b[-1]


class _NSS(nn.Module):
    """The NSS's Euler step and readout (NumpyNSS's statements) in float32."""

    def __init__(self, nss: NumpyNSS) -> None:
        super().__init__()
        self.f, self.g = _MLP(nss.state), _MLP(nss.output)
        for k in ("in_off", "in_sc", "in_lo", "in_hi", "st_off", "st_sc", "st_lo", "st_hi",
                  "out_off", "out_sc"):
            setattr(self, k, _t(np.nan_to_num(getattr(nss, k), posinf=3e38, neginf=-3e38)))
        self.dt, self.L, self.ratio = nss.dt, nss.L, nss.ratio
        self.residual = nss.residual

    def scale_u(self, u: Tensor) -> Tensor:
        return (torch.minimum(torch.maximum(u, self.in_lo), self.in_hi) - self.in_off) / self.in_sc

    def yaw_ref(self, vx_s: Tensor, steer_s: Tensor) -> Tensor:
        vx = vx_s * self.st_sc[0] + self.st_off[0]
        steer = steer_s * self.in_sc[3] + self.in_off[3]
        return vx / self.L * torch.tan(steer / self.ratio * (math.pi / 180.0))

    def yaw_s(self, x: Tensor, steer_s: Tensor) -> Tensor:
        if not self.residual:
            return x[1]
        return (self.yaw_ref(x[0], steer_s) - self.st_off[1]) / self.st_sc[1] + x[1]

    def initial(self, x0: Tensor, us: Tensor) -> Tensor:
        x0s = (torch.minimum(torch.maximum(x0, self.st_lo), self.st_hi) - self.st_off) / self.st_sc
        if not self.residual:
            return x0s
        ref_s = (self.yaw_ref(x0s[0], us[3]) - self.st_off[1]) / self.st_sc[1]
        return torch.stack([x0s[0], x0s[1] - ref_s])

    def step(self, x: Tensor, us: Tensor) -> tuple[Tensor, Tensor]:
        """(outputs [vx, yaw, ax, ay], next state)."""
        ys = self.yaw_s(x, us[3])
        y = self.g(torch.stack([x[0], ys, us[1], us[2], us[3]]))
        out = torch.stack([x[0] * self.st_sc[0] + self.st_off[0],
                           ys * self.st_sc[1] + self.st_off[1],
                           y[0] * self.out_sc[0] + self.out_off[0],
                           y[1] * self.out_sc[1] + self.out_off[1]])
        return out, x + self.dt * self.f(torch.cat([x, us]))


class NSSStep(nn.Module):
    """(state (2,), u (4,)) -> (next state (2,), [vx, yaw, ax, ay])."""

    def __init__(self, nss: NumpyNSS) -> None:
        super().__init__()
        self.nss = _NSS(nss)

    def forward(self, state: Tensor, command: Tensor) -> tuple[Tensor, Tensor]:
        out, nxt = self.nss.step(state, self.nss.scale_u(command))
        return nxt, out


class _Channel(nn.Module):
    """One stepper in float32 over its slice of the state."""

    def __init__(self, st: Stepper, features: tuple[str, ...]) -> None:
        super().__init__()
        self.st, self.features = st, features
        self.f_off, self.f_sc = _t(st.f_off), _t(st.f_sc)
        if isinstance(st, Lag1Stepper) and st.psi is not None:
            self.psi = _MLP(st.psi)
        if isinstance(st, NARXStepper):
            self.net = _MLP(st.net)
            self.skip_w = _t(st.skip_w)
        if isinstance(st, GRUStepper):
            self.Wi, self.bi, self.Wh, self.bh = (_t(st.Wi), _t(st.bi), _t(st.Wh), _t(st.bh))
            self.Wo = _t(st.Wo)
        if isinstance(st, MonoLagStepper):
            self.knots, self.mw, self.lam = _t(st.knots), _t(st.w), _t(st.lam)

    def feats(self, vx: Tensor, yaw: Tensor, g: Tensor) -> Tensor:
        src = {"speed": torch.abs(vx), "vx": vx, "yaw_rate": yaw, "gear": g}
        if not self.features:
            return torch.zeros(0)
        return (torch.stack([src[n] for n in self.features]) - self.f_off) / self.f_sc

    def target(self, cs: Tensor, fs: Tensor) -> Tensor:
        st = self.st
        t = st.k * cs + st.b
        return t + (fs * _t(st.w)).sum() if st.n_feat else t

    def forward(self, s: Tensor, c: Tensor, vx: Tensor, yaw: Tensor, g: Tensor
                ) -> tuple[Tensor, Tensor]:
        """(actual, next stepper state) from the stepper state s, command c, state."""
        st = self.st
        cs = (c - st.c_off) / st.c_sc
        fs = self.feats(vx, yaw, g)
        if isinstance(st, MonoLagStepper):
            return self._monolag(s, c, vx)
        if isinstance(st, NARXStepper):
            win = torch.cat([s[1:], cs.reshape(1)])
            z = torch.cat([win, fs])
            y = self.net(z)[0] + (self.skip_w * z).sum() + st.skip_b
            return y * st.y_sc + st.y_off, win
        if isinstance(st, GRUStepper):
            H, x = st.H, torch.cat([cs.reshape(1), fs])
            h = s[:H]
            gi, gh = self.Wi @ x + self.bi, self.Wh @ h + self.bh
            if isinstance(st, LSTMStepper):
                gsum = gi + gh
                i, f = torch.sigmoid(gsum[:H]), torch.sigmoid(gsum[H : 2 * H])
                gg, o = torch.tanh(gsum[2 * H : 3 * H]), torch.sigmoid(gsum[3 * H :])
                cc = f * s[H:] + i * gg
                h1 = o * torch.tanh(cc)
                nxt = torch.cat([h1, cc])
            else:
                r = torch.sigmoid(gi[:H] + gh[:H])
                z = torch.sigmoid(gi[H : 2 * H] + gh[H : 2 * H])
                n = torch.tanh(gi[2 * H :] + r * gh[2 * H :])
                h1 = nxt = (1.0 - z) * n + z * h
            return ((self.Wo * h1).sum() + st.bo) * st.y_sc + st.y_off, nxt
        if isinstance(st, Lag2Stepper):
            t = self.target(cs, fs)
            (a00, a01), (a10, a11) = (map(float, row) for row in st.A)
            b0, b1 = map(float, st.Bv)
            p, r = s[0], s[1]
            nxt = torch.stack([a00 * p + a01 * r + b0 * t, a10 * p + a11 * r + b1 * t])
            return p * st.y_sc + st.y_off, nxt
        if isinstance(st, Lag1Stepper):
            lt = st.log_tau + ((fs * _t(st.v)).sum() if st.n_feat else 0.0)
            a = torch.exp(-st.dt * torch.exp(torch.as_tensor(-lt, dtype=torch.float32)))
            u = self.target(cs, fs)
            if getattr(self, "psi", None) is not None:
                u = u + self.psi(torch.cat([cs.reshape(1), fs]))[0]
            return s[0] * st.y_sc + st.y_off, (a * s[0] + (1.0 - a) * u).reshape(1)
        return self.target(cs, fs) * st.y_sc + st.y_off, s

    def _monolag(self, s: Tensor, c: Tensor, vx: Tensor) -> tuple[Tensor, Tensor]:
        """The monotone brake: state [map window (n, oldest first), hold gate, pos, rate]."""
        st, n = self.st, self.st.n
        r = st.d * (c - st.c_off) / st.c_sc
        x = st.beta * (r - self.knots)
        ramps = (torch.clamp(x, min=0.0) + torch.log(1.0 + torch.exp(-torch.abs(x)))) / st.beta
        m = st.b + (ramps * self.mw).sum()
        win = torch.cat([s[1:n], m.reshape(1)])
        t, gf = (win * self.lam).sum(), s[n]
        if st.hold:
            t = torch.maximum(t, st.b + st.H * gf)
            gate = torch.sigmoid(st.beta * (r - st.r_h)) * torch.sigmoid(
                (st.v_h - torch.abs(vx)) / st.v_w)
            up = st.a_on * gf + (1.0 - st.a_on) * gate
            if st.ramp:
                down = torch.maximum(gate, gf - st.off)
            else:
                down = st.off * gf + (1.0 - st.off) * gate
            gf = torch.where(gate > gf, up, down)
        (a00, a01), (a10, a11) = (map(float, row) for row in st.A)
        b0, b1 = map(float, st.Bv)
        p, q = s[n + 1], s[n + 2]
        nxt = torch.stack([gf, a00 * p + a01 * q + b0 * t, a10 * p + a11 * q + b1 * t])
        return p * st.y_sc + st.y_off, torch.cat([win, nxt])


class ChainStep(nn.Module):
    """(state (S,), command (4,)) -> (next state (S,), outputs (8,)); see the module doc."""

    def __init__(self, rt: RealtimeChain) -> None:
        super().__init__()
        if not rt.full or rt.shift is None:
            raise CheckpointError("ONNX export needs a chain with all three submodels")
        self.layout = StateLayout.of(rt)
        e = rt.env.env
        if math.isfinite(e.stop_latch_bar):
            raise CheckpointError("ONNX export does not implement the brake-stop latch")
        self.lo, self.hi = _t(e.cmd_lo), _t(e.cmd_hi)
        self.env = e
        self.max_speed, self.n_shift = rt.shift.max_speed, float(rt.shift.n_shift)
        self.latch_bar = float(min(e.hold_latch_bar, 1.0e30))  # inf: never (float32-safe)
        self.latch_speed = kmh_to_ms(e.hold_latch_kmh)
        self.nss = _NSS(rt.nss)
        self.chans = nn.ModuleList(_Channel(rt.steppers[c], rt.specs[c].features)
                                   for c in CHANNELS)
        self.slices = [self.layout.slice(c) for c in CHANNELS]

    def forward(self, state: Tensor, command: Tensor) -> tuple[Tensor, Tensor]:
        s = state
        raw = command[1:]
        c = torch.clamp(torch.where(torch.isnan(raw), s[0:3], raw), self.lo, self.hi)
        request = torch.where(torch.isfinite(command[0]), command[0], s[3])
        vx, yaw, gear, count = s[12], s[13], s[5], s[6]
        differ = request != gear
        slow = torch.abs(vx) <= self.max_speed
        count1 = torch.where(differ & slow, count + 1.0, torch.zeros_like(count))
        engage = differ & slow & (count1 >= self.n_shift)
        g = torch.where(engage, request, gear)
        shifting = differ & slow & ~engage
        count1 = torch.where(engage, torch.zeros_like(count1), count1)
        cm = torch.stack([torch.where(shifting, torch.zeros_like(c[0]), c[0]), c[1], c[2]])
        ys, parts = [], []
        for i, ch in enumerate(self.chans):
            y, nxt = ch(s[self.slices[i]], cm[i], vx, yaw, g)
            ys.append(y)
            parts.append(nxt)
        e = self.env
        tq = torch.clamp(ys[0], min=e.torque_floor)
        pb = torch.clamp(ys[1], min=e.pressure_floor)
        step = e.steer_rate_dps * DT
        st = torch.clamp(torch.minimum(torch.maximum(ys[2], s[4] - step), s[4] + step),
                         -e.steer_lock, e.steer_lock)
        us = self.nss.scale_u(torch.stack([g, tq, pb, st]))
        x = torch.where(s[7] > 0.5, s[10:12], self.nss.initial(s[8:10], us))
        out, x1 = self.nss.step(x, us)
        # the brake-hold latch (parknss.actuators.envelopes): a held car is set to rest
        held = (pb >= self.latch_bar) & (
            torch.abs(x1[0] * self.nss.st_sc[0] + self.nss.st_off[0]) < self.latch_speed)
        x1 = torch.where(held, self.nss.initial(torch.zeros_like(s[8:10]), us), x1)
        yaw1 = self.nss.yaw_s(x1, us[3]) * self.nss.st_sc[1] + self.nss.st_off[1]
        vx1 = x1[0] * self.nss.st_sc[0] + self.nss.st_off[0]
        core = torch.stack([c[0], c[1], c[2], request, st, g, count1, torch.ones_like(g),
                            s[8], s[9], x1[0], x1[1], vx1, yaw1])
        nxt = torch.cat([core, *[p.reshape(-1) for p in parts]])
        return nxt, torch.cat([torch.stack([tq, pb, st]), out, g.reshape(1)])


def nss_initial_state(nss: NumpyNSS, x0, u0) -> np.ndarray:
    """The NSS graph's initial state from physical [vx, yaw] and the physical u(0)."""
    return nss.initial_state(np.asarray(x0, float), np.asarray(u0, float))


@dataclass(frozen=True)
class OnnxReport:
    """What was written: the path, the kind ("chain" or "nss"), the state names."""

    path: Path
    kind: str
    state_names: tuple[str, ...]

    def to_json(self) -> dict:
        return {"onnx": str(self.path), "kind": self.kind, "state_size": len(self.state_names)}


def step_module(model_dir: str | Path | None = None, chain_dir: str | Path | None = None
                ) -> tuple[nn.Module, int, tuple[str, ...], str]:
    """(module, state size, state names, kind) for an NSS folder or a chain artefact
    (neither: the shipped chain)."""
    if model_dir is not None and chain_dir is not None:
        raise ParknssError("give --model or --chain, not both")
    if model_dir is not None:
        from parknss.nss.checkpoint import load_model

        nss = NumpyNSS(load_model(model_dir).model.double())
        return NSSStep(nss), 2, ("x_vx", "x_yaw"), "nss"
    from parknss.chain.deployed import load_chain
    from parknss.config import SHIPPED_PLANT

    dep = load_chain(chain_dir if chain_dir is not None else SHIPPED_PLANT)
    mod = ChainStep(dep.rt)
    return mod, len(mod.layout.names), mod.layout.names, "chain"


def export_onnx(out: str | Path, model_dir: str | Path | None = None,
                chain_dir: str | Path | None = None, overwrite: bool = False) -> OnnxReport:
    """Write the step graph to ``out`` (atomically; an existing file refused unless
    ``overwrite``), checked by ``onnx.checker``."""
    import onnx

    out = check_file_target(out, overwrite=overwrite)  # before any work
    mod, n_state, names, kind = step_module(model_dir, chain_dir)
    buf = io.BytesIO()
    args = (torch.zeros(n_state), torch.zeros(4))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(mod, args, buf, dynamo=False, opset_version=OPSET,
                          input_names=["state", "command"],
                          output_names=["next_state", "outputs"])
    proto = onnx.load_from_string(buf.getvalue())
    onnx.helper.set_model_props(proto, {"kind": kind, "state_names": ",".join(names),
                                        "dt_s": str(DT), "producer": "parknss"})
    onnx.checker.check_model(proto, full_check=True)
    with atomic_file(out) as tmp:
        onnx.save(proto, str(tmp))
    return OnnxReport(out, kind, names)
