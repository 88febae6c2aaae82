"""Physical input-output envelopes of the chain (paper §III-B).

Input side, on the commands before the submodels:

* a non-finite command is handled by one documented rule: NaN holds the channel's last
  clean command (at the start: the rest command, torque 0, decel 0, steering the initial
  angle); +inf/-inf are clamped to the domain bound they point at. NaN and inf never
  reach a submodel, so states never become NaN. The gear passes through unclamped
  (NaN gear: hold the last gear).
* every command is clamped to its identified domain: decel_cmd to [-0.8, 0] m/s² by
  default (paper), torque_cmd and steer_cmd to the range seen in the data, the latter
  also within the steering lock.
* the gear obeys the shift-by-wire rule of the reference vehicle (a differing request is
  engaged only after ``shift_time_s`` at |vx| <= ``shift_speed_kmh``, the drive command
  zero while it waits): :mod:`parknss.actuators.shift`, applied by the chain, which has
  the speed it needs.
* the brake-hold latch (closed loop only, with the gear rule): the NSS is not taught
  inside the wheel-speed blind zone (its loss masks |vx| < 0.5 km/h, where the sensor
  reads 0), so under a brake-hold its vx settles near, not at, 0 (a few cm/s) and a
  standstill that the gear rule and the interface must see never comes. A brake holds:
  once the pressure reaches ``hold_latch_bar`` (identified: the highest pressure the car
  was logged moving at, above the blind zone) with |vx| inside ``hold_latch_kmh``, the
  state is set to rest (vx 0, yaw rate 0) after the step, until the pressure falls below
  it. Replays of logs do not apply it (the logged gear and actuals already carry the
  car's behaviour; :mod:`parknss.chain.model`).
* the brake-stop latch (optional, off by default; with the gear rule, closed loop only):
  a brake only opposes motion and the drive pushes along the engaged gear, so a braked
  car cannot move against its gear. With ``stop_latch_bar`` finite, a step at brake
  pressure >= ``stop_latch_bar`` that ends with gear·vx < 0 (the learned brake, never
  scored inside the blind zone, drives the car through zero and back: issue 44, grid
  cell 30) ends at rest instead. The native engine and the ONNX step refuse a chain
  with it.

Output side, on the submodel outputs (never on measured channels): torque and pressure
are held at their floors (>= 0), the steering angle is rate-limited to just above the
highest slew rate in the data (so the guard only acts on out-of-domain requests), then
held within the lock ±400°.

:class:`Envelope` holds the numbers (saved in the chain artefact). The batched rules are
written once: :func:`clean_commands` (input side, NumPy histories) and
:func:`limit_outputs_torch` (output side, torch, a whole history or one sample, used by
fitting, the chain's decoupled and interleaved rollouts alike). :class:`EnvelopeState` is
their real-time twin, one sample per call in plain floats with activity counters; it is
tested against both (tests/actuators/test_envelopes.py).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field

import numpy as np
import torch
from torch import Tensor

from parknss.actuators.config import EnvelopeConfig
from parknss.actuators.shift import ShiftByWire
from parknss.data.trial import Trial
from parknss.errors import CheckpointError, DataError
from parknss.signals import DT, kmh_to_ms

CMD_NAMES: tuple[str, ...] = ("torque_cmd", "decel_cmd", "steer_cmd")


@dataclass(frozen=True)
class Envelope:
    """Command domains [lo, hi] per command channel, output floors, lock (deg), rate (deg/s),
    and the gear rule: shift speed (km/h) and shift time (s) (:mod:`parknss.actuators.shift`;
    an artefact written before the rule carries none and gets the reference's 0.1 km/h and
    0.25 s)."""

    cmd_lo: tuple[float, float, float]
    cmd_hi: tuple[float, float, float]
    torque_floor: float = 0.0
    pressure_floor: float = 0.0
    steer_lock: float = 400.0
    steer_rate_dps: float = 1.0e9
    shift_speed_kmh: float = 0.1
    shift_time_s: float = 0.25
    hold_latch_bar: float = math.inf
    hold_latch_kmh: float = 0.5
    stop_latch_bar: float = math.inf  # the brake-stop latch (module doc); inf: off

    def to_json(self) -> dict:
        d = asdict(self)
        d["hold_latch_bar"] = None if math.isinf(self.hold_latch_bar) else self.hold_latch_bar
        if math.isinf(self.stop_latch_bar):  # off: the artefact stays as before the option
            del d["stop_latch_bar"]
        return d

    @classmethod
    def from_json(cls, d: dict) -> Envelope:
        try:
            env = cls(
                tuple(map(float, d["cmd_lo"])), tuple(map(float, d["cmd_hi"])),
                float(d["torque_floor"]), float(d["pressure_floor"]),
                float(d["steer_lock"]), float(d["steer_rate_dps"]),
                float(d.get("shift_speed_kmh", cls.shift_speed_kmh)),
                float(d.get("shift_time_s", cls.shift_time_s)),
                math.inf if d.get("hold_latch_bar") is None else float(d["hold_latch_bar"]),
                float(d.get("hold_latch_kmh", cls.hold_latch_kmh)),
                math.inf if d.get("stop_latch_bar") is None else float(d["stop_latch_bar"]),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise CheckpointError(f"invalid envelope ({exc})") from exc
        if not (env.shift_speed_kmh >= 0.0 and env.shift_time_s >= 0.0):
            raise CheckpointError("invalid envelope (negative or NaN gear-shift rule)")
        if not (env.hold_latch_bar >= 0.0 and env.hold_latch_kmh >= 0.0):
            raise CheckpointError("invalid envelope (negative or NaN brake-hold latch)")
        if not env.stop_latch_bar >= 0.0:
            raise CheckpointError("invalid envelope (negative or NaN brake-stop latch)")
        return env

    def held(self, pressure: float, vx: float) -> bool:
        """The brake-hold latch (module doc): the brake holds the car at rest when its
        pressure (bar) reaches ``hold_latch_bar`` and |vx| (m/s) is inside the blind zone
        ``hold_latch_kmh``."""
        return pressure >= self.hold_latch_bar and abs(vx) < kmh_to_ms(self.hold_latch_kmh)

    def stops(self, pressure: float, gear: float, vx: float) -> bool:
        """The brake-stop latch (module doc): at pressure (bar) >= ``stop_latch_bar`` a
        car moving (vx m/s) against its engaged gear (-1, 0, 1) is set to rest."""
        return pressure >= self.stop_latch_bar and gear * vx < 0.0

    def shift_rule(self, dt: float = DT) -> ShiftByWire:
        """A fresh :class:`~parknss.actuators.shift.ShiftByWire` with this envelope's rule."""
        return ShiftByWire(self.shift_speed_kmh, self.shift_time_s, dt)


