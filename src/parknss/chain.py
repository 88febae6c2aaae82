"""The command-to-vehicle chain: envelopes -> actuator submodels -> NSS (paper Fig. 2).

Commands {gear, torque_cmd, decel_cmd, steer_cmd} pass the input envelope, the three
actuator submodels (drive, brake, steering) and the output envelope to become the NSS input
u = [gear, torque, brake_pressure, steer]; the NSS gives vx, yaw rate, ax, ay.

* :class:`Chain` (torch) is the batched, differentiable rollout used by selection,
  co-tuning and evaluation. A channel may be left *measured* (its submodel None: the
  logged actual is fed instead), which is how Phase B substitutes one candidate at a time.
  Without state-aware submodels the actuals are computed for the whole history at once and
  the NSS runs its fused kernel; with them the loop is interleaved sample by sample, the
  submodels reading the NSS-predicted state (feature timing in
  :mod:`parknss.actuators.spec`).
* :class:`DeployedChain` is the saved artefact loaded for use: a
  :class:`~parknss.plant.Plant` (``reset``/``step``) running the NumPy real-time twin
  (:mod:`parknss.actuators.realtime`), plus the batched rollout for whole trials.
* :func:`load_chain` / :func:`save_chain` read and write the one artefact folder
  (:mod:`parknss.actuators.artefact`); :func:`predict_chain_trials` gives whole-trial
  predictions from the logged commands in the format of
  :func:`parknss.nss.predict.predict_trials` (for ``parknss evaluate --chain`` and
  ``parknss rate --chain``).

Initial conditions of a trial rollout: the measured state [vx(0), ω_z(0)] (as for the NSS
alone), the measured actuals at k = 0 for the lag submodels, the first command filling
the command histories.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import Tensor, nn

from parknss.actuators.envelopes import Envelope, clean_commands, limit_outputs_torch
from parknss.actuators.models import ActuatorModel
from parknss.actuators.spec import CHANNELS
from parknss.data.trial import Trial
from parknss.errors import DataError
from parknss.nss.model import I_STEER, NSSModel, Rollout
from parknss.plant import Commands, PlantOutput
from parknss.signals import ACTUAL_CHANNELS, COMMAND_CHANNELS

Predictions = dict[str, dict[str, np.ndarray]]
ACTUALS: tuple[str, ...] = ACTUAL_CHANNELS[1:]  # torque, brake_pressure, steer


@dataclass
class ChainRollout:
    """actuals (B, T, 3) [torque N·m, pressure bar, steer deg] and the NSS rollout."""

    actuals: Tensor
    nss: Rollout


def torch_features(names: Sequence[str], vx: Tensor, yaw: Tensor, gear: Tensor) -> Tensor:
    """State features (B, F) from vx, yaw rate, gear (B,)."""
    vals = {"speed": vx.abs(), "vx": vx, "yaw_rate": yaw, "gear": gear}
    return torch.stack([vals[n] for n in names], dim=-1)


class Chain(nn.Module):
    """Envelopes, one submodel (or None: measured) per channel, and the frozen NSS."""

    def __init__(
        self, nss: NSSModel, models: dict[str, ActuatorModel | None], envelope: Envelope
    ) -> None:
        super().__init__()
        self.nss = nss
        self.acts = nn.ModuleDict({c: m for c, m in models.items() if m is not None})
        self.envelope = envelope

    def model(self, channel: str) -> ActuatorModel | None:
        return self.acts[channel] if channel in self.acts else None  # noqa: SIM401

    @property
    def state_aware(self) -> bool:
        return any(m.spec.state_aware for m in self.acts.values())

    def specs(self) -> dict[str, str | None]:
        return {c: (self.model(c).spec.name if self.model(c) else None) for c in CHANNELS}

    # ------------------------------------------------------------------ rollout
    def rollout(
        self,
        cmds: np.ndarray | Tensor,
        x0: Tensor,
        y0: Tensor,
        measured: Tensor | None = None,
        states: tuple[Tensor, Tensor] | None = None,
    ) -> ChainRollout:
        """Batched rollout. cmds (B, T, 4) [gear, torque_cmd, decel_cmd, steer_cmd];
        x0 (B, 2) [vx, yaw]; y0 (B, 3) actuals at k = 0; measured (B, T, 3) logged actuals
        (needed for channels without a submodel). ``states`` (vx, yaw), each (B, T), feeds
        state-aware submodels fixed states instead of the NSS's (the co-tuning surrogate);
        the rollout is then decoupled."""
        c_np = np.asarray(cmds.detach() if isinstance(cmds, Tensor) else cmds, np.float64)
        y0 = torch.as_tensor(y0, dtype=torch.float64)
        c = torch.as_tensor(clean_commands(self.envelope, c_np, y0[:, 2].numpy()))
        if len(self.acts) < len(CHANNELS) and measured is None:
            raise DataError("a chain with measured channels needs the measured actuals")
        x0 = torch.as_tensor(x0, dtype=torch.float64)
        if self.state_aware and states is None:
            return self._interleaved(c, x0, y0, measured)
        return self._decoupled(c, x0, y0, measured, states)

    def _limit(self, ys: list[Tensor], steer0: Tensor) -> list[Tensor]:
        """Output envelope on the modelled channels of (B, T) actuals."""
        env = self.envelope
        out = list(ys)
        if self.model("drive") is not None:
            out[0] = torch.clamp(ys[0], min=env.torque_floor)
        if self.model("brake") is not None:
            out[1] = torch.clamp(ys[1], min=env.pressure_floor)
        if self.model("steering") is not None:
            out[2] = limit_outputs_torch(env, ys[0], ys[1], ys[2], steer0)[2]
        return out

    def _decoupled(self, c, x0, y0, measured, states=None) -> ChainRollout:
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
        ys = self._limit(ys, y0[:, 2])
        u = torch.stack([c[..., 0], *ys], dim=-1)
        return ChainRollout(u[..., 1:], self.nss.rollout(x0, u))

    def _yaw(self, x: Tensor, steer_s: Tensor) -> Tensor:
        """Physical yaw rate reconstructed at internal state x (B, 2), scaled steering."""
        nss = self.nss
        if not nss.cfg.residual_yaw:
            return nss.yaw_phys(x[:, 1])
        ref_s = nss.yaw_scaled(nss.yaw_ref(x[:, 0], steer_s))
        return nss.yaw_phys(ref_s + x[:, 1])

    def _euler_step(self):
        """x̂ + dt·f([x̂, u_s]) with the state net's weights taken out of the modules once
        (the same addmm/tanh sequence as nn.Linear, without the module-call overhead)."""
        nss = self.nss
        if nss.cfg.integrator != "euler":
            return nss.integrate
        lin = [m for m in nss.state_net if isinstance(m, nn.Linear)]
        wts = [(m.bias, m.weight.t()) for m in lin]
        dt = nss.dt

        def step(x: Tensor, us: Tensor) -> Tensor:
            h = torch.cat([x, us], dim=-1)
            for b, wt in wts[:-1]:
                h = torch.tanh(torch.addmm(b, h, wt))
            b, wt = wts[-1]
            return x + dt * torch.addmm(b, h, wt)

        return step

    def _interleaved(self, c, x0, y0, measured) -> ChainRollout:
        nss, env = self.nss, self.envelope
        integrate = self._euler_step()
        dt_nss = nss.dtype
        states = {
            ch: m.init_state(c[:, 0, 1 + i], y0[:, i])
            for i, ch in enumerate(CHANNELS)
            if (m := self.model(ch)) is not None
        }
        vx, yaw = x0[:, 0], x0[:, 1]
        steer_prev = y0[:, 2]
        x = None
        Xs, Us = [], []
        rate = env.steer_rate_dps * nss.dt
        for k in range(c.shape[1]):
            g = c[:, k, 0]
            ys = []
            for i, ch in enumerate(CHANNELS):
                m = self.model(ch)
                if m is None:
                    ys.append(measured[:, k, i])
                    continue
                f = torch_features(m.spec.features, vx, yaw, g) if m.spec.state_aware else None
                y, states[ch] = m.step(states[ch], c[:, k, 1 + i], f)
                ys.append(y)
            if self.model("drive") is not None:
                ys[0] = torch.clamp(ys[0], min=env.torque_floor)
            if self.model("brake") is not None:
                ys[1] = torch.clamp(ys[1], min=env.pressure_floor)
            if self.model("steering") is not None:
                s = torch.minimum(torch.maximum(ys[2], steer_prev - rate), steer_prev + rate)
                ys[2] = torch.clamp(s, -env.steer_lock, env.steer_lock)
            steer_prev = ys[2]
            u = torch.stack([g, *ys], dim=-1).to(dt_nss)
            us = nss.scale_inputs(u)
            if x is None:
                x = nss.initial_state_scaled(x0.to(dt_nss), us)
            Xs.append(x)
            Us.append(u)
            x = integrate(x, us)
            vx = nss.vx_phys(x[:, 0]).to(torch.float64)
            yaw = self._yaw(x, us[:, I_STEER]).to(torch.float64)
        U = torch.stack(Us, dim=1)
        r = nss.readout(torch.stack(Xs, dim=1), nss.scale_inputs(U))
        return ChainRollout(U[..., 1:], r)


# ---------------------------------------------------------------------- trials


@dataclass
class TrialBatch:
    """Whole trials padded to the longest (last sample repeated): commands (B, T, 4),
    measured actuals (B, T, 3), x0 (B, 2), y0 (B, 3), lengths."""

    cmds: np.ndarray
    actuals: np.ndarray
    x0: np.ndarray
    y0: np.ndarray
    lengths: list[int]
    ids: list[str]


def _pad(x: np.ndarray, L: int) -> np.ndarray:
    return np.concatenate([x, np.repeat(x[-1:], L - len(x), axis=0)]) if len(x) < L else x


def trial_batch(trials: Sequence[Trial]) -> TrialBatch:
    """Batch whole trials for :meth:`Chain.rollout` (logged commands and actuals)."""
    trials = list(trials)
    if not trials:
        raise DataError("no trials to roll out")
    L = max(tr.n for tr in trials)
    cmds = np.stack([_pad(tr.array(COMMAND_CHANNELS), L) for tr in trials])
    acts = np.stack([_pad(tr.array(ACTUALS), L) for tr in trials])
    x0 = np.stack([[tr["vx"][0], tr["yaw_rate"][0]] for tr in trials])
    return TrialBatch(cmds, acts, x0, acts[:, 0].copy(), [tr.n for tr in trials],
                      [tr.id for tr in trials])


def rollout_trials(chain: Chain, trials: Sequence[Trial]) -> ChainRollout:
    """No-grad chain rollout of whole trials (padded); see :func:`trial_batch`."""
    b = trial_batch(trials)
    with torch.no_grad():
        return chain.rollout(b.cmds, torch.as_tensor(b.x0), torch.as_tensor(b.y0),
                             torch.as_tensor(b.actuals))


def realtime_predictions(chain: Chain, trials: Iterable[Trial]) -> Predictions:
    """The same predictions by the NumPy real-time twin, trial by trial (faster than the
    torch loop when state-aware submodels force an interleaved rollout)."""
    from parknss.actuators.realtime import RealtimeChain

    rt = RealtimeChain(chain.nss, {c: chain.model(c) for c in CHANNELS}, chain.envelope)
    out: Predictions = {}
    names = ("vx", "yaw_rate", "ax", "ay", *ACTUALS)
    for tr in trials:
        cm, ac = tr.array(COMMAND_CHANNELS), tr.array(ACTUALS)
        rt.start([tr["vx"][0], tr["yaw_rate"][0]], ac[0], cm[0])
        rows = np.empty((tr.n, 7))
        for k in range(tr.n):
            act, st = rt.step(*cm[k], measured=ac[k])
            rows[k, :4] = st
            rows[k, 4:] = act
        out[tr.id] = {n: rows[:, i].copy() for i, n in enumerate(names)}
    return out


def chain_predictions(chain: Chain, trials: Iterable[Trial]) -> Predictions:
    """{trial_id: {"vx", "yaw_rate", "ax", "ay", "torque", "brake_pressure", "steer"}}.

    A chain with state-aware submodels in float64 is evaluated by the real-time twin
    (equal to the torch rollout to rounding, tests/test_chain.py), else by the batched
    torch rollout."""
    trials = list(trials)
    if chain.state_aware and chain.nss.dtype == torch.float64:
        return realtime_predictions(chain, trials)
    r = rollout_trials(chain, trials)
    ch = {k: v.detach().to(torch.float64).numpy() for k, v in r.nss.channels().items()}
    for i, name in enumerate(ACTUALS):
        ch[name] = r.actuals[..., i].detach().to(torch.float64).numpy()
    return {tr.id: {k: v[j, : tr.n].copy() for k, v in ch.items()} for j, tr in enumerate(trials)}


# ---------------------------------------------------------------------- deployed


class DeployedChain:
    """The loaded chain artefact: a real-time :class:`~parknss.plant.Plant` and a batched
    evaluator. ``meta`` holds the artefact's JSON (selection, co-tuning, provenance)."""

    def __init__(self, chain: Chain, meta: dict | None = None, path: Path | None = None):
        from parknss.actuators.realtime import RealtimeChain

        self.chain = chain.double().eval()
        self.meta = meta or {}
        self.path = path
        models = {c: chain.model(c) for c in CHANNELS}
        self.rt = RealtimeChain(self.chain.nss, models, chain.envelope)
        self.dt = self.rt.dt
        self.reset()

    # Plant protocol
    def start(self, x0, y0, cmd0) -> None:
        """Exact start (see :meth:`RealtimeChain.start`): x0 [vx, yaw], actuals y0, cmd0."""
        self.rt.start(x0, y0, cmd0)

    def reset(
        self, vx: float = 0.0, yaw_rate: float = 0.0, steer: float = 0.0, gear: int = 0
    ) -> PlantOutput:
        """At rest (by default) with the given steering angle; histories hold the rest
        command (torque 0, decel 0, steer_cmd = steer)."""
        self.rt.start([vx, yaw_rate], [0.0, 0.0, steer], [gear, 0.0, 0.0, steer])
        return PlantOutput(int(gear), 0.0, 0.0, float(steer), float(vx), float(yaw_rate), 0.0, 0.0)

    def step(self, cmd: Commands) -> PlantOutput:
        """One 10 ms sample under ``cmd``: the actuals and states logged at this sample."""
        act, (vx, yaw, ax, ay) = self.rt.step(
            float(cmd.gear), float(cmd.torque_cmd), float(cmd.decel_cmd), float(cmd.steer_cmd)
        )
        return PlantOutput(int(cmd.gear), act[0], act[1], act[2], vx, yaw, ax, ay)

    @property
    def envelope_activity(self):
        return self.rt.env.activity

    def predict_trials(self, trials: Iterable[Trial]) -> Predictions:
        return chain_predictions(self.chain, trials)


def load_chain(path: str | Path) -> DeployedChain:
    """Load a chain artefact folder (one-line CheckpointError on any problem)."""
    from parknss.actuators.artefact import read_chain

    chain, meta, folder = read_chain(path)
    return DeployedChain(chain, meta, folder)


def save_chain(folder: str | Path, chain: Chain, meta: dict | None = None) -> Path:
    """Write the chain artefact folder (see :mod:`parknss.actuators.artefact`)."""
    from parknss.actuators.artefact import write_chain

    return write_chain(folder, chain, meta or {})


def predict_chain_campaign(path: str | Path, trials: Iterable[Trial]) -> Predictions:
    """Whole-trial chain predictions from the logged commands by the artefact at ``path``
    (the chain counterpart of :func:`parknss.nss.predict.predict_campaign`)."""
    return load_chain(path).predict_trials(trials)
