"""The reference vehicle: a physics-based stand-in for the paper's test car, as a Plant.

Per 10 ms step, under the commands {gear, torque_cmd, decel_cmd, steer_cmd}:

1. commands are checked (NaN/inf -> DataError) and clamped by documented rules:
   gear must be -1, 0 or 1; torque_cmd to [0, torque_max]; decel_cmd to
   [decel_cmd_min, 0] (a positive deceleration command means "no braking");
   steer_cmd to ±lock;
2. the actuators advance (gear selector, drive torque with creep, auto-hold, brake
   hydraulics, steering) from the current true speed;
3. the body advances (longitudinal with stiction, yaw with lag), then the IMU-point
   accelerations are formed: ax = dv/dt - x_imu·ω², ay = vx·ω + x_imu·dω/dt;
4. the sensors turn truth into the logged output (quantization, blind zone, noise).

A trial's :class:`~parknss.reference.conditions.TrialConditions` (optional) change the
parameters (mass, rolling radius and resistance, brake, IMU biases) and add the floor's
grade, the wheel-speed scale, the drive-unit drag, the battery power limit, the sensor
misalignment and the gyro drift (:mod:`parknss.reference.environment`); without them the
car is the nominal one on a flat floor.

``step`` returns the logged :class:`~parknss.plant.PlantOutput`; ``last_truth`` holds
the noise-free one. ``simulate`` runs a whole command array in one call.
"""

from __future__ import annotations

import math
import random

import numpy as np

from parknss.errors import DataError
from parknss.plant import Commands, PlantOutput
from parknss.reference.actuators import (
    AutoHold,
    BrakeActuator,
    DriveActuator,
    GearSelector,
    SteeringActuator,
)
from parknss.reference.conditions import TrialConditions
from parknss.reference.dynamics import Lateral, Longitudinal
from parknss.reference.environment import Road, trial_environment
from parknss.reference.params import ReferenceVehicleParams
from parknss.reference.sensors import Bus, Imu, WheelSpeed
from parknss.signals import DT, TRUTH_PREFIX

LOGGED_CHANNELS: tuple[str, ...] = (
    "gear",
    "torque",
    "brake_pressure",
    "steer",
    "vx",
    "yaw_rate",
    "ax",
    "ay",
)
COMMAND_COLUMNS: tuple[str, ...] = ("gear", "torque_cmd", "decel_cmd", "steer_cmd")
TRUTH_CHANNELS: tuple[str, ...] = tuple(
    TRUTH_PREFIX + c
    for c in (
        "vx",
        "yaw_rate",
        "ax",
        "ay",
        "torque",
        "brake_pressure",
        "steer",
        "hold_pressure",
        "pitch",
    )
)


