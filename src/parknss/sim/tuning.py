"""Coordinate descent of the command-interface gains on the 12-cell tuning core (§IV-C).

The objective of a gain set is the mean goal error (cm) over the core cells executed
under one plant (the learned chain when available, else the reference vehicle), plus
``failure_penalty_cm`` per cell that did not complete, plus ``duration_weight`` times
the mean duration (s). Each round visits every tuned gain and tries it multiplied by
(1 ± step); the better of the two replaces it if it lowers the objective. A round
without improvement shrinks the step by ``shrink``; the search stops after ``rounds``
rounds or when the step falls below ``min_step``. The robustness grids use held-out
cells only: the core is tier 1 of the 36-cell grid, never a perturbed cell.

:func:`tune_gains` is the whole ``parknss tune`` job: every evaluation runs the core
through :func:`parknss.sim.grid.run_grid` (the one executor, local pool or Ray).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from pydantic import Field

from parknss.config import StrictModel, override
from parknss.errors import ConfigError, ParknssError
from parknss.outputs import run_folder, write_text_atomic
from parknss.sim.closed_loop import SimConfigFiles
from parknss.sim.control.interface import InterfaceConfig
from parknss.sim.grid import config_paths, run_grid
from parknss.sim.plants import parse_plants
from parknss.sim.scenarios import grid_cells
from parknss.sim.session import check_plants


class TuningConfig(StrictModel):
    """Which gains are tuned and how the descent moves."""

    gains: tuple[str, ...] = Field(
        ("kp", "ki", "kff", "hold_decel_ms2", "hold_ramp_ms3", "launch_torque_nm"),
        description="InterfaceConfig fields to tune",
    )
    relative_step: float = Field(0.3, gt=0, lt=1, description="initial step, fraction")
    shrink: float = Field(0.5, gt=0, lt=1, description="step factor after a dry round")
    min_step: float = Field(0.04, gt=0, description="stop below this step, fraction")
    rounds: int = Field(3, ge=1, description="maximum rounds")
    failure_penalty_cm: float = Field(100.0, ge=0, description="per non-completed cell, cm")
    duration_weight: float = Field(0.0, ge=0, description="cm per second of mean duration")


@dataclass
class TuningResult:
    """The tuned gains, the objective history and the evaluations spent."""

    gains: dict[str, float]
    objective: float
    initial_objective: float
    history: list[dict] = field(default_factory=list)
    evaluations: int = 0

    def to_json(self) -> dict:
        return dict(self.__dict__)


def objective(rows: list[dict], cfg: TuningConfig) -> float:
    """Mean goal error (cm) + penalties over the rows of one plant (see module docstring)."""
    if not rows:
        raise ConfigError("tuning: no executed cells to score")
    goals, fails, dur = [], 0, []
    for r in rows:
        if not r["plannable"]:
            continue
        goals.append(r["goal_error_cm"])
        dur.append(r["duration_s"])
        fails += not r["completed"]
    if not goals:
        raise ConfigError("tuning: no plannable cell in the tuning set")
    n = len(goals)
    return sum(goals) / n + cfg.failure_penalty_cm * fails / n + cfg.duration_weight * sum(dur) / n


def coordinate_descent(
    evaluate: Callable[[dict[str, float]], float],
    start: InterfaceConfig,
    cfg: TuningConfig | None = None,
    log: Callable[[str], None] | None = None,
) -> TuningResult:
    """Minimise ``evaluate(gains)`` over the tuned fields of ``start`` (see docstring)."""
    cfg = cfg or TuningConfig()
    fields = InterfaceConfig.model_fields
    for g in cfg.gains:
        if g not in fields:
            raise ConfigError(f"tuning: {g!r} is not an interface gain")
    gains = {g: float(getattr(start, g)) for g in cfg.gains}
    best = evaluate(dict(gains))
    result = TuningResult(dict(gains), best, best, [{"gains": dict(gains), "objective": best}], 1)
    step = cfg.relative_step
    for rnd in range(cfg.rounds):
        improved = False
        for g in cfg.gains:
            trials = []
            for sign in (1.0, -1.0):
                cand = dict(gains)
                cand[g] = gains[g] * (1.0 + sign * step) if gains[g] != 0 else sign * step
                try:
                    override(start, cand)
                except ConfigError:  # outside the gain's valid range: skip this way
                    continue
                value = evaluate(dict(cand))
                result.evaluations += 1
                result.history.append({"gains": dict(cand), "objective": value})
                trials.append((value, cand))
            if trials:
                value, cand = min(trials, key=lambda t: t[0])
                if value < best - 1e-9:
                    best, gains, improved = value, cand, True
                    if log:
                        log(f"round {rnd + 1}: {g} -> {cand[g]:.4g}, objective {best:.3f}")
        if not improved:
            step *= cfg.shrink
            if step < cfg.min_step:
                break
    result.gains, result.objective = gains, best
    if not math.isfinite(best):
        raise ConfigError("tuning: objective is not finite")
    return result


def write_tuned(
    result: TuningResult, start: InterfaceConfig, path: str | Path, note: str = ""
) -> Path:
    """Write the full interface config with the tuned gains as YAML (a configs/ drop-in)."""
    p = Path(path)
    gains = {k: float(f"{v:.6g}") for k, v in result.gains.items()}
    tuned = override(start, gains, source="tuned gains")
    head = (
        "# Command-interface gains tuned by coordinate descent (parknss tune).\n"
        f"# objective {result.initial_objective:.3f} -> {result.objective:.3f} "
        f"in {result.evaluations} evaluations. {note}\n"
    )
    return write_text_atomic(p, head + yaml.safe_dump(tuned.model_dump(), sort_keys=False))


def tune_gains(
    plant: str | None,
    out: Path,
    *,
    rounds: int | None = None,
    files: SimConfigFiles | None = None,
    executor: str = "local",
    workers: int = 1,
    address: str | None = None,
    log: Callable[[str], None] | None = None,
    overwrite: bool = False,
) -> dict:
    """``parknss tune``: coordinate descent of the interface gains on the 12-cell core
    under ``plant`` (None: the chain if it can be built here, else the reference
    vehicle); writes ``interface_tuned.yaml`` and ``tune.json`` to the run folder ``out``
    (:func:`parknss.outputs.run_folder`: refused if it holds anything but the same tuning
    run, unless ``overwrite``) and returns the summary (gains, objective history,
    evaluations, wall s)."""
    files = files or SimConfigFiles()
    say = log or (lambda _msg: None)
    cfg = files.closed_loop_config()
    if plant is None:
        try:
            check_plants(["chain"], cfg, files.vehicle_geometry())
            plant = "chain"
        except ParknssError:
            plant = "reference"
            say("chain plant unavailable: tuning on the reference plant")
    kind = parse_plants(plant)[0]
    check_plants([kind], cfg, files.vehicle_geometry())
    tcfg = TuningConfig() if rounds is None else TuningConfig(rounds=rounds)
    start = files.interface_config()
    cells = grid_cells("12", files.scenarios_config())

    def evaluate(gains: dict[str, float]) -> float:
        rows = run_grid(
            "12",
            [kind],
            cells,
            workers,
            files=files,
            interface_overrides=gains,
            executor=executor,
            address=address,
            progress=False,
        )
        value = objective(rows, tcfg)
        say(f"{json.dumps({k: round(v, 4) for k, v in gains.items()})} -> {value:.3f}")
        return value

    identity = {"plant": kind, "rounds": tcfg.rounds, **config_paths(files)}
    with run_folder(out, command="parknss tune", args=identity, overwrite=overwrite) as run:
        t0 = time.perf_counter()
        result = coordinate_descent(evaluate, start, tcfg, say)
        note = f"plant {kind}, core cells."
        path = write_tuned(result, start, out / "interface_tuned.yaml", note)
        doc = result.to_json()
        doc.update(plant=kind, yaml=str(path), cells=cells,
                   wall_s=round(time.perf_counter() - t0, 1))
        run.write_json("tune.json", doc)
    return doc
