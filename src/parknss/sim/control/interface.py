"""The command interface of §IV-C: tracker requests -> {gear, torque_cmd, decel_cmd, steer_cmd}.

Three parts, run once per 10 ms on what the car's bus reports (measured vx, engaged gear):

* **Gear state machine.** The commanded gear follows the requested direction (+1 drive,
  -1 reverse, 0 park) only at confirmed standstill: the brake-hold applied, the measured
  |vx| below ``standstill_speed_ms`` for ``standstill_time_s`` without a break, *and* the
  car's speed accounted for down to zero. The wheel-speed sensor reads 0 inside its blind
  zone (|vx| < 0.139 m/s), so a car still rolling at 0.1 m/s reads like one at rest; the
  interface therefore starts from the last speed it measured (the blind-zone edge when
  it last read 0 while driving) and integrates the deceleration the car reports along
  its motion (ax) down to 0. Should ax not show the stop (a biased or missing IMU), the
  hold itself settles it: once the commanded hold has ramped to ``hold_max_ms2`` and
  ``standstill_brake_lag_s`` has passed, the time that deceleration needs to stop the
  last measured speed. A speed sensor that does read inside the band (|vx| >=
  ``standstill_read_ms``, e.g. the learned chain's output) is believed: the car moves.
  Only then does the confirmation count. Reverse <-> drive shifts
  go directly, never through neutral. Park (gear 0) pins the
  state at rest: torque_cmd is 0 whenever the commanded gear is 0 (neutral/park never
  carries torque), and the brake-hold stays applied.
* **Longitudinal controller.** A PI on the speed along the gear direction with request
  feed-forward gives a desired acceleration a (m/s²). With hysteresis (±
  ``hysteresis_ms2``) it is sent either as a drive torque (torque_cmd = offset +
  gain·a >= 0, decel_cmd = 0) or as a deceleration request (decel_cmd = a <= 0,
  torque_cmd = 0), never both. A launch from standstill ramps a minimum torque until
  the wheel speed leaves the standstill band (pushing through an auto-hold).
* **Brake-hold.** Whenever the car must stand (a stop, a gear change, park, or a speed
  request of 0) the commanded deceleration is raised to ``hold_decel_ms2`` and keeps
  rising at ``hold_ramp_ms3`` (up to ``hold_max_ms2``) while the car has not yet stopped,
  then held: a fixed gentle brake would lose to the creep torque.

Besides the Commands the interface exposes ``speed_target`` (signed m/s: what its speed
controller is steering to after gear logic and hold), which the ideal kinematic plant
executes directly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from pydantic import Field

from parknss.config import StrictModel, load_config, shipped_config
from parknss.errors import ConfigError, ParknssError
from parknss.plant import Commands, PlantOutput
from parknss.signals import BLIND_ZONE_MS, DT

HOLD, LAUNCH, DRIVE = "hold", "launch", "drive"


class InterfaceConfig(StrictModel):
    """Gains of the command interface (configs/interface.yaml)."""

    standstill_speed_ms: float = Field(
        BLIND_ZONE_MS, gt=0, description="measured |vx| below this counts as stopped, m/s"
    )
    standstill_time_s: float = Field(0.3, ge=0, description="stop confirmed after, s")
    kp: float = Field(2.535, ge=0, description="speed-error gain, (m/s²)/(m/s)")
    ki: float = Field(1.3, ge=0, description="speed-error integral gain, (m/s²)/m")
    kff: float = Field(1.3, ge=0, description="feed-forward of the requested acceleration, -")
    integral_max_ms2: float = Field(0.6, ge=0, description="integral clamp, m/s²")
    hysteresis_ms2: float = Field(0.05, ge=0, description="torque/brake switch band, m/s²")
    torque_per_accel: float = Field(90.0, gt=0, description="drive torque per m/s², N·m/(m/s²)")
    torque_offset_nm: float = Field(10.0, ge=0, description="torque at a = 0 (resistance), N·m")
    torque_max_nm: float = Field(150.0, gt=0, description="torque command ceiling, N·m")
    decel_min_ms2: float = Field(-2.0, lt=0, description="strongest decel command, m/s²")
    hold_decel_ms2: float = Field(0.546, gt=0, description="brake-hold initial decel, m/s²")
    hold_ramp_ms3: float = Field(0.91, ge=0, description="brake-hold rise while moving, m/s³")
    hold_max_ms2: float = Field(2.0, gt=0, description="brake-hold ceiling, m/s²")
    launch_torque_nm: float = Field(28.0, ge=0, description="minimum launch torque, N·m")
    launch_rate_nms: float = Field(150.0, gt=0, description="launch torque ramp, N·m/s")
    standstill_read_ms: float = Field(
        0.02, gt=0, description="a measured |vx| at or above this inside the band is motion, m/s"
    )
    standstill_brake_lag_s: float = Field(
        0.3, ge=0, description="brake-hold assumed to act this long after it is commanded, s"
    )  # used only when ax does not show the stop (see hold_settle_s)
    steer_lock_deg: float = Field(
        400.0, gt=0, description="steer_cmd clamp without a vehicle, ±deg (else the car's lock)"
    )
    steer_rate_dps: float = Field(0.0, ge=0, description="steer_cmd slew limit (0: none), deg/s")


def load_interface_config(path: str | Path | None = None) -> InterfaceConfig:
    """Read ``path`` (default: the shipped configs/interface.yaml)."""
    cfg = load_config(InterfaceConfig, path, default="interface.yaml")
    if cfg.hold_max_ms2 < cfg.hold_decel_ms2:
        where = path if path is not None else shipped_config("interface.yaml")
        raise ConfigError(f"{where}: hold_max_ms2 must be >= hold_decel_ms2")
    return cfg


@dataclass(frozen=True)
class Request:
    """What the tracker asks for, once per 10 ms.

    Attributes:
        direction: +1 drive, -1 reverse, 0 park.
        speed: speed magnitude along the direction, m/s (>= 0; 0 means stop and hold).
        steer: steering-wheel angle, deg.
        accel: rate of change of the speed request, m/s² (feed-forward).
    """

    direction: int
    speed: float
    steer: float
    accel: float = 0.0


class CommandInterface:
    """Turns :class:`Request` into :class:`~parknss.plant.Commands` (see module docstring).

    ``steer_lock_deg`` is the car's steering-wheel lock (deg): steer_cmd is clamped to it
    (every closed-loop plant passes its vehicle's); None: the config's ``steer_lock_deg``.
    """

    def __init__(
        self,
        cfg: InterfaceConfig | None = None,
        dt: float = DT,
        steer_lock_deg: float | None = None,
    ) -> None:
        self.cfg = cfg or InterfaceConfig()
        self.dt = float(dt)
        self.steer_lock_deg = float(
            self.cfg.steer_lock_deg if steer_lock_deg is None else steer_lock_deg
        )
        if not (math.isfinite(self.steer_lock_deg) and self.steer_lock_deg > 0):
            raise ConfigError(f"command interface: steering lock {steer_lock_deg!r} deg")
        self.reset()

    def reset(self) -> None:
        """At rest in park with the brake-hold applied; standstill not yet confirmed."""
        self.gear = 0
        self.mode = HOLD
        self.hold_level = self.cfg.hold_decel_ms2
        self.integral = 0.0
        self.still_time = 0.0
        self.launch_time = 0.0
        self.braking = True
        self.speed_target = 0.0
        self.steer = 0.0
        self.shifts = 0
        self.speed_left = 0.0  # speed not yet accounted for down to 0, m/s (>= 0)
        self.speed_entry = 0.0  # the speed last measured before the hold, m/s
        self.hold_time = 0.0  # time since the brake-hold was commanded, s
        self.motion_sign = 0  # direction of the last measured motion, ±1 (0: none yet)

    @property
    def standstill(self) -> bool:
        """Standstill confirmed: held, measured |vx| in the band for the confirm time, and
        the last measured speed accounted for down to 0 (module docstring)."""
        return self.still_time >= self.cfg.standstill_time_s - 1e-9 and self.speed_left <= 0.0

    def _track_speed(self, u: float, ax: float) -> None:
        """Update the speed still unaccounted for from the measured vx and ax (m/s, m/s²)."""
        c, dt = self.cfg, self.dt
        if u != 0.0:
            self.motion_sign = 1 if u > 0 else -1
        if self.mode != HOLD or abs(u) >= c.standstill_speed_ms:
            # a reading is the speed; a 0 while driving may be anything in the blind zone
            self.speed_left = abs(u) if u != 0.0 or self.mode == HOLD else c.standstill_speed_ms
            self.speed_entry = self.speed_left
            return
        if abs(u) >= c.standstill_read_ms:  # a sensor that reads inside the band: it moves
            self.speed_left = abs(u)
            return
        decel = -self.motion_sign * ax if self.motion_sign else 0.0
        self.speed_left = min(max(self.speed_left - decel * dt, 0.0), c.standstill_speed_ms)
        if self.hold_time >= self.hold_settle_s(self.speed_entry) - 1e-9:
            self.speed_left = 0.0

    def hold_settle_s(self, speed: float) -> float:
        """Time (s) after which the brake-hold has stopped a car at ``speed`` (m/s) whatever
        ax says: the brake lag, the ramp to ``hold_max_ms2``, then speed / hold_max."""
        c = self.cfg
        ramp = (c.hold_max_ms2 - c.hold_decel_ms2) / c.hold_ramp_ms3 if c.hold_ramp_ms3 else 0.0
        top = c.hold_max_ms2 if c.hold_ramp_ms3 else c.hold_decel_ms2
        return c.standstill_brake_lag_s + ramp + speed / top

    def step(self, req: Request, y: PlantOutput) -> Commands:
        """One 10 ms update from the request and the bus output ``y`` of this sample."""
        c, dt = self.cfg, self.dt
        if req.direction not in (-1, 0, 1):
            raise ConfigError(f"command interface: request direction {req.direction!r}")
        for name, v in (
            ("request speed", req.speed),
            ("request accel", req.accel),
            ("request steer", req.steer),
            ("measured vx", y.vx),
        ):
            if not math.isfinite(v):
                raise ParknssError(f"command interface: {name} is not finite ({v!r})")
        if req.speed < 0.0:
            raise ParknssError(f"command interface: request speed {req.speed!r} < 0")
        speed, u = req.speed, y.vx
        self.hold_time = self.hold_time + dt if self.mode == HOLD else 0.0
        self._track_speed(u, y.ax if math.isfinite(y.ax) else 0.0)
        still = self.mode == HOLD and abs(u) < c.standstill_speed_ms
        self.still_time = self.still_time + dt if still else 0.0
        if req.direction != self.gear and self.mode == HOLD and self.standstill:
            self.gear = req.direction  # R <-> D directly; 0 only as park
            self.shifts += 1
        go = self.gear != 0 and req.direction == self.gear and y.gear == self.gear and speed > 0.0
        if not go:
            torque, decel = self._hold()
        else:
            torque, decel = self._drive(speed, req.accel, u)
        if self.gear == 0:
            torque = 0.0  # neutral/park never carries torque
        return Commands(self.gear, torque, decel, self._steer(req.steer))

    # ------------------------------------------------------------------ parts
    def _hold(self) -> tuple[float, float]:
        """Brake-hold: raise the deceleration until stopped, then keep it; no torque."""
        c = self.cfg
        if self.mode != HOLD:
            self.mode = HOLD
            self.hold_level = c.hold_decel_ms2
        elif not self.standstill:
            self.hold_level = min(self.hold_level + c.hold_ramp_ms3 * self.dt, c.hold_max_ms2)
        self.integral = 0.0
        self.speed_target = 0.0
        return 0.0, -self.hold_level

    def _drive(self, speed: float, accel: float, u: float) -> tuple[float, float]:
        """PI speed control along the gear direction, torque or brake with hysteresis."""
        c, dt = self.cfg, self.dt
        if self.mode == HOLD:
            self.mode, self.launch_time, self.integral, self.braking = LAUNCH, 0.0, 0.0, False
        along = self.gear * u
        err = speed - along
        a = c.kff * accel + c.kp * err + self.integral
        if self.mode != LAUNCH:  # the launch ramp, not the integral, breaks the car away
            self.integral = min(
                max(self.integral + c.ki * err * dt, -c.integral_max_ms2), c.integral_max_ms2
            )
        if self.braking and a > c.hysteresis_ms2:
            self.braking = False
        elif not self.braking and a < -c.hysteresis_ms2:
            self.braking = True
        if self.mode == LAUNCH:
            self.launch_time += dt
            if abs(u) >= c.standstill_speed_ms:
                self.mode = DRIVE
        self.speed_target = self.gear * speed
        if self.mode == LAUNCH:
            ramp = min(c.launch_rate_nms * self.launch_time, c.launch_torque_nm)
            tq = max(ramp, c.torque_offset_nm + c.torque_per_accel * a)
            self.braking = False
            return min(tq, c.torque_max_nm), 0.0
        if self.braking:
            return 0.0, max(min(a, 0.0), c.decel_min_ms2)
        tq = c.torque_offset_nm + c.torque_per_accel * a
        return min(max(tq, 0.0), c.torque_max_nm), 0.0

    def _steer(self, target: float) -> float:
        """Clamp (and optionally slew-limit) the steering request, deg."""
        c, lock = self.cfg, self.steer_lock_deg
        t = min(max(target, -lock), lock)
        if c.steer_rate_dps > 0.0:
            step = c.steer_rate_dps * self.dt
            t = self.steer + min(max(t - self.steer, -step), step)
        self.steer = t
        return t
