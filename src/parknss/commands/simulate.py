"""``parknss simulate``, ``parknss grid`` and ``parknss tune``: the closed loop from the shell.

``simulate`` plans one scene (a scene JSON file, grid cell 0-35 or ``robust:N``) and
executes it under one plant (``--compare`` adds more on the same plan), draws Fig. 8
(planned vs driven path) and Fig. 9 (vx, ω_z, ax, ay on one time axis) and prints a
summary or one JSON document. ``grid`` runs the 36-cell grid (or the 12-cell core, or
the 252-cell robustness grid) in parallel, planning each cell once and executing it
under every plant, and prints Table V with a per-cell CSV. ``tune`` tunes the command
interface gains by coordinate descent on the core and writes them as YAML.
"""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path

import typer

from parknss.errors import ConfigError, ParknssError

GRIDS = ("36", "12", "252")


def _log(msg: str) -> None:
    typer.echo(f"[sim] {msg}", err=True)


def _plants(spec: str) -> list[str]:
    from parknss.sim.plants import PLANT_KINDS

    out = []
    for p in (s.strip() for s in spec.split(",")):
        if p not in PLANT_KINDS:
            raise ConfigError(f"unknown plant {p!r}; one of {', '.join(PLANT_KINDS)}")
        if p not in out:
            out.append(p)
    if not out:
        raise ConfigError("no plant given")
    return out


def _cells(spec: str | None, grid: str, sc_path: str | None) -> list[int]:
    """Cell indices of a grid, or the subset ``spec`` ("0-5,9")."""
    from parknss.sim.scenarios import N_CELLS, N_ROBUST, core_cells, load_scenarios_config

    if grid == "12":
        allowed = core_cells(load_scenarios_config(sc_path))
    else:
        allowed = list(range(N_ROBUST if grid == "252" else N_CELLS))
    if not spec:
        return allowed
    out: list[int] = []
    for part in spec.split(","):
        lo, _, hi = part.strip().partition("-")
        try:
            rng = range(int(lo), int(hi or lo) + 1)
        except ValueError as exc:
            raise ConfigError(f"--cells {spec!r}: expected numbers like 0-5,9") from exc
        for i in rng:
            if i not in allowed:
                raise ConfigError(f"--cells: {i} is not a cell of grid {grid}")
            out.append(i)
    return out


# ---------------------------------------------------------------------------------------
# simulate


def simulate_scene(
    spec: str,
    plants: list[str],
    out: Path,
    cfg_path: str | None = None,
    iface_path: str | None = None,
    plan_path: str | None = None,
    sc_path: str | None = None,
    series: bool = False,
) -> dict:
    """Plan, execute under each plant, draw Fig. 8/9; the JSON summary."""
    from parknss.commands.plan import resolve_scene
    from parknss.report.sim_figures import draw_driven, draw_states
    from parknss.sim.closed_loop import load_closed_loop_config, run_cell
    from parknss.sim.control.interface import load_interface_config

    scene = resolve_scene(spec, sc_path)
    cfg = load_closed_loop_config(cfg_path)
    icfg = load_interface_config(iface_path)
    plan, outcomes = run_cell(scene, plants, cfg, icfg, plan_path)
    name = scene.meta.name
    doc: dict = {
        "scene": name,
        "cell": scene.meta.cell if scene.meta.robust_index is None else scene.meta.robust_index,
        "plannable": plan.trajectory is not None,
        "plan_reason": plan.reason,
        "refined": plan.refined,
        "plan_s": round(plan.plan_s, 4),
        "cusps": plan.trajectory.cusps if plan.trajectory else None,
        "planned_length_m": plan.trajectory.length if plan.trajectory else None,
    }
    first = outcomes[0].to_json()
    for key in ("plant", "completed", "reason", "goal_error_cm", "heading_error_deg"):
        doc[key] = first[key]
    for key in ("clearance_cm", "duration_s", "realtime_factor"):
        doc[key] = first[key]
    doc["runs"] = [o.to_json() for o in outcomes]
    if plan.trajectory is not None:
        runs = {o.plant: o.series for o in outcomes}
        tag = "_vs_".join(runs)
        fig8 = draw_driven(scene, plan.trajectory, runs, out / f"fig8_{name}_{tag}.png")
        fig9 = draw_states(runs, out / f"fig9_{name}_{tag}.png", title=name)
        doc["figures"] = {"fig8": str(fig8), "fig9": str(fig9)}
        if series:
            doc["series"] = {}
            for o in outcomes:
                p = out / f"series_{name}_{o.plant}.csv"
                _write_series(o.series, p)
                doc["series"][o.plant] = str(p)
    return doc


