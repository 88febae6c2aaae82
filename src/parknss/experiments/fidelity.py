"""``parknss fidelity``: the learned chain against the truth in closed loop, cell by cell.

Every cell (a grid cell, a TPCAP case, any scene) is one executor job
(:func:`fidelity_job`): the cell is planned once and driven under the chain and under
the reference vehicle with a fresh plant-noise seed (:func:`parknss.sim.fidelity.
cell_seed`, never a campaign trial's seed); the job scores the pair
(:func:`parknss.sim.fidelity.compare_outcomes`) and draws the cell's figure (chain and
truth overlaid). :func:`run_fidelity` runs the cells through the one executor with the
job cache in the run folder (an interrupted run resumes cell by cell), aggregates them
(:func:`parknss.sim.fidelity.summarize_fidelity`, the issue's targets as pass/fail lines)
and writes ``fidelity.json``, ``fidelity_cells.csv``, ``fidelity.md`` and
``fidelity.html`` (summary, per-cell table, one figure per cell under ``cells/``).
"""

from __future__ import annotations

import re
import time
from dataclasses import fields
from pathlib import Path

from parknss.config import override
from parknss.errors import ConfigError
from parknss.metrics.iso18571 import ISORatingConfig
from parknss.outputs import run_folder
from parknss.report.fidelity_figure import draw_fidelity, write_fidelity_html
from parknss.sim import scenarios as sc
from parknss.sim.closed_loop import SimConfigFiles, execute
from parknss.sim.fidelity import (
    CellFidelity,
    cell_seed,
    compare_outcomes,
    fidelity_text,
    load_fidelity_config,
    summarize_fidelity,
)
from parknss.sim.grid import config_paths, write_rows_csv
from parknss.sim.hybrid import HYBRIDS, make_hybrid
from parknss.sim.scene_formats import load_scene
from parknss.sim.session import check_plants, run_cell

PLANTS = ["chain", "reference"]
CANDIDATES = ("chain", "reference", *HYBRIDS)  # what is scored against the truth


def fidelity_specs(
    grid: str | None = None,
    cells: str | None = None,
    tpcap: str | Path | None = None,
    scenes: list[str] | None = None,
) -> list[str]:
    """The ``--scene`` values of a fidelity run: the cells of grid "36", "12" or "252"
    (``cells``: a subset "0-5,9"), the TPCAP cases ``Case<N>.csv`` of folder ``tpcap``
    (in case order), or ``scenes``; exactly one source, else a one-line ConfigError."""
    given = [x for x in (grid, tpcap, scenes) if x]
    if len(given) != 1:
        raise ConfigError("give exactly one of --grid, --tpcap or --scene")
    if grid:
        idx = sc.grid_cells(grid, None, cells)
        return [f"robust:{i}" if grid == "252" else str(i) for i in idx]
    if tpcap:
        folder = Path(tpcap)
        found = [p for p in folder.glob("*.csv") if re.fullmatch(r"Case\d+\.csv", p.name)]
        if not found:
            raise ConfigError(f"--tpcap {folder}: no Case<N>.csv files there")
        return [str(p.resolve()) for p in sorted(found, key=lambda p: int(p.stem[4:]))]
    return [str(Path(s).resolve()) if Path(s).suffix else s for s in scenes or []]


