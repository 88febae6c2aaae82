"""The chain artefact loaded for use: a real-time :class:`~parknss.plant.Plant` and a
batched evaluator.

:class:`DeployedChain` implements the one Plant protocol (``dt``, ``reset``, ``step``)
by the NumPy real-time twin (:class:`~parknss.chain.realtime.RealtimeChain`), so
``parknss simulate --plant chain`` and the web simulator drive it like any other plant.
Beyond the protocol it offers :meth:`DeployedChain.start`, the exact start of a trial
replay (measured state, actuals and first command), and
:meth:`DeployedChain.predict_trials`, whole-trial predictions by the batched rollout.
:func:`step_many` steps several deployed chains one sample together (a vector
environment's or a grid's plants): native engines of one artefact in one C call.
:func:`load_chain` / :func:`save_chain` read and write the artefact folder
(:mod:`parknss.chain.artefact`).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path

from parknss.actuators.envelopes import Activity
from parknss.chain.artefact import read_chain, write_chain
from parknss.chain.model import Chain
from parknss.chain.realtime import RealtimeChain
from parknss.chain.trials import Predictions, chain_predictions
from parknss.data.trial import Trial
from parknss.errors import ConfigError
from parknss.plant import Commands, PlantOutput


class DeployedChain:
    """A chain ready to drive: ``chain`` (float64, eval), its real-time twin ``rt``, the
    artefact's build metadata ``meta`` and its folder ``path`` (None when built in memory);
    ``dt`` is the step in s. ``engine`` "numpy" (default: the NumPy twin, the reference
    implementation) or "native" (its generated C through ctypes,
    :class:`~parknss.chain.native.NativeChain`, equal to rounding and faster; needs a C
    compiler) runs the Plant steps."""

    def __init__(self, chain: Chain, meta: dict | None = None, path: Path | None = None,
                 engine: str = "numpy"):
        self.chain = chain.double().eval()
        self.meta = meta or {}
        self.path = path
        self.rt = RealtimeChain(self.chain.nss, chain.models(), chain.envelope)
        self.dt = self.rt.dt
        if engine not in ("numpy", "native"):
            raise ConfigError(f"chain engine {engine!r}: one of numpy, native")
        self.engine = engine
        self.stepper = self.rt
        self._row = None  # the native engine's step_row: the Plant step's short path
        if engine == "native":
            from parknss.chain.native import NativeChain

            self.stepper = NativeChain(self.rt)
            self._row = self.stepper.step_row
        self.reset()

    # ------------------------------------------------------------ Plant protocol
    def reset(
        self, vx: float = 0.0, yaw_rate: float = 0.0, steer: float = 0.0, gear: int = 0
    ) -> PlantOutput:
        """At rest (by default) with the given steering angle; histories hold the rest
        command (torque 0, decel 0, steer_cmd = steer)."""
        self.stepper.start([vx, yaw_rate], [0.0, 0.0, steer], [gear, 0.0, 0.0, steer])
        return PlantOutput(int(gear), 0.0, 0.0, float(steer), float(vx), float(yaw_rate), 0.0, 0.0)

    def step(self, cmd: Commands) -> PlantOutput:
        """One 10 ms sample under ``cmd``: the engaged gear (the gear rule,
        :mod:`parknss.actuators.shift`), the actuals and states logged at this sample."""
        if self._row is not None:
            o = self._row(float(cmd.gear), float(cmd.torque_cmd), float(cmd.decel_cmd),
                          float(cmd.steer_cmd))
            return PlantOutput(int(o[7]), o[0], o[1], o[2], o[3], o[4], o[5], o[6])
        act, (vx, yaw, ax, ay) = self.stepper.step(
            float(cmd.gear), float(cmd.torque_cmd), float(cmd.decel_cmd), float(cmd.steer_cmd)
        )
        return PlantOutput(int(self.stepper.gear), act[0], act[1], act[2], vx, yaw, ax, ay)

    # ------------------------------------------------------- beyond the protocol
    def start(self, x0: Sequence[float], y0: Sequence[float], cmd0: Sequence[float]) -> None:
        """Exact start of a trial replay (not part of the Plant protocol): x0 [vx m/s,
        yaw rad/s], actuals y0 [torque N·m, pressure bar, steer deg], the first command
        cmd0 [gear, torque_cmd, decel_cmd, steer_cmd] filling the histories."""
        self.stepper.start(x0, y0, cmd0)

    @property
    def envelope_activity(self) -> Activity:
        """How often each envelope acted since the real-time twin was built (the NumPy
        engine counts; the native engine does not)."""
        return self.rt.env.activity

    def predict_trials(self, trials: Iterable[Trial]) -> Predictions:
        """Whole-trial predictions from the logged commands (:func:`chain_predictions`)."""
        return chain_predictions(self.chain, trials)


def load_chain(path: str | Path, engine: str = "numpy") -> DeployedChain:
    """Load a chain artefact folder (one-line CheckpointError on any problem); ``engine``
    as for :class:`DeployedChain`."""
    chain, meta, folder = read_chain(path)
    return DeployedChain(chain, meta, folder, engine)


def save_chain(folder: str | Path, chain: Chain, meta: dict | None = None) -> Path:
    """Write the chain artefact folder (see :mod:`parknss.chain.artefact`)."""
    return write_chain(folder, chain, meta or {})


def predict_chain_campaign(path: str | Path, trials: Iterable[Trial]) -> Predictions:
    """Whole-trial chain predictions from the logged commands by the artefact at ``path``
    (the chain counterpart of :func:`parknss.nss.predict.predict_campaign`)."""
    return load_chain(path).predict_trials(trials)


def step_many(plants: Sequence[DeployedChain], cmds: Sequence[Commands]) -> list[PlantOutput]:
    """One 10 ms sample of each plant under its command: exactly each plant's own
    :meth:`DeployedChain.step`. Native-engine chains of one artefact are stepped in one C
    call (:func:`parknss.chain.native.step_many`, each NSS layer applied to all of them at
    once); any other set of plants one by one."""
    plants, cmds = list(plants), list(cmds)
    if len(plants) != len(cmds):
        raise ConfigError(f"step_many: {len(plants)} plants, {len(cmds)} commands")
    native = [p.stepper for p in plants if p.engine == "native"]
    if not plants or len(native) < len(plants) or len({n.path for n in native}) != 1:
        return [p.step(c) for p, c in zip(plants, cmds, strict=True)]
    from parknss.chain.native import step_many as native_step_many

    rows = native_step_many(native, [(c.gear, c.torque_cmd, c.decel_cmd, c.steer_cmd)
                                     for c in cmds])
    return [PlantOutput(int(r[7]), r[0], r[1], r[2], r[3], r[4], r[5], r[6])
            for r in rows.tolist()]