def _write_series(series: dict, path: Path) -> None:
    import numpy as np

    path.parent.mkdir(parents=True, exist_ok=True)
    cols = list(series)
    mat = np.column_stack([series[c] for c in cols])
    np.savetxt(path, mat, delimiter=",", header=",".join(cols), comments="", fmt="%.6g")


def _print_summary(doc: dict) -> None:
    typer.echo(f"scene {doc['scene']}: plannable {doc['plannable']} ({doc['plan_reason']})")
    head = f"{'plant':<10} {'result':<10} {'goal cm':>8} {'head deg':>8} {'clr cm':>7} {'dur s':>7}"
    typer.echo(head)
    for r in doc["runs"]:
        typer.echo(
            f"{r['plant']:<10} {r['reason']:<10} {_f(r['goal_error_cm'], '8.2f')} "
            f"{_f(r['heading_error_deg'], '8.2f')} {_f(r['clearance_cm'], '7.1f')} "
            f"{_f(r['duration_s'], '7.2f')}"
        )
    for k, v in doc.get("figures", {}).items():
        typer.echo(f"{k}: {v}")


def _f(v, spec: str) -> str:
    width = int(spec.split(".")[0]) if spec[0].isdigit() else 0
    return "-".rjust(width) if v is None else format(v, spec)


# ---------------------------------------------------------------------------------------
# grid


def table_v(summaries: dict, heldout: dict | None = None) -> str:
    """Table V as fixed-width text: one column per plant, plus the held-out block."""
    plants = list(summaries)
    lines = [f"{'':<40}" + "".join(f"{p:>14}" for p in plants)]

    def row(label, fn):
        lines.append(f"{label:<40}" + "".join(f"{fn(summaries[p]):>14}" for p in plants))

    row("Completed maneuvers", lambda s: f"{s['completed']}/{s['plannable']}")
    row("Plannable cells", lambda s: f"{s['plannable']}/{s['cells']}")
    row("Goal error, mean [cm]", lambda s: _f(s["goal_mean_cm"], ".1f"))
    row("Goal error, median [cm]", lambda s: _f(s["goal_median_cm"], ".1f"))
    row("Goal error, max [cm]", lambda s: _f(s["goal_max_cm"], ".1f"))
    row("Driven clearance, mean [cm]", lambda s: _f(s["clearance_mean_cm"], ".1f"))
    row("Cells under the 20 cm sensor floor", lambda s: str(s["under_floor"]))
    row("Cells with goal error > 20 cm", lambda s: str(s["over_20cm_goal"]))
    row(
        "Collisions / livelocks / timeouts",
        lambda s: "{collisions}/{livelocks}/{timeouts}".format(**s),
    )
    row("Duration, mean [s]", lambda s: _f(s["duration_mean_s"], ".1f"))
    row("Real-time factor (per process)", lambda s: _f(s["realtime_factor"], ".1f"))
    if heldout:
        lines.append("Held-out axes; goal error mean/med/max [cm] (plannable cells)")
        perts = list(next(iter(heldout.values())))
        for pert in perts:
            cells = []
            for p in plants:
                s = heldout[p][pert]
                cells.append(
                    f"{_f(s['goal_mean_cm'], '.1f')}/{_f(s['goal_median_cm'], '.1f')}/"
                    f"{_f(s['goal_max_cm'], '.1f')}"
                )
            n = heldout[plants[0]][pert]["plannable"]
            lines.append(f"  {pert + f' ({n})':<38}" + "".join(f"{c:>14}" for c in cells))
    return "\n".join(lines)


def run_grid(
    grid: str,
    plants: list[str],
    cells: list[int],
    workers: int,
    cfg_path: str | None = None,
    iface_path: str | None = None,
    iface_overrides: dict | None = None,
    plan_path: str | None = None,
    sc_path: str | None = None,
    progress: bool = True,
) -> list[dict]:
    """Run the cells of a grid under the plants (parallel); one JSON row per (cell, plant)."""
    from parknss.experiments.executor import Job, run_jobs

    kind = "252" if grid == "252" else "36"
    jobs = [
        Job(
            "parknss.sim.closed_loop:cell_job",
            {
                "grid": kind,
                "index": i,
                "plants": plants,
                "closed_loop_config": cfg_path,
                "interface_config": iface_path,
                "interface_overrides": iface_overrides,
                "planning_config": plan_path,
                "scenarios_config": sc_path,
            },
            name=f"cell {i}",
        )
        for i in cells
    ]
    results = run_jobs(jobs, workers=workers, progress=progress, desc=f"grid {grid}")
    return [row for rows in results for row in rows]