def fidelity_job(
    spec: str,
    seed: int,
    files: dict,
    iso: dict | None = None,
    figure_dir: str | None = None,
    candidate: str = "chain",
) -> dict:
    """Executor job: plan ``spec`` once, drive it under the candidate and the truth
    (noise seed ``seed``), score the pair (ISO settings ``iso``, ISORatingConfig fields)
    and draw its figure into ``figure_dir``; JSON. ``candidate`` "chain" (the learned
    chain), "reference" (the truth again under the noise seed ``seed + 1``: the
    ceiling of every number, what the sensor noise alone costs), or a diagnosis hybrid
    (:mod:`parknss.sim.hybrid`): "nss" (the truth's actuators driving the chain's NSS)
    or "actuators" (the chain's actuator side driving the truth's body, noise seed
    ``seed + 1``)."""
    if candidate not in CANDIDATES:
        raise ConfigError(f"--candidate {candidate!r}: one of {', '.join(CANDIDATES)}")
    f = SimConfigFiles(**files)
    geom = f.vehicle_geometry()
    scene = load_scene(spec, f.scenarios_config(), geom)
    cfg = override(f.closed_loop_config(), {"plant_seed": seed}, source="fidelity seed")
    icfg = f.interface_config()
    if candidate == "chain":
        plan, (chain, truth) = run_cell(scene, PLANTS, cfg, icfg, f.planning, geom)
    elif candidate in HYBRIDS:
        plan, (truth,) = run_cell(scene, ["reference"], cfg, icfg, f.planning, geom)
        chain = truth
        if plan.trajectory is not None:
            hyb = make_hybrid(
                candidate,
                chain_path=cfg.chain_path,
                vehicle_yaml=cfg.reference_vehicle,
                seed=seed + 1,
                geom=geom,
            )
            chain = execute(scene, plan.trajectory, hyb, cfg, icfg, geom)
    else:
        plan, (truth,) = run_cell(scene, ["reference"], cfg, icfg, f.planning, geom)
        other = override(cfg, {"plant_seed": seed + 1}, source="fidelity ceiling seed")
        chain = truth
        if plan.trajectory is not None:
            _, (chain,) = run_cell(scene, ["reference"], other, icfg, f.planning, geom,
                                   trajectory=plan.trajectory)  # fmt: skip
    doc = {"spec": spec, "scene": scene.meta.name, "seed": seed,
           "plannable": plan.trajectory is not None, "plan_reason": plan.reason,
           "fidelity": None, "figure": None}  # fmt: skip
    if plan.trajectory is None:
        return doc
    cell = compare_outcomes(chain, truth, scene.meta.name, ISORatingConfig(**(iso or {})))
    doc["fidelity"] = cell.to_json()
    if figure_dir is not None:
        title = (f"{scene.meta.name}: {candidate} {chain.reason} {chain.duration_s:.1f} s, truth "
                 f"{truth.reason} {truth.duration_s:.1f} s; ISO vx {_f(cell.iso_vx)}, "
                 f"ω_z {_f(cell.iso_yaw_rate)}")  # fmt: skip
        path = Path(figure_dir) / f"fidelity_{scene.meta.name}.png"
        name = {"chain": "chain", "reference": "truth, seed + 1"}.get(candidate, candidate)
        runs = {name: chain.series, "reference": truth.series}
        doc["figure"] = str(draw_fidelity(runs, path, title))
    return doc


def _f(v, spec: str = ".3f") -> str:
    return "-" if v is None else format(v, spec)


CELL_COLUMNS = ("cell", "chain", "truth", "ratio", "goal chain/truth cm", "clr chain/truth cm",
                "ISO vx", "ISO ω_z", "rmse vx m/s", "gears agree")  # fmt: skip


def cell_row(doc: dict) -> list[str]:
    """One row of the per-cell table of a job's document."""
    c = doc["fidelity"]
    if c is None:
        return [doc["scene"], "not plannable"] + ["-"] * (len(CELL_COLUMNS) - 2)
    return [
        doc["scene"], c["chain_reason"], c["truth_reason"], _f(c["duration_ratio"], ".2f"),
        f"{_f(c['chain_goal_cm'], '.1f')}/{_f(c['truth_goal_cm'], '.1f')}",
        f"{_f(c['chain_clearance_cm'], '.1f')}/{_f(c['truth_clearance_cm'], '.1f')}",
        _f(c["iso_vx"]), _f(c["iso_yaw_rate"]), _f(c["rmse_vx_ms"]),
        "yes" if c["gear_sequence_agree"] else f"no ({c['chain_gear_changes']}/"
        f"{c['truth_gear_changes']})",
    ]  # fmt: skip


