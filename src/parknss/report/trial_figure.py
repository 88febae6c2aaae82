"""Draw one trial: commands vs actuals, vx, yaw rate, ax, ay, with reverse shaded."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt

from parknss.data.trial import Trial
from parknss.report.style import save, shade_reverse
from parknss.signals import ms_to_kmh, rad_to_deg


def draw_trial(trial: Trial, path: str | Path) -> Path:
    """Seven stacked panels over the trial's time axis, saved as PNG at `path`."""
    t, gear = trial["t"], trial["gear"]
    panels = [
        ("gear [-]", [(gear, "gear", "k")]),
        ("torque [N·m]", [(trial["torque_cmd"], "cmd", "C1"), (trial["torque"], "actual", "C0")]),
        ("brake", [(trial["decel_cmd"], "decel cmd [m/s²]", "C1"),
                   (trial["brake_pressure"] / 10.0, "pressure [10 bar]", "C0")]),
        ("steer [deg]", [(trial["steer_cmd"], "cmd", "C1"), (trial["steer"], "actual", "C0")]),
        ("vx [km/h]", [(ms_to_kmh(trial["vx"]), "vx", "C0")]),
        ("ω_z [°/s]", [(rad_to_deg(trial["yaw_rate"]), "yaw rate", "C0")]),
        ("accel [m/s²]", [(trial["ax"], "ax", "C0"), (trial["ay"], "ay", "C2")]),
    ]
    fig, axes = plt.subplots(len(panels), 1, sharex=True, figsize=(10, 12))
    for ax, (label, series) in zip(axes, panels, strict=True):
        shade_reverse(ax, t, gear)
        for y, name, color in series:
            ax.plot(t, y, lw=0.8, color=color, label=name)
        ax.set_ylabel(label)
        if len(series) > 1:
            ax.legend(loc="upper right", fontsize=7)
    axes[0].set_title(f"{trial.id} ({trial.maneuver}); reverse shaded")
    axes[-1].set_xlabel("t [s]")
    return save(fig, path)
