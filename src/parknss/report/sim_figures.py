"""Closed-loop figures: Fig. 8 (planned vs driven path in the scene) and Fig. 9 (vehicle
states vx, ω_z, ax, ay under several plants on a common time axis); :func:`draw_scene_run`
draws both for a :class:`~parknss.sim.session.SceneRun`."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from parknss.outputs import inside, safe_stem
from parknss.report.plan_figure import finish_scene, outline, scene_axes
from parknss.report.style import save, shade_reverse
from parknss.signals import ms_to_kmh, rad_to_deg
from parknss.sim.geometry import footprint
from parknss.sim.session import SceneRun
from parknss.sim.trajectory import Trajectory
from parknss.vehicle import VehicleGeometry

PLANT_COLOURS = {"kinematic": "#00bcd4", "chain": "#e67e22", "reference": "#8e44ad"}
PLANNED_COLOUR = "#27ae60"


def draw_driven(
    scene,
    trajectory: Trajectory,
    runs: dict[str, dict[str, np.ndarray]],
    path: str | Path,
    geom: VehicleGeometry | None = None,
    title: str | None = None,
) -> Path:
    """Fig. 8: the scene, the planned path (green) and each plant's driven rear-axle path.

    ``runs`` maps a plant name to its time series (needs x, y, heading). The final
    footprint of each run is outlined. Returns the PNG path.
    """
    geom = geom or VehicleGeometry()
    fig, ax = scene_axes(scene)
    first = True
    for seg in trajectory.segments:
        ax.plot(
            seg.poses[:, 0],
            seg.poses[:, 1],
            "-" if seg.direction > 0 else "--",
            color=PLANNED_COLOUR,
            lw=2.2,
            label="planned" if first else None,
        )
        first = False
    for name, s in runs.items():
        colour = PLANT_COLOURS.get(name, "#34495e")
        ax.plot(s["x"], s["y"], "-", color=colour, lw=1.1, label=f"driven ({name})")
        pose = (s["x"][-1], s["y"][-1], s["heading"][-1])
        outline(ax, footprint(pose, geom), color=colour, lw=1.0)
    return finish_scene(
        fig, ax, scene, geom, title or f"{scene.meta.name}: planned vs driven", path, 1.4
    )


def _smooth(v: np.ndarray, n: int) -> np.ndarray:
    """Centred moving average over n samples (edges use the available samples)."""
    if n <= 1 or len(v) < 2:
        return v
    kernel = np.ones(n)
    num = np.convolve(v, kernel, mode="same")
    den = np.convolve(np.ones_like(v), kernel, mode="same")
    return num / den


def draw_states(
    runs: dict[str, dict[str, np.ndarray]],
    path: str | Path,
    title: str = "",
    smooth_s: float = 0.2,
    dt: float = 0.01,
) -> Path:
    """Fig. 9: vx [km/h], ω_z [°/s], ax and ay [m/s²] of each plant on one time axis.

    ax and ay are shown with a centred moving average of ``smooth_s`` seconds; reverse
    gear of the first run is shaded, and the legend says so ("reverse gear (<plant>)").
    Returns the PNG path.
    """
    fig, axes = plt.subplots(4, 1, figsize=(10, 9), sharex=True)
    n = max(1, round(smooth_s / dt))
    rows = (
        ("vx", "v_x [km/h]", ms_to_kmh, 1),
        ("yaw_rate", "ω_z [°/s]", rad_to_deg, 1),
        ("ax", f"a_x [m/s²] ({smooth_s:.1f} s avg)", lambda v: v, n),
        ("ay", f"a_y [m/s²] ({smooth_s:.1f} s avg)", lambda v: v, n),
    )
    first = next(iter(runs.values()), None)
    for ax, (key, label, conv, width) in zip(axes, rows, strict=True):
        if first is not None:
            shade_reverse(ax, first["t"], first["gear"])
        for name, s in runs.items():
            ax.plot(
                s["t"],
                _smooth(conv(np.asarray(s[key])), width),
                color=PLANT_COLOURS.get(name, "#34495e"),
                lw=1.0,
                label=name,
            )
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    if first is not None and np.any(np.asarray(first["gear"]) < -0.5):
        from matplotlib.patches import Patch

        axes[0].add_artist(axes[0].legend(loc="upper right", fontsize=8))
        axes[0].legend(handles=[Patch(color="0.85", label=f"reverse gear ({next(iter(runs))})")],
                       loc="upper left", fontsize=8)
    else:
        axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("t [s]")
    if title:
        axes[0].set_title(title)
    return save(fig, path)


def draw_scene_run(run: SceneRun, out: str | Path) -> dict[str, str]:
    """Figs. 8 and 9 of a simulated scene as ``fig8_<scene>_<plants>.png`` and
    ``fig9_...`` in ``out``; {"fig8": path, "fig9": path}, or {} when not plannable."""
    if run.plan.trajectory is None:
        return {}
    runs = {o.plant: o.series for o in run.outcomes}
    name, tag = safe_stem(run.scene.meta.name, what="scene name"), "_vs_".join(runs)
    fig8 = draw_driven(
        run.scene, run.plan.trajectory, runs, inside(out, f"fig8_{name}_{tag}.png"), run.geom
    )
    fig9 = draw_states(runs, inside(out, f"fig9_{name}_{tag}.png"), title=name)
    return {"fig8": str(fig8), "fig9": str(fig9)}
