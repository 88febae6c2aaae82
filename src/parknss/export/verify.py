"""The FMU against parknss's real-time chain, trial by trial (what ``parknss export fmu
--verify`` prints and tests/export/test_fmu.py asserts).

:func:`fmu_trial_errors` drives the FMU with FMPy's ``simulate_fmu`` under one trial's
logged commands (communication step 10 ms; the initial-state parameters from the trial's
first sample) and the NumPy real-time chain (:class:`~parknss.chain.realtime.RealtimeChain`,
the reference implementation) under the same commands, with the pose integrated as the
closed loop integrates the chain plant's (:class:`parknss.sim.plants.ChainPlant`: the mean
of consecutive samples along the exact arc); it returns the largest absolute difference of
every output. The output of the FMU after the step from t_k to t_k + 10 ms is the chain's
sample k. The reference also recomputes the identified-domain outputs (``in_domain``,
``domain_exits``) from the same :class:`~parknss.export.fmi2_source.Domain`, so the C check
is verified too.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parknss.chain.deployed import DeployedChain
from parknss.data.trial import Trial
from parknss.export.config import load_export_config
from parknss.export.fmi2_source import OUTPUTS, Domain
from parknss.signals import ACTUAL_CHANNELS, COMMAND_CHANNELS, DT
from parknss.vehicle import arc_step

CHAIN_OUTPUTS: tuple[str, ...] = tuple(v.name for v in OUTPUTS)


@dataclass(frozen=True)
class TrialErrors:
    """Largest |FMU - real-time chain| per output over one trial of ``samples`` samples."""

    trial: str
    samples: int
    max_abs: dict[str, float]

    @property
    def worst(self) -> float:
        return max(self.max_abs.values())


def outside(domain: Domain, cmd, vx: float, yaw: float) -> bool:
    """Whether a sample's commands (torque, decel, steer) or vx, yaw rate leave ``domain``
    (NaN is never outside: the envelope holds it)."""
    val = (*cmd, vx, yaw)
    lo, hi = (*domain.cmd_lo, *domain.state_lo), (*domain.cmd_hi, *domain.state_hi)
    return any(v < a or v > b for v, a, b in zip(val, lo, hi, strict=True))


def realtime_reference(dep: DeployedChain, tr: Trial, domain: Domain | None = None
                       ) -> np.ndarray:
    """(T, 13) rows of :data:`CHAIN_OUTPUTS` by the NumPy real-time chain, the pose and the
    identified-domain outputs (``domain``: default, the one the FMU of ``dep`` checks)."""
    from parknss.export.fmu import identified_domain

    domain = domain or identified_domain(dep, load_export_config().fmu)
    cm, ac = tr.array(COMMAND_CHANNELS), tr.array(ACTUAL_CHANNELS[1:])
    rt = dep.rt
    exits = 0
    rt.start([tr["vx"][0], tr["yaw_rate"][0]], ac[0], cm[0])
    prev = (float(tr["vx"][0]), float(tr["yaw_rate"][0]))
    pose = (0.0, 0.0, 0.0)
    rows = np.empty((tr.n, len(CHAIN_OUTPUTS)))
    for k in range(tr.n):
        act, (vx, yaw, ax, ay) = rt.step(*cm[k])
        mv, mw = 0.5 * (prev[0] + vx), 0.5 * (prev[1] + yaw)
        prev = (vx, yaw)
        pose = arc_step(*pose, mv * DT, mw * DT)
        out = outside(domain, cm[k, 1:], vx, yaw)
        exits += out
        rows[k] = (*act, vx, yaw, ax, ay, rt.gear, *pose, float(not out), exits)
    return rows


def simulate_trial(fmu: str | Path, tr: Trial) -> np.ndarray:
    """(T, 13) rows of :data:`CHAIN_OUTPUTS` by FMPy's simulate_fmu under the logged
    commands (the gear as the FMU's Integer input)."""
    from fmpy import simulate_fmu

    cm, ac = tr.array(COMMAND_CHANNELS), tr.array(ACTUAL_CHANNELS[1:])
    names = ("gear", "torque_cmd", "decel_cmd", "steer_cmd")
    sig = np.zeros(tr.n, dtype=[("time", float), ("gear", np.int32)]
                   + [(n, float) for n in names[1:]])
    sig["time"] = np.arange(tr.n) * DT
    for i, n in enumerate(names):
        sig[n] = cm[:, i]
    start = {"vx0": tr["vx"][0], "yaw_rate0": tr["yaw_rate"][0], "torque0": ac[0, 0],
             "brake_pressure0": ac[0, 1], "steer0": ac[0, 2]}
    res = simulate_fmu(str(fmu), start_values={k: float(v) for k, v in start.items()},
                       input=sig, output_interval=DT, stop_time=tr.n * DT,
                       output=list(CHAIN_OUTPUTS), logger=_quiet)
    return np.column_stack([res[n] for n in CHAIN_OUTPUTS])[1 : tr.n + 1]


def _quiet(*_args) -> None:
    """FMPy logger that drops the FMU's domain warnings (the outputs carry them)."""


def fmu_trial_errors(fmu: str | Path, dep: DeployedChain, trials: Iterable[Trial],
                     progress: Callable[[int, int, TrialErrors], None] | None = None
                     ) -> list[TrialErrors]:
    """:class:`TrialErrors` of every trial (see the module doc); ``progress(i, n, errors)``
    is called after each trial (the replay takes seconds per trial)."""
    trials = list(trials)
    out = []
    for i, tr in enumerate(trials, start=1):
        diff = np.abs(simulate_trial(fmu, tr) - realtime_reference(dep, tr))
        out.append(TrialErrors(tr.id, tr.n, dict(zip(CHAIN_OUTPUTS, diff.max(axis=0).tolist(),
                                                     strict=True))))
        if progress is not None:
            progress(i, len(trials), out[-1])
    return out
