"""The command-to-vehicle chain: envelopes -> actuator submodels -> NSS (paper Fig. 2).

Commands {gear, torque_cmd, decel_cmd, steer_cmd} pass the input envelope, the three
actuator submodels (drive, brake, steering) and the output envelope to become the NSS input
u = [gear, torque, brake_pressure, steer]; the NSS gives vx, yaw rate, ax, ay.

:class:`Chain` (torch) is the batched, differentiable rollout used by selection,
co-tuning and evaluation. A channel may be left *measured* (its submodel None: the logged
actual is fed instead), which is how Phase B substitutes one candidate at a time. Without
state-aware submodels the actuals are computed for the whole history at once and the NSS
runs its fused kernel; with them the loop is interleaved sample by sample, the submodels
reading the NSS-predicted state (feature timing in :mod:`parknss.actuators.spec`). The
physics is not written here: the envelopes are :mod:`parknss.actuators.envelopes`, the
Euler step and the yaw readout are the NSS's own (:meth:`NSSModel.step_function`,
:meth:`NSSModel.reconstruct_yaw`).

In closed loop (``rollout(..., gear_rule=True)``, the real-time chain of a Plant, the FMU) the
gear channel is a request and obeys the shift-by-wire rule (:mod:`parknss.actuators.shift`),
which reads the chain's own predicted vx. Replaying a log it is not applied (the default):
the logged gear is the gear the car engaged, already gated by the car's own rule, and the
chain's vx inside the wheel-speed blind zone (where the loss does not look) cannot resolve
the rule's 0.1 km/h, so gating it again would delay shifts the car made at rest.
The rule belongs to the drive train, with the drive submodel:
a chain whose drive channel is measured feeds the logged gear (the engaged one) and the
logged torque, which already carry the shifts (Phase B's all-measured reference is the NSS
on the logged actuals, exactly). With a drive submodel the rule, like the brake-hold latch
it comes with (:mod:`parknss.actuators.envelopes`), acts sample by sample on the chain's own
state, so a closed-loop rollout is the interleaved loop.

Initial conditions of a trial rollout: the measured state [vx(0), ω_z(0)] (as for the NSS
alone), the measured actuals at k = 0 for the lag submodels, the first command filling
the command histories.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

from parknss.actuators.envelopes import Envelope, clean_commands, limit_outputs_torch
from parknss.actuators.models import ActuatorModel
from parknss.actuators.shift import ShiftByWire
from parknss.actuators.spec import CHANNELS, feature_values
from parknss.errors import DataError
from parknss.nss.config import NSSConfig
from parknss.nss.model import I_STEER, NSSModel, Rollout
from parknss.signals import ACTUAL_CHANNELS, kmh_to_ms

ACTUALS: tuple[str, ...] = ACTUAL_CHANNELS[1:]  # torque, brake_pressure, steer


@dataclass
class ChainRollout:
    """actuals (B, T, 3) [torque N·m, pressure bar, steer deg] and the NSS rollout."""

    actuals: Tensor
    nss: Rollout


def torch_features(names: tuple[str, ...], vx: Tensor, yaw: Tensor, gear: Tensor) -> Tensor:
    """State features (B, F) from vx (m/s), yaw rate (rad/s), gear, each (B,)."""
    return torch.stack(feature_values(names, vx, yaw, gear), dim=-1)


@dataclass
class NSSProvenance:
    """What the chain's artefact records about its NSS besides the weights: the full
    :class:`~parknss.nss.config.NSSConfig` it was trained with (None: unknown, the chain
    cannot be saved) and its training metadata (epochs, best epoch, data hash, ...)."""

    config: NSSConfig | None = None
    training: dict[str, Any] = field(default_factory=dict)


class Chain(nn.Module):
    """Envelopes, one submodel (or None: measured) per channel, and the frozen NSS.

    Attributes:
        nss: the NSS vehicle model.
        acts: the submodels present, by channel ("drive", "brake", "steering").
        envelope: the input and output envelopes.
        provenance: the NSS's config and training metadata, written into the artefact.
    """

    def __init__(
        self,
        nss: NSSModel,
        models: dict[str, ActuatorModel | None],
        envelope: Envelope,
        provenance: NSSProvenance | None = None,
    ) -> None:
        super().__init__()
        self.nss = nss
        self.acts = nn.ModuleDict({c: m for c, m in models.items() if m is not None})
        self.envelope = envelope
        self.provenance = provenance or NSSProvenance()

    def model(self, channel: str) -> ActuatorModel | None:
        """The submodel of ``channel``, or None when the channel is measured."""
        return self.acts[channel] if channel in self.acts else None  # noqa: SIM401

    def models(self) -> dict[str, ActuatorModel | None]:
        """Every channel's submodel (None: measured), in channel order."""
        return {c: self.model(c) for c in CHANNELS}

    @property
    def modelled(self) -> tuple[bool, bool, bool]:
        """Which channels (drive, brake, steering) have a submodel."""
        drive, brake, steering = (self.model(c) is not None for c in CHANNELS)
        return drive, brake, steering

    @property
    def state_aware(self) -> bool:
        return any(m.spec.state_aware for m in self.acts.values())

    def specs(self) -> dict[str, str | None]:
        return {c: (m.spec.name if m else None) for c, m in self.models().items()}

    # ------------------------------------------------------------------ rollout
    def rollout(
        self,
        cmds: np.ndarray | Tensor,
        x0: Tensor,
        y0: Tensor,
        measured: Tensor | None = None,
        states: tuple[Tensor, Tensor] | None = None,
        gear_rule: bool = False,
    ) -> ChainRollout:
        """Batched rollout. cmds (B, T, 4) [gear, torque_cmd, decel_cmd, steer_cmd];
        x0 (B, 2) [vx, yaw]; y0 (B, 3) actuals at k = 0; measured (B, T, 3) logged actuals
        (needed for channels without a submodel). ``states`` (vx, yaw), each (B, T), feeds
        state-aware submodels fixed states instead of the NSS's (the co-tuning surrogate);
        the rollout is then decoupled. ``gear_rule``: the gear column is a request that the
        shift-by-wire rule gates (closed loop); False (default): it is the engaged gear of a
        log, which already carries the car's own gating (module doc)."""
        c_np = np.asarray(cmds.detach() if isinstance(cmds, Tensor) else cmds, np.float64)
        y0 = torch.as_tensor(y0, dtype=torch.float64)
        c = torch.as_tensor(clean_commands(self.envelope, c_np, y0[:, 2].numpy()))
        if len(self.acts) < len(CHANNELS) and measured is None:
            raise DataError("a chain with measured channels needs the measured actuals")
        x0 = torch.as_tensor(x0, dtype=torch.float64)
        rule = gear_rule and self.model("drive") is not None
        if rule and states is not None:
            raise DataError("the gear rule reads the chain's own vx: no fixed states with it")
        if rule or (self.state_aware and states is None):
            return self._interleaved(c, x0, y0, measured, rule)
        return self._decoupled(c, x0, y0, measured, states)

    def _rules(self, c: Tensor) -> list[ShiftByWire]:
        """One gear rule per row, engaged in the row's first (clean) gear."""
        rules = []
        for g0 in c[:, 0, 0].tolist():
            r = self.envelope.shift_rule()
            r.reset(g0)
            rules.append(r)
        return rules

    def _decoupled(self, c, x0, y0, measured, states=None) -> ChainRollout:
        """Every submodel over the whole history, the output envelope, then the NSS."""
        ys = []
        for i, ch in enumerate(CHANNELS):
            m = self.model(ch)
            if m is None:
                ys.append(measured[..., i])
                continue
            f = None
            if m.spec.state_aware:
                if states is None:
                    raise DataError("state-aware submodels need states in a decoupled rollout")
                f = torch_features(m.spec.features, states[0], states[1], c[..., 0])
            ys.append(m.rollout(c[..., 1 + i], f, y0[:, i]))
        ys = limit_outputs_torch(self.envelope, *ys, y0[:, 2], self.modelled)
        u = torch.stack([c[..., 0], *ys], dim=-1)
        return ChainRollout(u[..., 1:], self.nss.rollout(x0, u))

    def _interleaved(self, c, x0, y0, measured, rule: bool = False) -> ChainRollout:
        """Sample by sample: submodels read the NSS state x̂(k), the NSS advances on u(k)."""
        nss = self.nss
        integrate = nss.step_function()
        dt_nss = nss.dtype
        modelled = self.modelled
        env = self.envelope
        states = {
            ch: m.init_state(c[:, 0, 1 + i], y0[:, i])
            for i, ch in enumerate(CHANNELS)
            if (m := self.model(ch)) is not None
        }
        vx, yaw = x0[:, 0], x0[:, 1]
        steer_prev = y0[:, 2]
        rules = self._rules(c) if rule else []
        x = None
        Xs, Us = [], []
        for k in range(c.shape[1]):
            g, cmds = c[:, k, 0], (c[:, k, 1], c[:, k, 2], c[:, k, 3])
            if rules:
                req, v_now = c[:, k, 0].tolist(), vx.detach().tolist()
                g = torch.tensor([r.step(q, v) for r, q, v in zip(rules, req, v_now, strict=True)],
                                 dtype=c.dtype)
                hold = torch.tensor([r.shifting for r in rules])
                cmds = (torch.where(hold, 0.0, cmds[0]), *cmds[1:])
            ys = []
            for i, ch in enumerate(CHANNELS):
                m = self.model(ch)
                if m is None:
                    ys.append(measured[:, k, i])
                    continue
                f = torch_features(m.spec.features, vx, yaw, g) if m.spec.state_aware else None
                y, states[ch] = m.step(states[ch], cmds[i], f)
                ys.append(y)
            ys = limit_outputs_torch(self.envelope, *ys, steer_prev, modelled)
            steer_prev = ys[2]
            u = torch.stack([g, *ys], dim=-1).to(dt_nss)
            us = nss.scale_inputs(u)
            if x is None:
                x = nss.initial_state_scaled(x0.to(dt_nss), us)
            Xs.append(x)
            Us.append(u)
            x = integrate(x, us)
            if rule:  # the brake latches (parknss.actuators.envelopes), closed loop only
                v_after = nss.vx_phys(x[:, 0])
                held = (ys[1] >= env.hold_latch_bar) & (
                    v_after.abs() < kmh_to_ms(env.hold_latch_kmh))
                if env.stop_latch_bar < float("inf"):
                    held = held | ((ys[1] >= env.stop_latch_bar)
                                   & (g.to(v_after.dtype) * v_after < 0.0))
                if bool(held.any()):
                    rest = nss.initial_state_scaled(torch.zeros_like(x0).to(dt_nss), us)
                    x = torch.where(held[:, None], rest, x)
            vx = nss.vx_phys(x[:, 0]).to(torch.float64)
            yaw = nss.yaw_phys(nss.reconstruct_yaw(x, us[:, I_STEER])[2]).to(torch.float64)
        U = torch.stack(Us, dim=1)
        r = nss.readout(torch.stack(Xs, dim=1), nss.scale_inputs(U))
        return ChainRollout(U[..., 1:], r)