def markdown(title: str, text: str, docs: list[dict], out: Path) -> str:
    """The run's markdown page: summary, per-cell table, figure links."""
    lines = [
        f"# {title}",
        "",
        "```",
        text,
        "```",
        "",
        "| " + " | ".join(CELL_COLUMNS) + " |",
        "|" + " --- |" * len(CELL_COLUMNS),
    ]
    lines += ["| " + " | ".join(cell_row(d)) + " |" for d in docs]
    lines += [""] + [f"![{d['scene']}]({Path(d['figure']).relative_to(out)})"
                     for d in docs if d["figure"]]  # fmt: skip
    return "\n".join(lines) + "\n"


def run_fidelity(
    specs: list[str],
    out: Path,
    *,
    label: str,
    files: SimConfigFiles | None = None,
    fidelity_config: str | Path | None = None,
    figures: bool = True,
    candidate: str = "chain",
    executor: str = "local",
    workers: int = 1,
    address: str | None = None,
    overwrite: bool = False,
    progress: bool = True,
) -> dict:
    """``parknss fidelity``: score ``specs`` (:func:`fidelity_specs`) in the run folder
    ``out``; the report (summary with target lines, cells, file paths). ``candidate``:
    see :func:`fidelity_job`."""
    from parknss.executor import Job, run_jobs

    files = files or SimConfigFiles()
    fcfg = load_fidelity_config(fidelity_config)
    if candidate not in CANDIDATES:
        raise ConfigError(f"--candidate {candidate!r}: one of {', '.join(CANDIDATES)}")
    check_plants(PLANTS, files.closed_loop_config(), files.vehicle_geometry())
    identity = {
        "scenes": specs,
        "fidelity_config": None if fidelity_config is None else Path(fidelity_config),
        "figures": figures,
        **({} if candidate == "chain" else {"candidate": candidate}),
        **config_paths(files),
    }
    with run_folder(out, command="parknss fidelity", args=identity, overwrite=overwrite) as run:
        figdir = str((out / "cells").resolve()) if figures else None
        common = {"files": files.to_json(), "iso": fcfg.iso.model_dump(), "figure_dir": figdir}
        if candidate != "chain":  # the chain's job keys stay those of earlier runs
            common["candidate"] = candidate
        jobs = [
            Job(f"{__name__}:fidelity_job", {"spec": s, "seed": cell_seed(fcfg.seed, s), **common},
                name=s)
            for s in specs
        ]  # fmt: skip
        t0 = time.perf_counter()
        docs = run_jobs(
            jobs,
            executor=executor,
            workers=workers,
            address=address,
            cache_dir=out / "cache",
            progress=progress,
            desc="fidelity",
        )
        wall = time.perf_counter() - t0
        cells = [None if d["fidelity"] is None else CellFidelity(**d["fidelity"]) for d in docs]
        summary = summarize_fidelity(cells, fcfg.targets)
        text = fidelity_text(summary)
        who = {
            "chain": "the chain",
            "reference": "the truth under another seed (ceiling)",
            "nss": "the truth's actuators + the chain's NSS (hybrid)",
            "actuators": "the chain's actuators + the truth's body (hybrid)",
        }[candidate]
        title = f"Closed-loop fidelity of {who} against the truth: {label}"
        report = {"label": label, "cells": len(specs), "wall_s": round(wall, 2),
                  "summary": summary.to_json(), "text": text, "per_cell": docs}  # fmt: skip
        blank = {f.name: None for f in fields(CellFidelity)}
        rows = [{"scene": d["scene"], "seed": d["seed"], "plannable": d["plannable"],
                 **blank, **(d["fidelity"] or {})} for d in docs]  # fmt: skip
        write_rows_csv(rows, out / "fidelity_cells.csv")
        run.write_text("fidelity.md", markdown(title, text, docs, out.resolve()))
        write_fidelity_html(out / "fidelity.html", title, text.splitlines(), list(CELL_COLUMNS),
                            [cell_row(d) for d in docs],
                            [(d["scene"], str(Path(d["figure"]).relative_to(out.resolve())))
                             for d in docs if d["figure"]])  # fmt: skip
        run.write_json("fidelity.json", report)
        report["files"] = {
            k: str(out / k)
            for k in ("fidelity.json", "fidelity_cells.csv", "fidelity.md", "fidelity.html")
        }
    return report
