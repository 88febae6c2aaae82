"""The physics-informed neural state-space model of paper §II (Fig. 1).

Internal state x̂ = [v̂x, ω_res] in scaled units, input u = [gear, τ_m, p_b, δ_sw]:

    x̂(0)       = [vx(0), ω_z(0) - ω_ref(0)]                    (eq. 3a, 5)
    x̂(k+1)     = x̂(k) + Δt · f_θ([x̂(k), u(k)])               (eq. 3b, forward Euler)
    ω̂_z(k)     = ω_ref(v̂x(k), δ_sw(k)) + ω_res(k)             (eq. 5, the readout)
    [ax, ay](k) = g_φ([v̂x, ω̂_z, τ_m, p_b, δ_sw](k))           (eq. 3c, no gear)

f and g are tanh MLPs (6x128 and 3x128 by default). Everything the networks see is scaled
by the model's :class:`~parknss.data.normalize.Normalizer`; the kinematic prior
ω_ref = vx/L·tan(δ_sw/i_sw) (:func:`parknss.vehicle.yaw_rate_ref`, constant ratio) is
computed in physical units (unscale v̂x and δ_sw, compute, rescale with the yaw-rate
scaling). The residual state is kept in yaw-rate scaled units without offset, so
ω̂_z,scaled = ω_ref,scaled + ω_res,scaled. With ``residual_yaw=False`` (the ablation's
direct-yaw variant) the second state is the scaled yaw rate itself.

:meth:`NSSModel.rollout` is the one rollout used by training, evaluation and the
simulator; :meth:`NSSModel.step` advances one sample in real time and reproduces
``rollout`` step by step. Midpoint and RK4 hold u constant over the step. The Euler step
(:meth:`NSSModel.integrate`, :meth:`NSSModel.step_function`) and the yaw readout
(:meth:`NSSModel.reconstruct_yaw`) are written here once: the chain's interleaved rollout
calls them, and the NumPy real-time twin (:class:`parknss.chain.realtime.NumpyNSS`) is
tested against :meth:`NSSModel.step` (tests/chain/test_chain.py).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import Tensor, nn

from parknss.data.normalize import Normalizer
from parknss.errors import DataError
from parknss.nss.config import ModelConfig
from parknss.nss.fused import FusedEulerRollout, euler_forward
from parknss.nss.fused_mlp import FusedTanhMLP
from parknss.nss.nets import linear_layers, tanh_mlp
from parknss.signals import ACTUAL_CHANNELS, OUTPUT_CHANNELS, STATE_CHANNELS
from parknss.vehicle import VehicleGeometry, yaw_rate_ref

INPUTS: tuple[str, ...] = ACTUAL_CHANNELS  # gear, torque, brake_pressure, steer
STATES: tuple[str, ...] = STATE_CHANNELS  # vx, yaw_rate
OUTPUTS: tuple[str, ...] = OUTPUT_CHANNELS  # ax, ay
NORMALIZED: tuple[str, ...] = (*INPUTS, *STATES, *OUTPUTS)
I_GEAR, I_TORQUE, I_BRAKE, I_STEER = range(4)

# A limiter maps (next scaled state (B, 2), scaled input of the step (B, 4)) -> state.
StateLimiter = Callable[[Tensor, Tensor], Tensor]


@dataclass
class Rollout:
    """One (batched) open-loop prediction; every field (B, T).

    Physical: vx m/s, yaw_rate rad/s (reconstructed), yaw_res rad/s (ω̂_z - ω_ref),
    ax, ay m/s². Scaled (the losses' space): vx_s, yaw_s (reconstructed), yaw_ref_s
    (ω_ref at the predicted vx), ax_s, ay_s; state_s (B, T, 2) is the internal state.
    """

    vx: Tensor
    yaw_rate: Tensor
    yaw_res: Tensor
    ax: Tensor
    ay: Tensor
    vx_s: Tensor
    yaw_s: Tensor
    yaw_ref_s: Tensor
    ax_s: Tensor
    ay_s: Tensor
    state_s: Tensor

    def channels(self) -> dict[str, Tensor]:
        """The physical predictions by schema channel name."""
        return {"vx": self.vx, "yaw_rate": self.yaw_rate, "ax": self.ax, "ay": self.ay}


def _affine(norm: Normalizer, names: tuple[str, ...]) -> tuple[Tensor, ...]:
    off = torch.tensor([norm.channels[n].offset for n in names], dtype=torch.float64)
    sc = torch.tensor([norm.channels[n].scale for n in names], dtype=torch.float64)
    inf = float("inf")
    lo = [norm.channels[n].clip_lo for n in names]
    hi = [norm.channels[n].clip_hi for n in names]
    lo_t = torch.tensor([-inf if v is None else v for v in lo], dtype=torch.float64)
    hi_t = torch.tensor([inf if v is None else v for v in hi], dtype=torch.float64)
    return off, sc, lo_t, hi_t


class NSSModel(nn.Module):
    """State net f, output net g, the yaw readout and the scaling (see the module doc)."""

    def __init__(
        self,
        cfg: ModelConfig,
        normalizer: Normalizer,
        geometry: VehicleGeometry | None = None,
    ) -> None:
        super().__init__()
        missing = [n for n in NORMALIZED if n not in normalizer.channels]
        if missing:
            raise DataError(f"normalizer lacks channel(s) {', '.join(missing)}")
        self.cfg = cfg
        self.normalizer = normalizer
        self.geometry = geometry or VehicleGeometry()
        self.dt = float(cfg.dt)
        self.state_net = tanh_mlp(2 + len(INPUTS), (cfg.state_units,) * cfg.state_layers, 2)
        self.output_net = tanh_mlp(5, (cfg.output_units,) * cfg.output_layers, 2)
        self._refresh_scaling()

    def _refresh_scaling(self) -> None:
        """(Re)build the scaling buffers from the float64 normalizer in the weights' dtype."""
        dtype = self.state_net[0].weight.dtype
        for prefix, names in (("in", INPUTS), ("st", STATES), ("out", OUTPUTS)):
            for key, t in zip(
                ("off", "sc", "lo", "hi"), _affine(self.normalizer, names), strict=True
            ):
                self.register_buffer(f"{prefix}_{key}", t.to(dtype), persistent=False)

    def _apply(self, fn, recurse: bool = True):
        """After .to()/.double()/.float(): rebuild the buffers from the exact statistics."""
        out = super()._apply(fn, recurse)
        if hasattr(self, "normalizer") and "state_net" in self._modules:
            self._refresh_scaling()
        return out

    @property
    def dtype(self) -> torch.dtype:
        return self.state_net[0].weight.dtype

    # ----------------------------------------------------------------- scaling
    def _scale(self, x: Tensor, prefix: str, clip: bool = True) -> Tensor:
        off, sc = getattr(self, f"{prefix}_off"), getattr(self, f"{prefix}_sc")
        if clip:
            x = torch.clamp(x, getattr(self, f"{prefix}_lo"), getattr(self, f"{prefix}_hi"))
        return (x - off) / sc

    def scale_inputs(self, u: Tensor) -> Tensor:
        """Physical inputs (..., 4) [gear, N·m, bar, deg] -> scaled (clipped)."""
        return self._scale(u, "in")

    def scale_states(self, x: Tensor) -> Tensor:
        """Physical [vx m/s, yaw rad/s] (..., 2) -> scaled (clipped)."""
        return self._scale(x, "st")

    def scale_outputs(self, y: Tensor) -> Tensor:
        """Physical [ax, ay] m/s² (..., 2) -> scaled (clipped)."""
        return self._scale(y, "out")

    def vx_phys(self, vx_s: Tensor) -> Tensor:
        return vx_s * self.st_sc[0] + self.st_off[0]

    def yaw_phys(self, yaw_s: Tensor) -> Tensor:
        return yaw_s * self.st_sc[1] + self.st_off[1]

    def yaw_scaled(self, yaw: Tensor) -> Tensor:
        """Physical yaw rate -> scaled, without the clip (for predictions and the prior)."""
        return (yaw - self.st_off[1]) / self.st_sc[1]

    def vx_zero_s(self) -> Tensor:
        """The scaled image of vx = 0 (the origin of the gear-conditioned loss)."""
        return -self.st_off[0] / self.st_sc[0]

    def yaw_ref(self, vx_s: Tensor, steer_s: Tensor) -> Tensor:
        """Kinematic prior ω_ref in rad/s from scaled vx and scaled steering angle."""
        steer = steer_s * self.in_sc[I_STEER] + self.in_off[I_STEER]
        return yaw_rate_ref(self.vx_phys(vx_s), steer, self.geometry)

    # ------------------------------------------------------------ dynamics
    def derivative(self, x_s: Tensor, u_s: Tensor) -> Tensor:
        """f_θ([x̂, u]): dx̂/dt in scaled units per second, (B, 2)."""
        return self.state_net(torch.cat([x_s, u_s], dim=-1))

    def step_function(self) -> Callable[[Tensor, Tensor], Tensor]:
        """:meth:`integrate` for per-sample loops: (x_s (B, 2), u_s (B, 4)) -> x_s (B, 2).

        Forward Euler x̂ + dt·f([x̂, u_s]) with the state net's weights taken out of the
        modules once: the same addmm/tanh sequence ``nn.Linear`` runs on 2-D inputs, without
        the module-call overhead (the chain's interleaved rollout). Other integrators:
        :meth:`integrate` itself. Snapshot of the weights: call again after they change.
        """
        if self.cfg.integrator != "euler":
            return self.integrate
        wts = [(m.bias, m.weight.t()) for m in linear_layers(self.state_net)]
        dt = self.dt

        def step(x_s: Tensor, u_s: Tensor) -> Tensor:
            h = torch.cat([x_s, u_s], dim=-1)
            for b, wt in wts[:-1]:
                h = torch.tanh(torch.addmm(b, h, wt))
            b, wt = wts[-1]
            return x_s + dt * torch.addmm(b, h, wt)

        return step

    def integrate(self, x_s: Tensor, u_s: Tensor, dt: float | None = None) -> Tensor:
        """One step of the configured integrator, u held over the step; (B, 2). ``dt``: the
        step in s (default the model's, ``model.dt``)."""
        dt = self.dt if dt is None else dt
        f = self.derivative
        if self.cfg.integrator == "euler":
            return x_s + dt * f(x_s, u_s)
        if self.cfg.integrator == "midpoint":
            return x_s + dt * f(x_s + 0.5 * dt * f(x_s, u_s), u_s)
        k1 = f(x_s, u_s)
        k2 = f(x_s + 0.5 * dt * k1, u_s)
        k3 = f(x_s + 0.5 * dt * k2, u_s)
        k4 = f(x_s + dt * k3, u_s)
        return x_s + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)

    def initial_state_scaled(self, x0: Tensor, u0_s: Tensor) -> Tensor:
        """Internal scaled state from the measured [vx, yaw] (B, 2) and the scaled u(0)."""
        x0_s = self.scale_states(x0)
        if not self.cfg.residual_yaw:
            return x0_s
        ref_s = self.yaw_scaled(self.yaw_ref(x0_s[:, 0], u0_s[:, I_STEER]))
        return torch.stack([x0_s[:, 0], x0_s[:, 1] - ref_s], dim=-1)

    def _fused(self, x0_s: Tensor, u_s: Tensor, dt: float) -> Tensor:
        """Internal states (B, T, 2) by the fused Euler kernel (see parknss.nss.fused)."""
        lin = linear_layers(self.state_net)
        U = u_s[:, :-1].transpose(0, 1).contiguous()
        hidden = [t for m in lin[1:-1] for t in (m.weight, m.bias)]
        args = (x0_s, U, lin[0].weight, lin[0].bias, lin[-1].weight, lin[-1].bias)
        needs_grad = x0_s.requires_grad or U.requires_grad
        needs_grad = needs_grad or any(p.requires_grad for p in self.state_net.parameters())
        kernels = self.kernels()
        if torch.is_grad_enabled() and needs_grad:
            X = FusedEulerRollout.apply(dt, kernels, *args, *hidden)
        else:
            X = euler_forward(*args, hidden[0::2], hidden[1::2], dt=dt, kernels=kernels)
        return X.transpose(0, 1)

    def kernels(self) -> str:
        """The fused kernels this model runs: ``cfg.fused_kernels``, except that a model in
        a dtype other than float32 (a chain's float64 copy, an evaluation in float64) runs
        the ``reference`` kernels where its config names the float32-only ``native`` ones
        (the config forbids training so: :class:`~parknss.nss.config.NSSConfig`)."""
        if self.cfg.fused_kernels == "native" and self.dtype != torch.float32:
            return "reference"
        return self.cfg.fused_kernels

    def _eager(
        self, x0_s: Tensor, u_s: Tensor, limiter: StateLimiter | None, dt: float
    ) -> Tensor:
        """Internal states (B, T, 2) by the plain per-step loop (any integrator)."""
        xs = [x0_s]
        x = x0_s
        for k in range(u_s.shape[1] - 1):
            x = self.integrate(x, u_s[:, k], dt)
            if limiter is not None:
                x = limiter(x, u_s[:, k])
            xs.append(x)
        return torch.stack(xs, dim=1)

    def engine_for(self, limiter: StateLimiter | None, engine: str | None = None) -> str:
        """Which recurrence engine a rollout uses ("fused" or "eager")."""
        engine = engine or self.cfg.engine
        if engine == "auto":
            fusable = self.cfg.integrator == "euler" and limiter is None
            return "fused" if fusable else "eager"
        if engine == "fused" and (self.cfg.integrator != "euler" or limiter is not None):
            raise DataError("the fused engine supports forward Euler without a limiter only")
        return engine

    # -------------------------------------------------------------- readout
    def output(self, g_in: Tensor, fused: bool = False) -> Tensor:
        """Output network g_φ on (..., 5) -> (..., 2); ``fused`` uses FusedTanhMLP."""
        if not (fused and torch.is_grad_enabled()):
            return self.output_net(g_in)
        lin = linear_layers(self.output_net)
        params = [t for m in lin for t in (m.weight, m.bias)]
        flat = g_in.reshape(-1, g_in.shape[-1]).contiguous()
        return FusedTanhMLP.apply(self.kernels(), flat, *params).view(*g_in.shape[:-1], -1)

    def reconstruct_yaw(self, X_s: Tensor, steer_s: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """The yaw readout (eq. 5) at internal states X_s (..., 2) and scaled steering (...):
        (ω_ref rad/s, ω_ref scaled, reconstructed ω̂_z scaled), each (...). With
        ``residual_yaw=False`` the second state is the scaled yaw rate itself."""
        ref = self.yaw_ref(X_s[..., 0], steer_s)
        ref_s = self.yaw_scaled(ref)
        yaw_s = ref_s + X_s[..., 1] if self.cfg.residual_yaw else X_s[..., 1]
        return ref, ref_s, yaw_s

    def readout(self, X_s: Tensor, u_s: Tensor, fused: bool = False) -> Rollout:
        """Yaw reconstruction and output network on states (B, T, 2), inputs (B, T, 4)."""
        vx_s = X_s[..., 0]
        ref, ref_s, yaw_s = self.reconstruct_yaw(X_s, u_s[..., I_STEER])
        g_in = torch.stack(
            [vx_s, yaw_s, u_s[..., I_TORQUE], u_s[..., I_BRAKE], u_s[..., I_STEER]], dim=-1
        )
        y_s = self.output(g_in, fused)
        yaw = self.yaw_phys(yaw_s)
        return Rollout(
            vx=self.vx_phys(vx_s),
            yaw_rate=yaw,
            yaw_res=yaw - ref,
            ax=y_s[..., 0] * self.out_sc[0] + self.out_off[0],
            ay=y_s[..., 1] * self.out_sc[1] + self.out_off[1],
            vx_s=vx_s,
            yaw_s=yaw_s,
            yaw_ref_s=ref_s,
            ax_s=y_s[..., 0],
            ay_s=y_s[..., 1],
            state_s=X_s,
        )

    # -------------------------------------------------------------- public
    def _check(self, x0: Tensor, u: Tensor) -> None:
        if x0.ndim != 2 or x0.shape[1] != 2:
            raise DataError(f"initial state must be (B, 2) [vx, yaw_rate], got {tuple(x0.shape)}")
        if u.ndim != 3 or u.shape[2] != len(INPUTS) or u.shape[0] != x0.shape[0]:
            raise DataError(f"inputs must be (B, T, 4) {list(INPUTS)}, got {tuple(u.shape)}")
        if u.shape[1] < 1:
            raise DataError("inputs have no samples")

    def rollout(
        self,
        x0: Tensor,
        u: Tensor,
        limiter: StateLimiter | None = None,
        engine: str | None = None,
        stride: int = 1,
    ) -> Rollout:
        """Open-loop prediction from the measured initial state.

        x0: (B, 2) physical [vx m/s, yaw_rate rad/s] at k = 0; u: (B, T, 4) physical
        [gear, torque N·m, brake bar, steer deg]. Returns a :class:`Rollout` of (B, T).
        ``stride``: samples of u are ``stride`` model steps apart, so each step integrates
        over stride·dt (a decimated batch, :mod:`parknss.data.decimate`); 1 in every use
        but the coarse phase of ``train.recipe: coarse``.
        """
        if stride < 1:
            raise DataError(f"stride must be >= 1, got {stride}")
        h = self.dt * stride
        self._check(x0, u)
        x0, u = x0.to(self.dtype), u.to(self.dtype)
        u_s = self.scale_inputs(u)
        x0_s = self.initial_state_scaled(x0, u_s[:, 0])
        eng = self.engine_for(limiter, engine)
        if u.shape[1] == 1:
            X_s = x0_s[:, None]
        elif eng == "fused":
            X_s = self._fused(x0_s, u_s, h)
        else:
            X_s = self._eager(x0_s, u_s, limiter, h)
        return self.readout(X_s, u_s, fused=eng == "fused")

    def initial_state(self, x0: Tensor, u0: Tensor) -> Tensor:
        """Real-time start: internal state (B, 2) from physical x0 (B, 2) and u(0) (B, 4)."""
        x0, u0 = x0.to(self.dtype), u0.to(self.dtype)
        return self.initial_state_scaled(x0, self.scale_inputs(u0))

    def step(
        self, state: Tensor, u: Tensor, limiter: StateLimiter | None = None
    ) -> tuple[Rollout, Tensor]:
        """Real time: the prediction at this sample (fields (B, 1)) and the next state.

        state: (B, 2) internal scaled state; u: (B, 4) physical input of this sample.
        Identical to :meth:`rollout` step by step (tests/nss/test_model.py).
        """
        u_s = self.scale_inputs(u.to(self.dtype))
        out = self.readout(state[:, None], u_s[:, None])
        nxt = self.integrate(state, u_s)
        if limiter is not None:
            nxt = limiter(nxt, u_s)
        return out, nxt
