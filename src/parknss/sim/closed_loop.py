"""The closed loop at 100 Hz: tracker -> command interface -> plant, until the run ends.

:func:`execute` drives a planned trajectory (:func:`parknss.sim.planner.plan_scene`)
from the scene's start through a :class:`~parknss.sim.plants.SimPlant`, with the command
interface the plant names, until

* **completed**: the last segment ended, the car stands still and park is engaged;
* **collision**: the exact footprint overlaps an obstacle (checked at every 10 ms
  pose, in batches of ``collision_every``; the run ends at the first contact);
* **livelock**: the path progress has not grown by ``livelock_progress_m`` for
  ``livelock_s`` seconds (the car stands or oscillates without getting on);
* **timeout**: ``timeout_s`` of simulated time plus ``timeout_per_segment_s`` per segment
  after the first, at most ``timeout_max_s`` (:meth:`ClosedLoopConfig.time_limit`).

The :class:`Outcome` carries the goal position error (cm, rear axle against the scene's
goal) and heading error (deg), measured at the final pose whatever the reason, the driven
clearance (exact dense minimum over every executed pose, cm), the duration, and the full
time series. :class:`ClosedLoopConfig` also holds the two planning settings of every
plan that is driven (and shown by ``parknss plan``): the steering reserve and the margin.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from pydantic import Field

from parknss.config import StrictModel, load_config
from parknss.plant import PlantOutput
from parknss.sim import geometry
from parknss.sim.control.interface import InterfaceConfig, load_interface_config
from parknss.sim.control.mpc import PreviewMpc
from parknss.sim.control.tracker import Tracker, TrackerConfig
from parknss.sim.planning.hybrid_astar import PlanningConfig, load_planning_config
from parknss.sim.plants import PoseIntegrator, SimPlant
from parknss.sim.scenarios import ScenariosConfig, load_scenarios_config
from parknss.sim.trajectory import Trajectory
from parknss.sim.vehicles import resolve_vehicle
from parknss.vehicle import VehicleGeometry

REASONS = ("completed", "collision", "livelock", "timeout", "not plannable")
SERIES_COLUMNS = (
    "t",
    "x",
    "y",
    "heading",
    "vx",
    "yaw_rate",
    "ax",
    "ay",
    "gear",
    "torque",
    "brake_pressure",
    "steer",
    "gear_cmd",
    "torque_cmd",
    "decel_cmd",
    "steer_cmd",
    "speed_req",
    "steer_req",
    "progress",
    "lateral_error",
    "heading_error",
    "segment",
)


class ClosedLoopConfig(StrictModel):
    """Termination rules, the tracker and the planning settings of every driven plan
    (configs/closed_loop.yaml)."""

    timeout_s: float = Field(240.0, gt=0, description="simulated-time limit, s")
    timeout_per_segment_s: float = Field(
        3.0, ge=0, description="each gear segment after the first adds this to the limit, s"
    )
    timeout_max_s: float = Field(
        1800.0, gt=0, description="the limit never grows past this (nor below timeout_s), s"
    )
    livelock_s: float = Field(20.0, gt=0, description="no progress for this long: livelock, s")
    livelock_progress_m: float = Field(0.02, gt=0, description="progress that counts, m")
    collision_every: int = Field(10, ge=1, description="poses per collision batch")
    clearance_floor_cm: float = Field(20.0, ge=0, description="ultrasonic sensor floor, cm")
    reference_vehicle: str | None = Field(None, description="reference-plant vehicle YAML")
    chain_path: str | None = Field(None, description="chain checkpoint (default: shipped)")
    plant_seed: int | None = Field(None, description="reference-plant noise seed")
    steer_reserve: float = Field(
        0.1, ge=0, lt=0.5, description="fraction of the steering lock every plan leaves free"
    )
    plan_margin_m: float | None = Field(
        0.2, ge=0, description="planner clearance margin of every plan, m (None: planning.yaml)"
    )
    tracker: TrackerConfig = TrackerConfig()

    omit_at_default = frozenset({"timeout_per_segment_s", "timeout_max_s"})

    def time_limit(self, trajectory: Trajectory) -> float:
        """Simulated-time limit of driving ``trajectory``, s: ``timeout_s`` plus
        ``timeout_per_segment_s`` per segment after the first (each stop, gear change and
        standing steer costs seconds: a 150-stroke slot shuffle takes about 500 s), at most
        ``timeout_max_s`` (a documented clamp: the recorder allocates the whole run)."""
        extra = self.timeout_per_segment_s * max(len(trajectory.segments) - 1, 0)
        return max(self.timeout_s, min(self.timeout_s + extra, self.timeout_max_s))


def load_closed_loop_config(path: str | Path | None = None) -> ClosedLoopConfig:
    """Read ``path`` (default: the shipped configs/closed_loop.yaml)."""
    return load_config(ClosedLoopConfig, path, default="closed_loop.yaml")


@dataclass(frozen=True)
class SimConfigFiles:
    """The YAML files a simulator run reads; None: the shipped default of each.

    Paths are kept as strings so they travel as JSON in executor jobs.
    """

    closed_loop: str | None = None
    interface: str | None = None
    planning: str | None = None
    scenarios: str | None = None
    vehicle: str | None = None  # vehicle YAML (None: the chain's car, else the default car)

    def __post_init__(self) -> None:
        for name in ("closed_loop", "interface", "planning", "scenarios", "vehicle"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, str(value))

    def to_json(self) -> dict[str, str | None]:
        return asdict(self)

    def closed_loop_config(self) -> ClosedLoopConfig:
        return load_closed_loop_config(self.closed_loop)

    def interface_config(self) -> InterfaceConfig:
        return load_interface_config(self.interface)

    def planning_config(self) -> PlanningConfig:
        return load_planning_config(self.planning)

    def scenarios_config(self) -> ScenariosConfig:
        return load_scenarios_config(self.scenarios)

    def vehicle_geometry(self) -> VehicleGeometry:
        """The car of the run (:func:`parknss.sim.vehicles.resolve_vehicle`)."""
        return resolve_vehicle(self.vehicle, self.closed_loop_config().chain_path)


@dataclass
class Outcome:
    """The result of one closed-loop run (units in the names)."""

    completed: bool
    reason: str
    plant: str
    goal_error_cm: float | None = None
    heading_error_deg: float | None = None
    clearance_cm: float | None = None
    duration_s: float = 0.0
    wall_s: float = 0.0
    steps: int = 0
    planned_length_m: float | None = None
    cusps: int | None = None
    driven_length_m: float = 0.0
    gear_changes: int = 0
    series: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    @property
    def realtime_factor(self) -> float:
        """Simulated seconds per wall-clock second."""
        return self.duration_s / self.wall_s if self.wall_s > 0 else math.inf

    def to_json(self) -> dict:
        """The scalar fields as a JSON-ready dict (no time series)."""
        out = {k: v for k, v in self.__dict__.items() if k != "series"}
        for k, v in out.items():
            if isinstance(v, float) and not math.isfinite(v):
                out[k] = None
        out["realtime_factor"] = (
            round(self.realtime_factor, 2) if math.isfinite(self.realtime_factor) else None
        )
        return out


# ---------------------------------------------------------------------------------------
# Execution


class _Recorder:
    """Preallocated time-series buffers."""

    def __init__(self, n: int) -> None:
        self.data = {c: np.zeros(n) for c in SERIES_COLUMNS}
        self.n = 0

    def add(self, t, pose, y: PlantOutput, cmd, req, tracker: Tracker) -> None:
        k, d = self.n, self.data
        d["t"][k] = t
        d["x"][k], d["y"][k], d["heading"][k] = pose
        d["vx"][k], d["yaw_rate"][k], d["ax"][k], d["ay"][k] = y.vx, y.yaw_rate, y.ax, y.ay
        d["gear"][k], d["torque"][k] = y.gear, y.torque
        d["brake_pressure"][k], d["steer"][k] = y.brake_pressure, y.steer
        d["gear_cmd"][k], d["torque_cmd"][k] = cmd.gear, cmd.torque_cmd
        d["decel_cmd"][k], d["steer_cmd"][k] = cmd.decel_cmd, cmd.steer_cmd
        d["speed_req"][k] = req.direction * req.speed
        d["steer_req"][k], d["progress"][k] = req.steer, tracker.progress
        proj = tracker.last
        d["lateral_error"][k] = proj.e_y if proj is not None else np.nan
        d["heading_error"][k] = proj.e_phi if proj is not None else np.nan
        d["segment"][k] = tracker.index
        self.n += 1

    def arrays(self) -> dict[str, np.ndarray]:
        return {c: v[: self.n].copy() for c, v in self.data.items()}


def _wrap_deg(a: float) -> float:
    return abs(math.degrees((a + math.pi) % (2.0 * math.pi) - math.pi))


def execute(
    scene,
    trajectory: Trajectory,
    plant: SimPlant,
    cfg: ClosedLoopConfig | None = None,
    interface_cfg: InterfaceConfig | None = None,
    geom: VehicleGeometry | None = None,
    mpc: PreviewMpc | None = None,
) -> Outcome:
    """Drive ``trajectory`` from ``scene.start`` through ``plant`` (see module docstring).

    Every plant goes through the same protocol: ``plant.reset()``, then per 10 ms
    ``cmd = iface.step(request, y)`` and ``y = plant.step(cmd)`` with the interface the
    plant names (:meth:`~parknss.sim.plants.SimPlant.command_interface`); the pose moves
    with ``plant.motion``.
    """
    cfg = cfg or ClosedLoopConfig()
    geom = geom or VehicleGeometry()
    wall0 = time.perf_counter()
    dt = plant.dt
    tracker = Tracker(trajectory, cfg.tracker, geom, dt, mpc)
    iface = plant.command_interface(interface_cfg, dt)
    integ = PoseIntegrator(scene.start, dt)
    obstacles = scene.obstacle_arrays()
    circles = geometry.polygon_circles(obstacles)  # the collision broad phase, once
    n_max = round(cfg.time_limit(trajectory) / dt) + 1
    rec = _Recorder(n_max)
    y = plant.reset()
    poses = np.empty((n_max, 3))
    checked = 0
    best, best_t = -math.inf, 0.0
    reason = "timeout"
    for k in range(n_max):
        t = k * dt
        pose = integ.pose
        poses[k] = pose
        req = tracker.step(pose, y, iface.standstill)
        cmd = iface.step(req, y)
        rec.add(t, pose, y, cmd, req, tracker)
        if k + 1 - checked >= cfg.collision_every or tracker.done:
            hit = geometry.collides(poses[checked : k + 1], geom, obstacles, circles=circles)
            if np.any(hit):
                first = checked + int(np.argmax(hit))
                rec.n = first + 1
                reason = "collision"
                break
            checked = k + 1
        if tracker.done:
            reason = "completed"
            break
        if tracker.progress > best + cfg.livelock_progress_m:
            best, best_t = tracker.progress, t
        elif t - best_t >= cfg.livelock_s:
            reason = "livelock"
            break
        y = plant.step(cmd)
        integ.step(*plant.motion)
    series = rec.arrays()
    return _outcome(scene, trajectory, plant.name, geom, series, reason, wall0)


def _outcome(scene, traj: Trajectory, plant: str, geom, series, reason: str, wall0) -> Outcome:
    """Scalar metrics of a finished run (``wall0``: perf_counter at its start, s)."""
    x, y, th = series["x"], series["y"], series["heading"]
    gx, gy, gth = scene.goal
    obstacles = scene.obstacle_arrays()
    clr, _ = geometry.dense_clearance(np.column_stack([x, y, th]), geom, obstacles)
    driven = float(np.sum(np.hypot(np.diff(x), np.diff(y)))) if len(x) > 1 else 0.0
    return Outcome(
        completed=reason == "completed",
        reason=reason,
        plant=plant,
        goal_error_cm=float(math.hypot(x[-1] - gx, y[-1] - gy) * 100.0),
        heading_error_deg=_wrap_deg(th[-1] - gth),
        clearance_cm=clr * 100.0 if math.isfinite(clr) else None,
        duration_s=float(series["t"][-1]),
        wall_s=time.perf_counter() - wall0,
        steps=len(x),
        planned_length_m=traj.length,
        cusps=traj.cusps,
        driven_length_m=driven,
        gear_changes=int(np.count_nonzero(np.diff(series["gear_cmd"]))),
        series=series,
    )
