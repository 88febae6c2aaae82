"""The executed vehicles of the closed loop: kinematic, chain (learned) and reference plants.

Every plant here is a :class:`~parknss.plant.Plant` (``reset``; ``step(Commands)`` moves
the car one dt = 10 ms and returns what its bus reports), which is the one protocol the
closed loop drives. A :class:`SimPlant` adds what the closed loop needs beside it: a
``name``, the ``motion`` (vx m/s, yaw rate rad/s) that moved the rear axle during the last
step, from which the loop integrates the pose with :class:`PoseIntegrator`, and the
``command_interface`` that turns the tracker's requests into the plant's Commands. The
planner keeps its own kinematic model; only the executed plant changes.

What each plant consumes (the design choice, stated once):

* :class:`ReferencePlant` (the synthetic truth vehicle) and :class:`ChainPlant` (the
  learned command-to-vehicle chain) consume only the Commands {gear, torque_cmd,
  decel_cmd, steer_cmd}, as a real car does, from the production
  :class:`~parknss.sim.control.interface.CommandInterface`.
* :class:`KinematicPlant` (ideal) has no actuators: it executes a speed at once. Its speed
  comes through its own adapter, :class:`KinematicInterface`: the production command
  interface (gear state machine, brake-hold, standstill confirmation) that hands the
  plant its signed speed target with every command. The plant drives vx = that target
  (zero unless the engaged gear agrees with its sign), steering angle = ``steer_cmd``,
  yaw rate from the kinematic bicycle with the constant ratio (the planner's model). It
  ignores torque and deceleration.

The controller sees the bus output (the reference vehicle's wheel-speed blind zone,
noise and quantization included); the pose moves with the plant's true motion (the
reference's noise-free truth; the chain's and the kinematic plant's own states).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np

from parknss.config import SHIPPED_PLANT
from parknss.errors import CheckpointError, ConfigError, ParknssError
from parknss.plant import Commands, Plant, PlantOutput
from parknss.signals import DT
from parknss.sim.control.interface import CommandInterface, InterfaceConfig, Request
from parknss.sim.vehicles import check_chain_vehicle
from parknss.vehicle import VehicleGeometry, arc_step, yaw_rate_ref

PLANT_KINDS: tuple[str, ...] = ("kinematic", "chain", "reference")


@runtime_checkable
class SimPlant(Plant, Protocol):
    """A :class:`~parknss.plant.Plant` as the closed loop executes it (module docstring)."""

    name: str

    @property
    def motion(self) -> tuple[float, float]:
        """(vx m/s, yaw rate rad/s) that moved the rear axle during the last step."""
        ...

    def command_interface(
        self, cfg: InterfaceConfig | None = None, dt: float = DT
    ) -> CommandInterface:
        """The command interface that drives this plant (a fresh one per run)."""
        ...


# ---------------------------------------------------------------------------------------
# Pose integration


class PoseIntegrator:
    """Rear-axle pose (x m, y m, heading rad) integrated from vx and yaw rate.

    Each step moves along the exact circular arc of constant (vx, ω) over dt
    (:func:`parknss.vehicle.arc_step` with ds = vx·dt, dheading = ω·dt), exact whenever
    vx and ω are constant over the step (so a constant-speed, constant-steer run traces
    an exact circle of radius vx/ω).
    """

    def __init__(self, pose, dt: float = DT) -> None:
        self.dt = float(dt)
        self.x, self.y, self.heading = (float(v) for v in pose)

    @property
    def pose(self) -> tuple[float, float, float]:
        return (self.x, self.y, self.heading)

    def step(self, vx: float, yaw_rate: float) -> tuple[float, float, float]:
        """Advance one dt at speed vx (m/s, signed) and yaw rate (rad/s); return the pose."""
        self.x, self.y, self.heading = arc_step(
            self.x, self.y, self.heading, vx * self.dt, yaw_rate * self.dt
        )
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
    """The ideal plant: its speed target and the steering happen at once.

    vx = ``speed_target`` (m/s, signed; set by its :class:`KinematicInterface` before
    each step) when the commanded gear agrees with its sign (0 otherwise, and in park),
    steering angle = steer_cmd clamped to the lock, yaw rate = vx/L·tan(δ/i) with the
    constant ratio (the planner's model), ax = Δvx/dt, ay = vx·ω (at the rear axle).
    Torque and brake pressure are reported as 0: there are no actuators.
    """

    name = "kinematic"

    def __init__(self, geom: VehicleGeometry | None = None, dt: float = DT) -> None:
        self.geom = geom or VehicleGeometry()
        self.dt = float(dt)
        self.reset()

    def reset(
        self, vx: float = 0.0, yaw_rate: float = 0.0, steer: float = 0.0, gear: int = 0
    ) -> PlantOutput:
        """Start from the given state (at rest in park by default); return its output."""
        self._vx, self._w, self._steer = float(vx), float(yaw_rate), float(steer)
        self.speed_target = self._vx
        self._out = PlantOutput(int(gear), 0.0, 0.0, self._steer, self._vx, self._w, 0.0, 0.0)
        return self._out

    def step(self, cmd: Commands) -> PlantOutput:
        """Advance one dt: drive ``speed_target`` in the commanded gear, steer ``steer_cmd``."""
        _finite(cmd, "kinematic plant")
        lock = self.geom.steer_lock_deg
        steer = min(max(cmd.steer_cmd, -lock), lock)
        v = float(self.speed_target)
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

    def command_interface(
        self, cfg: InterfaceConfig | None = None, dt: float = DT
    ) -> KinematicInterface:
        return KinematicInterface(self, cfg, dt)


class KinematicInterface(CommandInterface):
    """The kinematic plant's adapter: the production command interface, which also hands
    the plant its signed speed target (m/s; 0 while it holds, gear · requested speed
    while it drives) with every command, so the ideal plant executes the speed the
    interface's longitudinal controller is trying to reach."""

    def __init__(
        self, plant: KinematicPlant, cfg: InterfaceConfig | None = None, dt: float = DT
    ) -> None:
        super().__init__(cfg, dt, plant.geom.steer_lock_deg)
        self.plant = plant

    def step(self, req: Request, y: PlantOutput) -> Commands:
        cmd = super().step(req, y)
        self.plant.speed_target = self.speed_target
        return cmd


class _TruthPlant:
    """A Commands-level :class:`~parknss.plant.Plant` with a name and a motion.

    The pose moves with the mean of the state before and after each step (trapezoidal),
    read from ``truth()`` (the noise-free state where the plant has one). Driven by the
    production :class:`~parknss.sim.control.interface.CommandInterface`.
    """

    name = "plant"
    geom: VehicleGeometry | None = None  # the car, where the plant knows it

    def __init__(self, plant: Plant) -> None:
        self.plant = plant
        self.dt = float(plant.dt)
        self._prev = (0.0, 0.0)
        self._motion = (0.0, 0.0)

    def truth(self, out: PlantOutput) -> PlantOutput:
        """The noise-free output of the last step (the bus output where there is none)."""
        return out

    def reset(
        self, vx: float = 0.0, yaw_rate: float = 0.0, steer: float = 0.0, gear: int = 0
    ) -> PlantOutput:
        """Start the wrapped plant from the given state (at rest in park by default)."""
        out = self.plant.reset(vx, yaw_rate, steer, gear)
        t = self.truth(out)
        self._prev = (t.vx, t.yaw_rate)
        self._motion = (0.0, 0.0)
        return out

    def step(self, cmd: Commands) -> PlantOutput:
        _finite(cmd, f"{self.name} plant")
        return self._took(self.plant.step(cmd))

    def _took(self, out: PlantOutput) -> PlantOutput:
        """Record the wrapped plant's output of one step (the motion); return it."""
        t = self.truth(out)
        self._motion = (0.5 * (self._prev[0] + t.vx), 0.5 * (self._prev[1] + t.yaw_rate))
        self._prev = (t.vx, t.yaw_rate)
        return out

    @property
    def motion(self) -> tuple[float, float]:
        return self._motion

    def command_interface(
        self, cfg: InterfaceConfig | None = None, dt: float = DT
    ) -> CommandInterface:
        lock = None if self.geom is None else self.geom.steer_lock_deg
        return CommandInterface(cfg, dt, lock)


class ReferencePlant(_TruthPlant):
    """The synthetic truth vehicle (:class:`parknss.reference.vehicle.ReferenceVehicle`).

    Args:
        vehicle_yaml: vehicle parameter file (default: the shipped reference_vehicle.yaml).
        seed: sensor-noise seed (None: the file's seed).
        vehicle: a reference vehicle built elsewhere (a trial's car under its conditions,
            :mod:`parknss.sim.stack_trials`); ``vehicle_yaml`` and ``seed`` are then unused.
    """

    name = "reference"

    def __init__(
        self, vehicle_yaml: str | Path | None = None, seed: int | None = None, vehicle=None
    ):
        from parknss.reference.params import load_vehicle_params
        from parknss.reference.vehicle import ReferenceVehicle

        if vehicle is None:
            vehicle = ReferenceVehicle(load_vehicle_params(vehicle_yaml or None), seed=seed)
        self.vehicle = vehicle
        self.geom = self.vehicle.geometry
        super().__init__(self.vehicle)

    def truth(self, out: PlantOutput) -> PlantOutput:
        return self.vehicle.last_truth or out


class ChainPlant(_TruthPlant):
    """The learned command-to-vehicle chain (envelopes -> actuator models -> NSS).

    Loads ``parknss.chain.load_chain(path)`` (default: the deployed plant in models/plant)
    and steps it in real time. Raises :class:`~parknss.errors.CheckpointError` with one
    line when the checkpoint cannot be loaded; there is no stand-in.
    """

    name = "chain"

    def __init__(self, path: str | Path | None = None, geom: VehicleGeometry | None = None,
                 engine: str = "numpy"):
        from parknss.chain import load_chain

        p = Path(path) if path else SHIPPED_PLANT
        try:
            chain = load_chain(p, engine=engine)
        except ParknssError:
            raise
        except (OSError, ValueError, KeyError) as exc:
            raise CheckpointError(f"{p}: cannot load the chain ({exc})") from exc
        if not isinstance(chain, Plant):
            raise CheckpointError(f"{p}: loaded chain does not implement reset/step (Plant)")
        nss = getattr(getattr(chain, "chain", None), "nss", None)
        self.geom = getattr(nss, "geometry", None)  # the car the chain was identified on
        if geom is not None:
            check_chain_vehicle(self.geom, geom, f"chain {p}")
        super().__init__(chain)


def make_plant(
    kind: str,
    *,
    geom: VehicleGeometry | None = None,
    vehicle_yaml: str | Path | None = None,
    chain_path: str | Path | None = None,
    seed: int | None = None,
    chain_engine: str = "numpy",
) -> SimPlant:
    """Build a plant by kind: "kinematic", "chain" (stepped by ``chain_engine``: "numpy"
    or "native", :class:`~parknss.chain.deployed.DeployedChain`) or "reference"."""
    if kind == "kinematic":
        return KinematicPlant(geom)
    if kind == "reference":
        plant = ReferencePlant(vehicle_yaml, seed)
        if geom is not None:
            check_chain_vehicle(plant.geom, geom, "the reference vehicle")
        return plant
    if kind == "chain":
        return ChainPlant(chain_path, geom, chain_engine)
    raise ConfigError(f"unknown plant {kind!r}; one of {', '.join(PLANT_KINDS)}")


def parse_plants(spec: str) -> list[str]:
    """Plant kinds from a comma list ("kinematic,chain"), in order, without repeats;
    one-line ConfigError for an unknown kind or an empty list."""
    out: list[str] = []
    for p in (s.strip() for s in spec.split(",")):
        if p not in PLANT_KINDS:
            raise ConfigError(f"unknown plant {p!r}; one of {', '.join(PLANT_KINDS)}")
        if p not in out:
            out.append(p)
    if not out:
        raise ConfigError("no plant given")
    return out


def step_plants(plants: Sequence[SimPlant], cmds: Sequence[Commands]) -> list[PlantOutput]:
    """One 10 ms sample of each plant under its command, exactly as each plant's own
    ``step``: chain plants of one artefact on the native engine go in one C call
    (:func:`parknss.chain.deployed.step_many`), any other set one by one."""
    plants, cmds = list(plants), list(cmds)
    if not plants or not all(isinstance(p, ChainPlant) for p in plants):
        return [p.step(c) for p, c in zip(plants, cmds, strict=True)]
    from parknss.chain.deployed import step_many

    for p, c in zip(plants, cmds, strict=True):
        _finite(c, f"{p.name} plant")
    outs = step_many([p.plant for p in plants], cmds)
    return [p._took(out) for p, out in zip(plants, outs, strict=True)]