def identify_envelope(trials: Sequence[Trial], cfg: EnvelopeConfig) -> Envelope:
    """Domains and the steering rate limit from the logged commands and actuals."""
    if not trials:
        raise DataError("no trials to identify the envelopes from")

    def span(ch: str) -> tuple[float, float]:
        x = np.concatenate([tr[ch] for tr in trials])
        return float(np.min(x)), float(np.max(x))

    t_lo, t_hi = cfg.torque_domain_nm or span("torque_cmd")
    s_lo, s_hi = cfg.steer_domain_deg or span("steer_cmd")
    lock = cfg.steer_lock_deg
    s_lo, s_hi = max(s_lo, -lock), min(s_hi, lock)
    d_lo, d_hi = cfg.decel_domain_ms2
    slew = max(float(np.max(np.abs(np.diff(tr["steer"])))) / DT for tr in trials if tr.n > 1)
    latch = math.inf
    if cfg.hold_latch:  # the highest pressure the car was seen moving at (above the zone)
        v_edge = kmh_to_ms(cfg.hold_latch_kmh)
        moving = [tr["brake_pressure"][np.abs(tr["vx"]) >= v_edge] for tr in trials]
        p = np.concatenate(moving) if moving else np.zeros(0)
        latch = float(np.max(p)) if p.size else math.inf
    return Envelope(
        (t_lo, d_lo, s_lo), (t_hi, d_hi, s_hi), cfg.torque_floor_nm, cfg.pressure_floor_bar,
        lock, cfg.steer_rate_margin * slew, cfg.max_shift_speed_kmh, cfg.shift_time_s,
        latch, cfg.hold_latch_kmh,
    )


@dataclass
class Activity:
    """How often each envelope acted (samples), per channel."""

    nonfinite: dict[str, int] = field(default_factory=lambda: dict.fromkeys(CMD_NAMES, 0))
    input_clamp: dict[str, int] = field(default_factory=lambda: dict.fromkeys(CMD_NAMES, 0))
    output_floor: dict[str, int] = field(default_factory=lambda: {"torque": 0, "brake_pressure": 0})
    steer_rate: int = 0
    steer_lock: int = 0

    def to_json(self) -> dict:
        return asdict(self)

    def active(self) -> list[str]:
        """Names of the envelopes that acted at least once."""
        out = [f"nonfinite:{k}" for k, v in self.nonfinite.items() if v]
        out += [f"input_clamp:{k}" for k, v in self.input_clamp.items() if v]
        out += [f"output_floor:{k}" for k, v in self.output_floor.items() if v]
        out += ["steer_rate"] * bool(self.steer_rate) + ["steer_lock"] * bool(self.steer_lock)
        return out