class ReferenceVehicle:
    """The synthetic truth vehicle (implements :class:`parknss.plant.Plant`, dt = 0.01 s).

    Args:
        params: vehicle parameters (defaults: configs/reference_vehicle.yaml values).
        seed: noise seed; None uses ``params.seed``. ``reset`` restarts the noise stream,
            so equal seeds give bit-identical runs.
        conditions: the trial's conditions (None: nominal car, flat floor). ``params``
            stays the nominal vehicle; ``env.params`` holds the trial's effective one.
    """

    dt: float = DT

    def __init__(
        self,
        params: ReferenceVehicleParams | None = None,
        seed: int | None = None,
        conditions: TrialConditions | None = None,
    ):
        self.params = params or ReferenceVehicleParams()
        self.seed = self.params.seed if seed is None else int(seed)
        self.conditions = conditions
        self.env = env = trial_environment(self.params, conditions)
        p, dt = env.params, self.dt
        self.geometry = p.to_geometry()
        self.rng = random.Random(self.seed)
        self.gearbox = GearSelector(p.gear, dt)
        self.drive = DriveActuator(p.drive, dt)
        self.autohold = AutoHold(p.autohold, dt)
        self.brake = BrakeActuator(p.brake, dt)
        self.steering = SteeringActuator(p.steering, p.geometry.steer_lock_deg, dt)
        self.long = Longitudinal(p.body, dt, env.drag_torque_nm)
        self.lat = Lateral(p.lateral, self.geometry, dt)
        self.imu = Imu(p.imu, dt, self.rng, env.imu_roll_rad, env.imu_pitch_rad, env.gyro_drift)
        self.wheel = WheelSpeed(p.wheel_speed, self.rng)
        self.bus = Bus(p.bus, self.rng)
        self.road = Road(env.floor) if env.floor is not None else None
        self.power_limited = env.power_limit_w != float("inf")
        self.force_per_bar = p.brake.force_per_bar
        self.x_imu = p.imu.x_offset_m
        self.last_truth: PlantOutput | None = None
        self.last_output: PlantOutput | None = None
        self.reset()

    # ------------------------------------------------------------------ protocol
    def reset(
        self,
        vx: float = 0.0,
        yaw_rate: float = 0.0,
        steer: float = 0.0,
        gear: int = 0,
        *,
        seed: int | None = None,
    ) -> PlantOutput:
        """Start from the given true state (at rest in park by default); actuators idle.

        Returns the logged output at t = 0. ``seed`` replaces the vehicle's noise seed.
        """
        if seed is not None:
            self.seed = int(seed)
        self.rng.seed(self.seed)
        gear = self._check_gear(gear, "reset")
        self.gearbox.reset(gear)
        self.drive.reset(self.drive.creep(vx, gear))
        self.autohold.reset()
        self.brake.reset()
        self.steering.reset(float(steer))
        self.long.reset(float(vx))
        self.lat.reset(float(yaw_rate), float(vx))
        self.imu.reset()
        if self.road is not None:
            self.road.reset()
        return self._emit(gear, self.drive.torque, 0.0, self.steering.angle)

    def step(self, cmd: Commands) -> PlantOutput:
        """Advance one dt under `cmd`; return the logged output (truth in ``last_truth``)."""
        self._advance(cmd.gear, cmd.torque_cmd, cmd.decel_cmd, cmd.steer_cmd)
        return self.last_output  # type: ignore[return-value]

    # ------------------------------------------------------------------ batch
    def simulate(self, commands: np.ndarray, **reset_kwargs) -> dict[str, np.ndarray]:
        """Reset, then run a (T, 4) command array [gear, torque_cmd, decel_cmd, steer_cmd].

        Row k of every returned array pairs command k with the output observed at time
        k (before command k acts); row 0 is the reset output. Returns float64 arrays of
        shape (T,): ``t``, the commands, the logged channels and the ``truth_*`` ones.
        """
        cmds = np.asarray(commands, dtype=np.float64)
        if cmds.ndim != 2 or cmds.shape[1] != 4:
            raise DataError(f"reference vehicle: commands must have shape (T, 4), got {cmds.shape}")
        T = cmds.shape[0]
        rows: list[tuple[float, ...]] = []
        self.reset(**reset_kwargs)
        for k, (g, tq, dc, st) in enumerate(cmds.tolist()):
            rows.append(self.record())
            if k < T - 1:
                self._advance(g, tq, dc, st)
        out = records_to_arrays(rows)
        for j, name in enumerate(COMMAND_COLUMNS[1:], start=1):
            out[name] = cmds[:, j].copy()
        out["t"] = np.arange(T) * self.dt
        return out

    def record(self) -> tuple[float, ...]:
        """The current logged and truth values as one flat tuple (see RECORD_NAMES)."""
        o, t = self.last_output, self.last_truth
        assert o is not None and t is not None
        return (
            float(o.gear),
            o.torque,
            o.brake_pressure,
            o.steer,
            o.vx,
            o.yaw_rate,
            o.ax,
            o.ay,
            t.vx,
            t.yaw_rate,
            t.ax,
            t.ay,
            t.torque,
            t.brake_pressure,
            t.steer,
            self.autohold.pressure,
            self.imu.pitch,
        )

    # ------------------------------------------------------------------ internals
    @staticmethod
    def _check_gear(gear, where: str) -> int:
        g = float(gear)
        if g not in (-1.0, 0.0, 1.0):
            raise DataError(f"reference vehicle: {where}: gear must be -1, 0 or 1, got {gear!r}")
        return int(g)

    def _clamp(self, torque_cmd: float, decel_cmd: float, steer_cmd: float):
        for name, v in (
            ("torque_cmd", torque_cmd),
            ("decel_cmd", decel_cmd),
            ("steer_cmd", steer_cmd),
        ):
            if not math.isfinite(v):
                raise DataError(f"reference vehicle: command {name} is not finite ({v!r})")
        p = self.params
        lock = p.geometry.steer_lock_deg
        return (
            min(max(torque_cmd, 0.0), p.drive.torque_max_nm),
            min(max(decel_cmd, p.brake.decel_cmd_min), 0.0),
            min(max(steer_cmd, -lock), lock),
        )

    def _advance(self, gear_cmd, torque_cmd, decel_cmd, steer_cmd) -> None:
        gear_req = self._check_gear(gear_cmd, "command")
        torque_cmd, decel_cmd, steer_cmd = self._clamp(
            float(torque_cmd), float(decel_cmd), float(steer_cmd)
        )
        v0 = self.long.vx
        if self.road is not None:
            self.long.set_grade(self.road.pitch)
        if self.power_limited:
            self.drive.limit = self.env.torque_available(v0)
        gear = self.gearbox.step(gear_req, v0)
        torque = self.drive.step(torque_cmd, gear, self.gearbox.shifting, v0)
        floor = self.autohold.step(v0, self.brake.pressure, torque, gear)
        pressure = self.brake.step(decel_cmd, floor)
        steer = self.steering.step(steer_cmd)
        vx = self.long.step(torque, gear, pressure * self.force_per_bar)
        w = self.lat.step(vx, steer)
        if self.road is not None:
            self.road.step(vx, w, self.dt)
        self._emit(gear, torque, pressure, steer)

    def _emit(self, gear: int, torque: float, pressure: float, steer: float) -> PlantOutput:
        """Form truth and logged outputs from the current state; store and return logged."""
        vx, w, dw = self.long.vx, self.lat.yaw_rate, self.lat.yaw_accel
        ax = self.long.accel - self.x_imu * w * w
        ay = vx * w + self.x_imu * dw
        self.last_truth = PlantOutput(gear, torque, pressure, steer, vx, w, ax, ay)
        if self.road is not None:
            ax_m, ay_m, w_m = self.imu.step(ax, ay, w, self.road.pitch, self.road.bank)
        else:
            ax_m, ay_m, w_m = self.imu.step(ax, ay, w)
        self.last_output = PlantOutput(
            gear,
            self.bus.torque(torque),
            self.bus.pressure(pressure),
            self.bus.steer(steer),
            self.wheel.read(vx * self.env.speed_scale),
            w_m,
            ax_m,
            ay_m,
        )
        return self.last_output


RECORD_NAMES: tuple[str, ...] = LOGGED_CHANNELS + TRUTH_CHANNELS


def records_to_arrays(rows: list[tuple[float, ...]]) -> dict[str, np.ndarray]:
    """Turn a list of :meth:`ReferenceVehicle.record` tuples into channel arrays (T,)."""
    mat = np.asarray(rows, dtype=np.float64).reshape(len(rows), len(RECORD_NAMES))
    return {name: mat[:, j].copy() for j, name in enumerate(RECORD_NAMES)}
