"""Stack-driven identification trials: the reference vehicle parked by parknss's own stack.

A user with a real car identifies the plant from logs of the car driven the way it will be
used: by their parking stack. These trials are that for the synthetic truth: the
reference vehicle (its normal sensor model and per-trial conditions, exactly as in the
APS campaign) parked in closed loop by parknss's planner, tracker and command interface
(:func:`~parknss.sim.planner.plan_scene`, :func:`~parknss.sim.closed_loop.execute`, as
``parknss simulate --plant reference`` does), recorded as campaign trials (the one
assembly :func:`parknss.reference.campaign.trial_channels`, the one provenance
:meth:`parknss.reference.campaign.TrialCar.trial`).

Classes: ``stack_parallel``, ``stack_perpendicular``, ``stack_angled`` (one per bay type),
``repetitions`` trials each, so with 4 repetitions every class has as many trials as the
APS campaign's and the stratified 4-fold CV still holds out one trial of every class.

Held out by cell: each scene is drawn from (seed, class, repetition, attempt) over
continuous ranges (slot size between the grid's tightest and loosest tier, widened by
``slot_extend_m``; approach and lane barrier at random; the start moved along and
across its heading and turned), and a draw that lies within ``min_separation_m`` of any
scene of the 36-cell or the 252-cell grid (:func:`scene_distance`) is redrawn, so no
fidelity cell is ever a training scene. A draw the planner cannot solve, or a run that
does not complete or falls outside ``length_range_s``, is redrawn too (next attempt,
deterministically). Everything follows from (seed, vehicle YAML, configs): the same
inputs give the same bits, as long as the planner's wall-clock guard
(``time_budget_s`` in planning.yaml) does not fire.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
from pydantic import Field

from parknss.config import StrictModel, load_config
from parknss.data.trial import MANEUVER_CLASSES, Campaign, Trial
from parknss.errors import ConfigError, DataError
from parknss.reference.campaign import trial_car, trial_channels
from parknss.reference.params import ReferenceVehicleParams, load_vehicle_params
from parknss.sim import scenarios as sc
from parknss.sim.closed_loop import ClosedLoopConfig, execute, load_closed_loop_config
from parknss.sim.control.interface import InterfaceConfig, load_interface_config
from parknss.sim.control.mpc import PreviewMpc
from parknss.sim.planner import plan_scene
from parknss.sim.plants import ReferencePlant
from parknss.vehicle import VehicleGeometry

GENERATOR = "parknss.sim.stack_trials"
GENERATOR_VERSION = "1"
STACK_CLASSES: tuple[str, ...] = tuple(f"stack_{bay}" for bay in sc.BAYS)
STREAM_TAG = 0x57AC  # the scene draws' stream (never the APS plans' or the conditions')


class StackTrialsConfig(StrictModel):
    """How the stack-driven trials are drawn (configs/stack_trials.yaml)."""

    repetitions: int = Field(4, ge=1, le=50, description="trials per class (bay type)")
    slot_extend_m: float = Field(
        0.075, ge=0, description="slot drawn from the tightest tier - this to the loosest + this, m"
    )
    jitter_m: float = Field(0.25, ge=0, description="start moved up to this along and across, m")
    jitter_deg: float = Field(3.0, ge=0, description="start turned up to this, deg")
    min_separation_m: float = Field(
        0.05, gt=0, description="held out: farther than this from every grid scene, m"
    )
    max_attempts: int = Field(20, ge=1, description="redraws per trial before giving up")
    length_range_s: tuple[float, float] = Field(
        (21.0, 120.0), description="a completed run's duration must lie in this range, s"
    )


def load_stack_config(
    path: str | Path | None = None, repetitions: int | None = None
) -> StackTrialsConfig:
    """Read ``path`` (default: the shipped configs/stack_trials.yaml), ``repetitions``
    replacing the file's when given."""
    extra = None if repetitions is None else {"repetitions": repetitions}
    return load_config(StackTrialsConfig, path, default="stack_trials.yaml", overrides=extra)


# ---------------------------------------------------------------------------------------
# Scenes, held out from the grids


