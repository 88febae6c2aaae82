"""The executed vehicles of the closed loop: kinematic, chain (learned) and reference plants.

Every plant here is a :class:`SimPlant`: ``reset()`` puts the car at rest in park,
``advance(act)`` moves it one dt = 10 ms under one :class:`Actuation` and returns what the
car's bus reports (:class:`~parknss.plant.PlantOutput`), and ``motion`` gives the
(vx m/s, yaw rate rad/s) that moved the rear axle during that step, from which the closed
loop integrates the pose with :class:`PoseIntegrator`. The planner keeps its own
kinematic model; only the executed plant changes.

What each plant consumes (the design choice, stated once):

* An :class:`Actuation` is the command interface's output: the production command set
  {gear, torque_cmd, decel_cmd, steer_cmd} (:class:`~parknss.plant.Commands`) plus the
  interface's own signed speed target (m/s), i.e. the speed its longitudinal controller
  is trying to reach after the gear logic and the brake-hold have had their say.
* :class:`KinematicPlant` (ideal) executes the speed target and ``steer_cmd`` at once:
  vx = speed target (zero unless the engaged gear agrees with its sign), steering angle
  = ``steer_cmd``, yaw rate from the kinematic bicycle with the constant ratio (the
  planner's model). It ignores torque and deceleration: it has no actuators. The gear
  state machine, stops and standstill still run through the interface.
* :class:`ReferencePlant` (the synthetic truth vehicle) and :class:`ChainPlant` (the
  learned command-to-vehicle chain) consume only the Commands, as a real car does.

The controller sees the bus output (the reference vehicle's wheel-speed blind zone,
noise and quantization included); the pose moves with the plant's true motion (the
reference's noise-free truth; the chain's and the kinematic plant's own states).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np

from parknss.config import CONFIG_DIR, SHIPPED_CHAIN
from parknss.errors import CheckpointError, ConfigError, ParknssError
from parknss.plant import Commands, Plant, PlantOutput
from parknss.signals import DT
from parknss.vehicle import VehicleGeometry, yaw_rate_ref

PLANT_KINDS: tuple[str, ...] = ("kinematic", "chain", "reference")


@dataclass(frozen=True)
class Actuation:
    """One 10 ms output of the command interface.

    Attributes:
        commands: the production command set sent to a real (or learned) car.
        speed_target: the interface's signed speed target, m/s (negative in reverse);
            only the ideal kinematic plant executes it.
    """

    commands: Commands
    speed_target: float


@runtime_checkable
class SimPlant(Protocol):
    """A plant the closed loop can execute (see the module docstring)."""

    name: str
    dt: float

    def reset(self) -> PlantOutput:
        """Put the car at rest in park; return the first bus output."""
        ...

    def advance(self, act: Actuation) -> PlantOutput:
        """Advance one dt under ``act``; return the bus output at the end of the step."""
        ...

    @property
    def motion(self) -> tuple[float, float]:
        """(vx m/s, yaw rate rad/s) that moved the rear axle during the last step."""
        ...


# ---------------------------------------------------------------------------------------
# Pose integration


class PoseIntegrator:
    """Rear-axle pose (x m, y m, heading rad) integrated from vx and yaw rate.

    Each step moves along the exact circular arc of constant (vx, ω) over dt: the
    heading turns by ω·dt and the position moves vx·dt along the chord direction
    heading + ω·dt/2 shortened by sinc(ω·dt/2). This is exact whenever vx and ω are
    constant over the step (so a constant-speed, constant-steer run traces an exact
    circle of radius vx/ω).
    """

    def __init__(self, pose, dt: float = DT) -> None:
        self.dt = float(dt)
        self.x, self.y, self.heading = (float(v) for v in pose)

    @property
    def pose(self) -> tuple[float, float, float]:
        return (self.x, self.y, self.heading)

    def step(self, vx: float, yaw_rate: float) -> tuple[float, float, float]:
        """Advance one dt at speed vx (m/s, signed) and yaw rate (rad/s); return the pose."""
        ds = vx * self.dt
        dth = yaw_rate * self.dt
        half = 0.5 * dth
        chord = ds * (math.sin(half) / half if abs(half) > 1e-12 else 1.0 - half * half / 6.0)
        ang = self.heading + half
        self.x += chord * math.cos(ang)
        self.y += chord * math.sin(ang)
        self.heading += dth
        return self.pose


def integrate_poses(start, vx: np.ndarray, yaw_rate: np.ndarray, dt: float = DT) -> np.ndarray:
    """(T+1, 3) poses from ``start`` under per-step (vx, yaw rate) arrays of shape (T,)."""
    integ = PoseIntegrator(start, dt)
    out = np.empty((len(vx) + 1, 3))
    out[0] = integ.pose
    for k, (v, w) in enumerate(
        zip(np.asarray(vx, float), np.asarray(yaw_rate, float), strict=True)
    ):
        out[k + 1] = integ.step(float(v), float(w))
    return out


# ---------------------------------------------------------------------------------------
# Plants


def _finite(cmd: Commands, who: str) -> None:
    for name in ("torque_cmd", "decel_cmd", "steer_cmd"):
        v = getattr(cmd, name)
        if not math.isfinite(v):
            raise ParknssError(f"{who}: command {name} is not finite ({v!r})")
    if cmd.gear not in (-1, 0, 1):
        raise ParknssError(f"{who}: gear must be -1, 0 or 1, got {cmd.gear!r}")


class KinematicPlant:
    """The ideal plant: the interface's speed target and steering happen at once.

    vx = speed target when the commanded gear agrees with its sign (0 otherwise, and in
    park), steering angle = steer_cmd clamped to the lock, yaw rate = vx/L·tan(δ/i) with
    the constant ratio (the planner's model), ax = Δvx/dt, ay = vx·ω (at the rear axle).
    Torque and brake pressure are reported as 0: there are no actuators.
    """

    name = "kinematic"

    def __init__(self, geom: VehicleGeometry | None = None, dt: float = DT) -> None:
        self.geom = geom or VehicleGeometry()
        self.dt = float(dt)
        self.reset()

    def reset(self) -> PlantOutput:
        self._vx = self._w = self._steer = 0.0
        self._out = PlantOutput(0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        return self._out

    def advance(self, act: Actuation) -> PlantOutput:
        cmd = act.commands
        _finite(cmd, "kinematic plant")
        lock = self.geom.steer_lock_deg
        steer = min(max(cmd.steer_cmd, -lock), lock)
        v = float(act.speed_target)
        if not math.isfinite(v):
            raise ParknssError(f"kinematic plant: speed target is not finite ({v!r})")
        if cmd.gear == 0 or v * cmd.gear < 0.0:
            v = 0.0
        w = float(yaw_rate_ref(v, steer, self.geom))
        ax = (v - self._vx) / self.dt
        self._vx, self._w, self._steer = v, w, steer
        self._out = PlantOutput(cmd.gear, 0.0, 0.0, steer, v, w, ax, v * w)
        return self._out

    @property
    def motion(self) -> tuple[float, float]:
        return (self._vx, self._w)


class _WrappedPlant:
    """A Commands-level :class:`~parknss.plant.Plant` as a SimPlant.

    The pose moves with the mean of the state before and after each step (trapezoidal),
    read from ``truth()`` (the noise-free state where the plant has one).
    """

    name = "plant"

    def __init__(self, plant: Plant) -> None:
        self.plant = plant
        self.dt = float(plant.dt)
        self._prev = (0.0, 0.0)
        self._motion = (0.0, 0.0)

    def truth(self, out: PlantOutput) -> PlantOutput:
        """The noise-free output of the last step (the bus output where there is none)."""
        return out

    def reset(self) -> PlantOutput:
        out = self.plant.reset()
        t = self.truth(out)
        self._prev = (t.vx, t.yaw_rate)
        self._motion = (0.0, 0.0)
        return out

    def advance(self, act: Actuation) -> PlantOutput:
        _finite(act.commands, f"{self.name} plant")
        out = self.plant.step(act.commands)
        t = self.truth(out)
        self._motion = (0.5 * (self._prev[0] + t.vx), 0.5 * (self._prev[1] + t.yaw_rate))
        self._prev = (t.vx, t.yaw_rate)
        return out

    @property
    def motion(self) -> tuple[float, float]:
        return self._motion


class ReferencePlant(_WrappedPlant):
    """The synthetic truth vehicle (:class:`parknss.reference.vehicle.ReferenceVehicle`).

    Args:
        vehicle_yaml: vehicle parameter file (default configs/reference_vehicle.yaml).
        seed: sensor-noise seed (None: the file's seed).
    """

    name = "reference"

    def __init__(self, vehicle_yaml: str | Path | None = None, seed: int | None = None):
        from parknss.reference.params import load_vehicle_params
        from parknss.reference.vehicle import ReferenceVehicle

        path = Path(vehicle_yaml) if vehicle_yaml else CONFIG_DIR / "reference_vehicle.yaml"
        params = load_vehicle_params(path if path.is_file() or vehicle_yaml else None)
        self.vehicle = ReferenceVehicle(params, seed=seed)
        self.geom = self.vehicle.geometry
        super().__init__(self.vehicle)

    def truth(self, out: PlantOutput) -> PlantOutput:
        return self.vehicle.last_truth or out


class ChainPlant(_WrappedPlant):
    """The learned command-to-vehicle chain (envelopes -> actuator models -> NSS).

    Loads ``parknss.chain.load_chain(path)`` lazily (default: the shipped chain in
    models/chain) and steps it in real time. The chain must implement the
    :class:`~parknss.plant.Plant` protocol (reset/step with Commands). Raises
    :class:`~parknss.errors.ParknssError` with one line when the chain module or the
    checkpoint is unavailable; there is no stand-in.
    """

    name = "chain"

    def __init__(self, path: str | Path | None = None) -> None:
        try:
            from parknss.chain import load_chain
        except ImportError as exc:
            raise ParknssError(
                "chain plant unavailable: parknss.chain is not installed in this build "
                "(use --plant kinematic or reference)"
            ) from exc
        p = Path(path) if path else SHIPPED_CHAIN
        try:
            chain = load_chain(p)
        except ParknssError:
            raise
        except (OSError, ValueError, KeyError) as exc:
            raise CheckpointError(f"{p}: cannot load the chain ({exc})") from exc
        if not isinstance(chain, Plant):
            raise CheckpointError(f"{p}: loaded chain does not implement reset/step (Plant)")
        super().__init__(chain)


def make_plant(
    kind: str,
    *,
    geom: VehicleGeometry | None = None,
    vehicle_yaml: str | Path | None = None,
    chain_path: str | Path | None = None,
    seed: int | None = None,
) -> SimPlant:
    """Build a plant by kind: "kinematic", "chain" or "reference"."""
    if kind == "kinematic":
        return KinematicPlant(geom)
    if kind == "reference":
        return ReferencePlant(vehicle_yaml, seed)
    if kind == "chain":
        return ChainPlant(chain_path)
    raise ConfigError(f"unknown plant {kind!r}; one of {', '.join(PLANT_KINDS)}")