def _write_csv(rows: list[dict], path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    cols = list(rows[0]) if rows else []
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=cols)
        w.writeheader()
        w.writerows(rows)


def grid_report(rows: list[dict], plants: list[str], grid: str, floor_cm: float) -> dict:
    """Summaries per plant and, for the robustness grid, per perturbation."""
    from parknss.sim.closed_loop import summarize
    from parknss.sim.scenarios import PERTURBATIONS

    doc = {"summary": {p: summarize(rows, p, floor_cm).to_json() for p in plants}}
    if grid == "252":
        doc["heldout"] = {
            p: {
                pert: summarize(
                    [r for r in rows if r["perturbation"] == pert], p, floor_cm
                ).to_json()
                for pert in PERTURBATIONS
                if any(r["perturbation"] == pert for r in rows)
            }
            for p in plants
        }
    return doc


# ---------------------------------------------------------------------------------------
# registration


def register(app: typer.Typer) -> None:
    cfg_opt = typer.Option(None, "--config", help="Closed-loop YAML (configs/closed_loop.yaml).")
    iface_opt = typer.Option(None, "--interface", help="Interface gains YAML.")
    plan_opt = typer.Option(None, "--planning-config", help="Planning YAML.")
    sc_opt = typer.Option(None, "--scenarios-config", help="Scenarios YAML.")

    @app.command("simulate")
    def simulate(
        scene: str = typer.Option(..., "--scene", help="Scene JSON file, cell 0-35, robust:N."),
        plant: str = typer.Option("kinematic", "--plant", help="kinematic, chain or reference."),
        compare: str | None = typer.Option(
            None, "--compare", help="Plants on the same plan, e.g. kinematic,reference."
        ),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON document."),
        out: Path = typer.Option(Path("runs/simulate"), "--out", help="Figures folder."),
        series: bool = typer.Option(False, "--series", help="Also write time-series CSVs."),
        config: Path | None = cfg_opt,
        interface: Path | None = iface_opt,
        planning_config: Path | None = plan_opt,
        scenarios_config: Path | None = sc_opt,
    ) -> None:
        """Execute one planned scene in closed loop; draw Fig. 8 and Fig. 9."""
        plants = _plants(plant if compare is None else f"{plant},{compare}")
        for k in plants:  # fail fast (one line) if a plant cannot be built here
            _check_plant(k, _s(config))
        doc = simulate_scene(
            scene,
            plants,
            out,
            _s(config),
            _s(interface),
            _s(planning_config),
            _s(scenarios_config),
            series,
        )
        out.mkdir(parents=True, exist_ok=True)
        (out / f"simulate_{doc['scene']}.json").write_text(json.dumps(doc, indent=2))
        if as_json:
            typer.echo(json.dumps(doc, indent=2))
        else:
            _print_summary(doc)

    @app.command("grid")
    def grid(
        grid: str = typer.Option("36", "--grid", help="36, 12 (tuning core) or 252."),
        plants: str = typer.Option("kinematic,reference", "--plants", help="Comma list."),
        cells: str | None = typer.Option(None, "--cells", help="Subset, e.g. 0-5,9."),
        workers: int = typer.Option(1, "--workers", help="Parallel workers (loky)."),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON document."),
        out: Path = typer.Option(Path("runs/grid"), "--out", help="CSV/JSON folder."),
        config: Path | None = cfg_opt,
        interface: Path | None = iface_opt,
        planning_config: Path | None = plan_opt,
        scenarios_config: Path | None = sc_opt,
    ) -> None:
        """Run a scenario grid in closed loop under several plants; print Table V."""
        from parknss.sim.closed_loop import load_closed_loop_config

        if grid not in GRIDS:
            raise ConfigError(f"--grid {grid!r}: one of {', '.join(GRIDS)}")
        kinds = _plants(plants)
        for k in kinds:  # fail fast (one line) if a plant cannot be built here
            _check_plant(k, _s(config))
        idx = _cells(cells, grid, _s(scenarios_config))
        t0 = time.perf_counter()
        rows = run_grid(
            grid,
            kinds,
            idx,
            workers,
            _s(config),
            _s(interface),
            None,
            _s(planning_config),
            _s(scenarios_config),
        )
        wall = time.perf_counter() - t0
        floor = load_closed_loop_config(_s(config)).clearance_floor_cm
        doc = {"grid": grid, "plants": kinds, "cells": len(idx), "workers": workers}
        doc.update(grid_report(rows, kinds, grid, floor))
        sim = sum(r["duration_s"] for r in rows)
        doc["wall_s"] = round(wall, 2)
        doc["sim_s"] = round(sim, 2)
        doc["realtime_factor_wall"] = round(sim / wall, 2) if wall > 0 else None
        csv_path = out / f"grid_{grid}_cells.csv"
        _write_csv(rows, csv_path)
        doc["csv"] = str(csv_path)
        out.mkdir(parents=True, exist_ok=True)
        (out / f"grid_{grid}.json").write_text(json.dumps(doc, indent=2))
        if as_json:
            typer.echo(json.dumps(doc, indent=2))
        else:
            typer.echo(table_v(doc["summary"], doc.get("heldout")))
            typer.echo(
                f"wall {wall:.1f} s with {workers} worker(s); simulated {sim:.0f} s "
                f"(x{doc['realtime_factor_wall']} real time overall); CSV {csv_path}"
            )

    @app.command("tune")
    def tune(
        plant: str | None = typer.Option(
            None, "--plant", help="Plant to tune on (default: chain if available, else reference)."
        ),
        workers: int = typer.Option(1, "--workers", help="Parallel workers (loky)."),
        rounds: int | None = typer.Option(None, "--rounds", help="Descent rounds."),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON document."),
        out: Path = typer.Option(Path("runs/tune"), "--out", help="Output folder."),
        config: Path | None = cfg_opt,
        interface: Path | None = iface_opt,
        planning_config: Path | None = plan_opt,
        scenarios_config: Path | None = sc_opt,
    ) -> None:
        """Tune the interface gains on the 12-cell core; write interface_tuned.yaml."""
        doc = tune_gains(
            plant,
            workers,
            rounds,
            out,
            _s(config),
            _s(interface),
            _s(planning_config),
            _s(scenarios_config),
        )
        if as_json:
            typer.echo(json.dumps(doc, indent=2))
        else:
            typer.echo(
                f"plant {doc['plant']}: objective {doc['initial_objective']:.3f} -> "
                f"{doc['objective']:.3f} in {doc['evaluations']} evaluations"
            )
            for k, v in doc["gains"].items():
                typer.echo(f"  {k} = {v:.4g}")
            typer.echo(f"wrote {doc['yaml']}")