def scene_seed(seed: int, bay: str, repetition: int, attempt: int) -> int:
    """The seed of one scene draw (also the trial's plan seed for its noise)."""
    ss = np.random.SeedSequence(
        [int(seed) & 0xFFFFFFFF, STREAM_TAG, sc.BAYS.index(bay), int(repetition), int(attempt)]
    )
    return int(ss.generate_state(1)[0])


def draw_scene(
    seed: int,
    bay: str,
    repetition: int,
    attempt: int = 0,
    cfg: StackTrialsConfig | None = None,
    scen: sc.ScenariosConfig | None = None,
    geom: VehicleGeometry | None = None,
) -> sc.Scene:
    """One drawn scene of class ``stack_<bay>`` (module docstring); not checked against
    the grids (:func:`held_out`)."""
    cfg, geom = cfg or StackTrialsConfig(), geom or VehicleGeometry()
    scen = scen if scen is not None else sc.load_scenarios_config()
    if bay not in sc.BAYS:
        raise ConfigError(f"unknown bay {bay!r}; one of {', '.join(sc.BAYS)}")
    rng = np.random.default_rng(scene_seed(seed, bay, repetition, attempt))
    approach = sc.APPROACHES[int(rng.integers(2))]
    barrier = bool(rng.integers(2))
    slots = [sc.slot_size(bay, t, scen, geom) for t in sc.TIERS]
    slot = float(rng.uniform(min(slots) - cfg.slot_extend_m, max(slots) + cfg.slot_extend_m))
    along, across = rng.uniform(-cfg.jitter_m, cfg.jitter_m, size=2)
    turn = math.radians(float(rng.uniform(-cfg.jitter_deg, cfg.jitter_deg)))
    scene = sc.build_scene(bay, approach, 1, barrier, cfg=scen, geom=geom, slot_override_m=slot)
    x, y, th = scene.start
    start = (
        x + along * math.cos(th) - across * math.sin(th),
        y + along * math.sin(th) + across * math.cos(th),
        th + turn,
    )
    meta = sc.SceneMeta(
        name=f"stack-{bay}-r{repetition}",
        bay=bay,
        approach=approach,
        barrier=barrier,
        perturbation="stack",
        slot_size_m=round(slot, 6),
        source=f"{GENERATOR} seed {int(seed)} attempt {int(attempt)}",
    )
    return replace(scene, start=start, meta=meta)


def fidelity_scenes(
    scen: sc.ScenariosConfig | None = None, geom: VehicleGeometry | None = None
) -> list[sc.Scene]:
    """Every scene of the 36-cell and the 252-cell grid (288), for the car ``geom``."""
    scen = scen if scen is not None else sc.load_scenarios_config()
    return [sc.grid_scene(i, scen, geom) for i in range(sc.N_CELLS)] + [
        sc.robust_scene(i, scen, geom) for i in range(sc.N_ROBUST)
    ]


def scene_distance(a: sc.Scene, b: sc.Scene, heading_scale_m: float = 5.0) -> float:
    """How far apart two scenes are, m: the largest displacement of the start, the goal
    and any obstacle vertex, a heading difference counting ``heading_scale_m`` per rad
    (about the car's length); infinite when their obstacles differ in number, kind or
    vertex count (different layouts)."""
    if len(a.obstacles) != len(b.obstacles):
        return math.inf
    worst = 0.0
    for oa, ob in zip(a.obstacles, b.obstacles, strict=True):
        if oa.kind != ob.kind or oa.vertices.shape != ob.vertices.shape:
            return math.inf
        worst = max(worst, float(np.max(np.hypot(*(oa.vertices - ob.vertices).T))))
    for pa, pb in ((a.start, b.start), (a.goal, b.goal)):
        dth = abs(math.remainder(pa[2] - pb[2], 2.0 * math.pi))
        worst = max(worst, math.hypot(pa[0] - pb[0], pa[1] - pb[1]), dth * heading_scale_m)
    return worst


def nearest_grid_scene(scene: sc.Scene, grid_scenes: list[sc.Scene]) -> tuple[float, str]:
    """(distance m, name) of the grid scene nearest to ``scene``."""
    pairs = ((scene_distance(scene, g), g.meta.name) for g in grid_scenes)
    return min(pairs, default=(math.inf, ""))


