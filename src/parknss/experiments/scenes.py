"""``parknss plan`` and ``parknss simulate`` as library calls: one scene planned and drawn,
a grid planned, or one scene driven in closed loop (Figs. 8/9), into a run folder.

Each claims its folder through :func:`parknss.outputs.run_folder` (the same command with
the same scene, plants and configs may write into it again; anything else there is
refused unless ``overwrite``) and writes every file atomically. Without ``out`` the one-
scene runs write to ``runs/plan/<scene>`` and ``runs/simulate/<scene>``, one folder per
scene, so planning or driving scene after scene needs no ``--overwrite``; ``plan --grid``
writes only with ``out``. The scene's name becomes part of file and folder names only
through :func:`parknss.outputs.safe_stem`, checked before any planning, and every file is
checked to lie inside the run folder (:func:`parknss.outputs.inside`).
"""

from __future__ import annotations

from pathlib import Path

from parknss.outputs import default_run_folder, run_folder, safe_stem
from parknss.sim.closed_loop import SimConfigFiles
from parknss.sim.grid import config_paths
from parknss.sim.scene_formats import load_scene

# the figures, the planner and the closed loop are imported by the runs that use them:
# `parknss plan` starts without matplotlib (its figure is SVG), the tracker or the
# closed-loop plants


def _scene_arg(spec: str) -> str | Path:
    """The ``--scene`` value as a manifest argument: a cell as given, a file resolved."""
    text = spec.strip()
    if text.isdigit() or text.lower().startswith("robust:"):
        return text.lower()
    return Path(text)


def plan_one(
    spec: str,
    files: SimConfigFiles | None = None,
    *,
    refine: bool = True,
    closed_loop_overrides: dict | None = None,
    out: Path | None = None,
    overwrite: bool = False,
    figure: bool = True,
) -> dict:
    """``parknss plan --scene``: plan a scene JSON file, grid cell 0-35 or ``robust:N``
    (:func:`parknss.sim.planner.plan_named_scene`), draw ``plan_<scene>.svg`` (unless not
    ``figure``; SVG written without matplotlib) and, with ``out``, write
    ``plan_<scene>.json``; the plan summary with the figure's path (None without one)."""
    files = files or SimConfigFiles()
    scene = load_scene(spec, files.scenarios_config(), files.vehicle_geometry())
    name = safe_stem(scene.meta.name, what="scene name")  # before the work
    folder = out or default_run_folder("plan", name, what="scene name")
    identity = {"scene": _scene_arg(spec), "refine": refine,
                "closed_loop_overrides": closed_loop_overrides, **config_paths(files)}
    with run_folder(folder, command="parknss plan", args=identity, overwrite=overwrite) as run:
        from parknss.sim.planner import plan_named_scene

        scene, plan = plan_named_scene(spec, files, refine=refine,
                                       closed_loop_overrides=closed_loop_overrides)
        geom = files.vehicle_geometry()
        summary = plan.to_json(scene)
        if scene.notes:
            summary["scene_notes"] = list(scene.notes)
        summary["figure"] = None
        if figure:
            from parknss.report.plan_figure import draw_plan  # SVG, no matplotlib

            svg = run.file(f"plan_{name}.svg")
            summary["figure"] = str(draw_plan(scene, svg, coarse=plan.coarse,
                                              refined=plan.refinement, geom=geom))
        if Path(str(spec)).suffix.lower() in (".csv", ".xml"):  # an imported scene
            summary["scene_json"] = str(run.write_json(f"scene_{name}.json",
                                                       scene.to_json()))
        if out is not None:
            run.write_json(f"plan_{name}.json", summary)
    return summary


def plan_grid_run(
    grid: str,
    files: SimConfigFiles | None = None,
    *,
    refine: bool = True,
    closed_loop_overrides: dict | None = None,
    executor: str = "local",
    workers: int = 1,
    address: str | None = None,
    out: Path | None = None,
    overwrite: bool = False,
) -> list[dict]:
    """``parknss plan --grid``: plan every cell through the executor
    (:func:`parknss.sim.planner.plan_grid`) and, with ``out``, write
    ``plan_grid_<grid>.json`` there; one plan summary per cell."""
    from parknss.sim import scenarios as sc
    from parknss.sim.planner import plan_grid

    files = files or SimConfigFiles()
    kwargs = {"files": files, "refine": refine, "closed_loop_overrides": closed_loop_overrides,
              "executor": executor, "workers": workers, "address": address}
    if out is None:
        return plan_grid(grid, **kwargs)
    cells = sc.grid_cells(grid, files.scenarios_config())  # a bad --grid: before the claim
    identity = {"grid": grid, "refine": refine,
                "closed_loop_overrides": closed_loop_overrides, **config_paths(files)}
    with run_folder(out, command="parknss plan", args=identity, overwrite=overwrite) as run:
        rows = plan_grid(grid, cells, **kwargs)
        run.write_json(f"plan_grid_{grid}.json", rows)
    return rows


def simulate_one(
    spec: str,
    plants: list[str],
    files: SimConfigFiles | None = None,
    *,
    out: Path | None = None,
    series: bool = False,
    overwrite: bool = False,
) -> dict:
    """``parknss simulate``: plan a scene once and drive it under each of ``plants``
    (:func:`parknss.sim.session.simulate_scene`); draw Figs. 8/9 (and, with ``series``,
    write the time-series CSVs) and ``simulate_<scene>.json``; the JSON summary."""
    from parknss.report.sim_figures import draw_scene_run
    from parknss.sim.session import check_plants, simulate_scene

    files = files or SimConfigFiles()
    check_plants(plants, files.closed_loop_config(), files.vehicle_geometry())  # fail fast
    scene = load_scene(spec, files.scenarios_config(), files.vehicle_geometry())
    name = safe_stem(scene.meta.name, what="scene name")  # before the work
    folder = out or default_run_folder("simulate", name, what="scene name")
    identity = {"scene": _scene_arg(spec), "plants": plants, "series": series,
                **config_paths(files)}
    with run_folder(folder, command="parknss simulate", args=identity,
                    overwrite=overwrite) as run:
        scene_run = simulate_scene(scene, plants, files)
        doc = scene_run.to_json()
        figures = draw_scene_run(scene_run, folder)
        if figures:
            doc["figures"] = figures
            if series:
                doc["series"] = scene_run.write_series(folder)
        run.write_json(f"simulate_{name}.json", doc)
    return doc