class EnvelopeState:
    """The envelopes applied sample by sample (real time), with activity counters."""

    def __init__(self, env: Envelope) -> None:
        self.env = env
        self.activity = Activity()
        self.reset()

    def reset(self, steer: float = 0.0, gear: float = 0.0) -> None:
        self.last = [0.0, 0.0, float(steer)]
        self.gear = float(gear)
        self.steer_prev = float(steer)

    def command(self, gear: float, cmds: Sequence[float]) -> tuple[float, list[float]]:
        """Clean (gear, [torque_cmd, decel_cmd, steer_cmd]) of one sample."""
        if math.isfinite(gear):
            self.gear = gear
        out = []
        for i, c in enumerate(cmds):
            name = CMD_NAMES[i]
            if math.isnan(c):
                self.activity.nonfinite[name] += 1
                c = self.last[i]
            elif math.isinf(c):
                self.activity.nonfinite[name] += 1
            lo, hi = self.env.cmd_lo[i], self.env.cmd_hi[i]
            if c < lo or c > hi:
                self.activity.input_clamp[name] += 1
                c = lo if c < lo else hi
            self.last[i] = c
            out.append(c)
        return self.gear, out

    def output(self, torque: float, pressure: float, steer: float) -> tuple[float, float, float]:
        """Floors, steering rate limit and lock on one sample of submodel outputs."""
        e = self.env
        if torque < e.torque_floor:
            self.activity.output_floor["torque"] += 1
            torque = e.torque_floor
        if pressure < e.pressure_floor:
            self.activity.output_floor["brake_pressure"] += 1
            pressure = e.pressure_floor
        step = e.steer_rate_dps * DT
        lo, hi = self.steer_prev - step, self.steer_prev + step
        if steer < lo or steer > hi:
            self.activity.steer_rate += 1
            steer = lo if steer < lo else hi
        if abs(steer) > e.steer_lock:
            self.activity.steer_lock += 1
            steer = math.copysign(e.steer_lock, steer)
        self.steer_prev = steer
        return torque, pressure, steer


def clean_commands(env: Envelope, cmds: np.ndarray, steer0: np.ndarray | None = None) -> np.ndarray:
    """The input envelope over command histories (B, T, 4) [gear, torque, decel, steer].

    Same rule as :meth:`EnvelopeState.command`; steer0 (B,) is the NaN fill before the
    first clean steering command (default 0).
    """
    c = np.array(cmds, dtype=np.float64, copy=True)
    if c.ndim != 3 or c.shape[2] != 4:
        raise DataError(f"commands must be (B, T, 4) [gear, torque, decel, steer], got {c.shape}")
    B = c.shape[0]
    init = np.zeros((B, 4))
    if steer0 is not None:
        init[:, 3] = steer0
    for j in range(4):
        x = c[:, :, j]
        bad = np.isnan(x)
        if bad.any():  # hold the last clean value
            idx = np.where(~bad, np.arange(x.shape[1])[None], -1)
            idx = np.maximum.accumulate(idx, axis=1)
            held = np.take_along_axis(x, np.maximum(idx, 0), axis=1)
            x = np.where(idx < 0, init[:, j : j + 1], held)
        if j > 0:
            x = np.clip(x, env.cmd_lo[j - 1], env.cmd_hi[j - 1])
        c[:, :, j] = x
    return c


ALL_MODELLED: tuple[bool, bool, bool] = (True, True, True)


def _limit_steer(env: Envelope, steer: Tensor, prev: Tensor) -> Tensor:
    """One sample of the steering envelope: rate limit around prev, then the lock; (B,)."""
    step = env.steer_rate_dps * DT
    s = torch.minimum(torch.maximum(steer, prev - step), prev + step)
    return torch.clamp(s, -env.steer_lock, env.steer_lock)


def limit_outputs_torch(
    env: Envelope,
    torque: Tensor,
    pressure: Tensor,
    steer: Tensor,
    steer_prev: Tensor,
    modelled: tuple[bool, bool, bool] = ALL_MODELLED,
) -> tuple[Tensor, Tensor, Tensor]:
    """The output envelope on submodel outputs, torch (differentiable where it is not active).

    torque N·m, pressure bar, steer deg: each (B, T), a history whose steering angle before
    k = 0 is steer_prev (B,), or each (B,), one sample whose previous angle is steer_prev.
    Floors on torque and pressure, the steering rate limit then the lock, on the channels
    ``modelled`` (drive, brake, steering) only: a measured channel passes as logged.
    """
    if modelled[0]:
        torque = torch.clamp(torque, min=env.torque_floor)
    if modelled[1]:
        pressure = torch.clamp(pressure, min=env.pressure_floor)
    if modelled[2]:
        if steer.ndim == 1:
            steer = _limit_steer(env, steer, steer_prev)
        else:
            outs = []
            prev = steer_prev
            for k in range(steer.shape[1]):
                prev = _limit_steer(env, steer[:, k], prev)
                outs.append(prev)
            steer = torch.stack(outs, dim=1)
    return torque, pressure, steer