def held_out(scene: sc.Scene, grid_scenes: list[sc.Scene], cfg: StackTrialsConfig) -> bool:
    """True when ``scene`` is farther than ``min_separation_m`` from every grid scene."""
    return nearest_grid_scene(scene, grid_scenes)[0] > cfg.min_separation_m


# ---------------------------------------------------------------------------------------
# Trials


class RecordingReference(ReferencePlant):
    """The reference plant that keeps :meth:`ReferenceVehicle.record` of every state it
    reaches (row 0 at reset, then one per step): row k is the state the closed loop
    observed before its command k, the campaign's alignment."""

    def __init__(self, vehicle) -> None:
        super().__init__(vehicle=vehicle)
        self.rows: list[tuple[float, ...]] = []

    def reset(self, *args, **kwargs):
        out = super().reset(*args, **kwargs)
        self.rows = [self.vehicle.record()]
        return out

    def step(self, cmd):
        out = super().step(cmd)
        self.rows.append(self.vehicle.record())
        return out


def generate_stack_trial(
    bay: str,
    repetition: int,
    seed: int = 0,
    params: ReferenceVehicleParams | None = None,
    cfg: StackTrialsConfig | None = None,
    loop: ClosedLoopConfig | None = None,
    interface: InterfaceConfig | None = None,
    planning=None,
    scen: sc.ScenariosConfig | None = None,
    grid_scenes: list[sc.Scene] | None = None,
    vehicle_hash: str | None = None,
    conditions: str | None = None,
) -> Trial:
    """Trial ``stack_<bay>_r<repetition>``: a held-out scene planned and parked by the
    stack with the reference vehicle (module docstring). ConfigError when no attempt
    gives a completed run of an accepted length."""
    params = params or load_vehicle_params(None)
    cfg = cfg or StackTrialsConfig()
    loop = loop if loop is not None else load_closed_loop_config()
    interface = interface if interface is not None else load_interface_config()
    scen = scen if scen is not None else sc.load_scenarios_config()
    geom = params.to_geometry()
    grid_scenes = grid_scenes if grid_scenes is not None else fidelity_scenes(scen, geom)
    maneuver = f"stack_{bay}"
    class_index = len(MANEUVER_CLASSES) + sc.BAYS.index(bay) if bay in sc.BAYS else -1
    lo, hi = cfg.length_range_s
    mpc = PreviewMpc(loop.tracker.mpc)
    tried: list[str] = []
    for attempt in range(cfg.max_attempts):
        scene = draw_scene(seed, bay, repetition, attempt, cfg, scen, geom)
        dist, near = nearest_grid_scene(scene, grid_scenes)
        if dist <= cfg.min_separation_m:
            tried.append(f"{attempt}: {dist * 100:.1f} cm from grid scene {near}")
            continue
        plan = plan_scene(scene, loop, planning, geom)
        if plan.trajectory is None:
            tried.append(f"{attempt}: not plannable ({plan.reason})")
            continue
        plan_seed = scene_seed(seed, bay, repetition, attempt)
        car = trial_car(params, seed, class_index, repetition, plan_seed, conditions)
        plant = RecordingReference(car.vehicle())
        out = execute(scene, plan.trajectory, plant, loop, interface, geom, mpc)
        if out.completed and lo <= out.duration_s <= hi:
            break
        tried.append(f"{attempt}: {out.reason}, {out.duration_s:.1f} s")
    else:
        raise ConfigError(
            f"{maneuver}_r{repetition}: no completed stack run within {lo}-{hi} s in "
            f"{cfg.max_attempts} attempts ({'; '.join(tried[-3:])})"
        )
    s = out.series
    cmds = np.column_stack([s["gear_cmd"], s["torque_cmd"], s["decel_cmd"], s["steer_cmd"]])
    channels = trial_channels(plant.rows[: len(s["t"])], cmds)
    provenance = {
        "generator": GENERATOR,
        "generator_version": GENERATOR_VERSION,
        "driver": "parknss stack: plan_scene + tracker + command interface (closed loop)",
        "seed": int(seed),
        "plan_seed": plan_seed,
        "attempt": attempt,
        "scene": scene.to_json(),
        "nearest_grid_scene": {"name": near, "distance_m": round(dist, 6)},
        "redrawn": tried,
        "plan": {"refined": plan.refined, "cusps": plan.trajectory.cusps,
                 "length_m": round(plan.trajectory.length, 6)},
        "outcome": {
            "goal_error_cm": round(out.goal_error_cm or 0.0, 4),
            "clearance_cm": None if out.clearance_cm is None else round(out.clearance_cm, 4),
            "duration_s": round(out.duration_s, 2),
            "gear_changes": out.gear_changes,
        },
    }
    return car.trial(f"{maneuver}_r{repetition}", maneuver, repetition, channels, provenance,
                     vehicle_hash)