def _s(p: Path | None) -> str | None:
    return str(p) if p is not None else None


def _check_plant(kind: str, cfg_path: str | None) -> None:
    from parknss.sim.closed_loop import load_closed_loop_config
    from parknss.sim.plants import make_plant

    cfg = load_closed_loop_config(cfg_path)
    make_plant(kind, vehicle_yaml=cfg.reference_vehicle, chain_path=cfg.chain_path)


def tune_gains(plant, workers, rounds, out, cfg_path, iface_path, plan_path, sc_path) -> dict:
    """Coordinate descent on the core cells; writes the tuned YAML; the JSON summary."""
    from parknss.sim.control.interface import load_interface_config
    from parknss.sim.tuning import TuningConfig, coordinate_descent, objective, write_tuned

    if plant is None:
        try:
            _check_plant("chain", cfg_path)
            plant = "chain"
        except ParknssError:
            plant = "reference"
            _log("chain plant unavailable: tuning on the reference plant")
    kind = _plants(plant)[0]
    _check_plant(kind, cfg_path)
    tcfg = TuningConfig() if rounds is None else TuningConfig(rounds=rounds)
    start = load_interface_config(iface_path)
    cells = _cells(None, "12", sc_path)

    def evaluate(gains: dict[str, float]) -> float:
        rows = run_grid(
            "12",
            [kind],
            cells,
            workers,
            cfg_path,
            iface_path,
            gains,
            plan_path,
            sc_path,
            progress=False,
        )
        value = objective(rows, tcfg)
        _log(f"{json.dumps({k: round(v, 4) for k, v in gains.items()})} -> {value:.3f}")
        return value

    t0 = time.perf_counter()
    result = coordinate_descent(evaluate, start, tcfg, _log)
    path = write_tuned(result, start, out / "interface_tuned.yaml", f"plant {kind}, core cells.")
    doc = result.to_json()
    doc.update(plant=kind, yaml=str(path), cells=cells, wall_s=round(time.perf_counter() - t0, 1))
    (out / "tune.json").write_text(json.dumps(doc, indent=2))
    return doc