def generate_stack_trials(
    seed: int = 0,
    vehicle_yaml: str | Path | None = None,
    cfg: StackTrialsConfig | None = None,
    bays: tuple[str, ...] = sc.BAYS,
    loop: ClosedLoopConfig | None = None,
    interface: InterfaceConfig | None = None,
    planning=None,
    scen: sc.ScenariosConfig | None = None,
    conditions: str | None = None,
    progress: bool = False,
) -> list[Trial]:
    """``cfg.repetitions`` stack trials of each bay of ``bays``, class by class."""
    cfg = cfg or StackTrialsConfig()
    scen = scen if scen is not None else sc.load_scenarios_config()
    params = load_vehicle_params(vehicle_yaml)
    yaml_hash = None
    if vehicle_yaml:
        yaml_hash = hashlib.sha256(Path(vehicle_yaml).read_bytes()).hexdigest()
    grid_scenes = fidelity_scenes(scen, params.to_geometry())
    jobs = [(b, r) for b in bays for r in range(1, cfg.repetitions + 1)]
    if progress:
        from tqdm import tqdm

        jobs = tqdm(jobs, desc="stack trials", unit="trial")
    return [
        generate_stack_trial(b, r, seed, params, cfg, loop, interface, planning, scen,
                             grid_scenes, yaml_hash, conditions)
        for b, r in jobs
    ]


def stack_campaign(
    trials: list[Trial],
    params: ReferenceVehicleParams,
    base: Campaign | None = None,
    seed: int = 0,
    cfg: StackTrialsConfig | None = None,
) -> Campaign:
    """A campaign of ``base``'s trials (unchanged) followed by the stack ``trials`` (driven
    with the vehicle ``params``), or of the stack trials alone; its meta is ``base``'s
    plus ``stack_trials`` (generator, seed, classes, count, the held-out rule). DataError
    when ``base`` was generated from another vehicle, or an id repeats."""
    cfg = cfg or StackTrialsConfig()
    check_base(base, params)
    if base is not None:
        meta = dict(base.meta)
    else:
        meta = {
            "synthetic": True,
            "note": "stack-driven trials of the parknss reference vehicle, not field data",
            "vehicle_id": params.vehicle_id,
            "vehicle_params_digest": params.digest(),
            "vehicle_geometry": params.to_geometry().to_dict(),
        }
    old = list(base) if base is not None else []
    ids = [tr.id for tr in old + trials]
    if len(set(ids)) != len(ids):
        raise DataError("stack trials: a trial id repeats (does the base campaign hold them?)")
    meta["stack_trials"] = {
        "generator": GENERATOR,
        "generator_version": GENERATOR_VERSION,
        "seed": int(seed),
        "classes": sorted({tr.maneuver for tr in trials}),
        "n_trials": len(trials),
        "held_out": f"every scene farther than {cfg.min_separation_m} m from each scene "
        "of the 36- and 252-cell grids",
        "base": None if base is None else base.name,
    }
    name = f"{base.name}+stack_seed{seed}" if base is not None else f"stack_seed{seed}"
    return Campaign(old + trials, name=name, meta=meta)


def check_base(base: Campaign | None, params: ReferenceVehicleParams) -> None:
    """DataError (one line) unless ``base`` (when given) was generated from the vehicle
    ``params`` (its meta's parameter digest): stack trials join only their own car."""
    if base is None:
        return
    own = base.meta.get("vehicle_params_digest")
    if own != params.digest():
        raise DataError(
            f"campaign {base.name!r}: its vehicle (parameter digest {own}) is not the one the "
            f"stack trials are driven with ({params.digest()}); use the campaign's vehicle YAML"
        )
