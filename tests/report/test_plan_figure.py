"""The plan figure: a large map is drawn zoomed to the problem, a small one whole."""

from dataclasses import replace

import matplotlib.pyplot as plt

from parknss.report.plan_figure import ZOOM_PAD_M, finish_scene, scene_axes
from parknss.sim.scenarios import grid_scene
from parknss.vehicle import VehicleGeometry


def _limits(scene, tmp_path, monkeypatch):
    seen = {}
    monkeypatch.setattr(plt, "close", lambda *a, **k: None)
    fig, ax = scene_axes(scene)
    finish_scene(fig, ax, scene, VehicleGeometry(), "t", tmp_path / "f.png", 1.0)
    seen["x"], seen["y"] = ax.get_xlim(), ax.get_ylim()
    plt.close(fig)
    return seen


def test_large_maps_zoom_to_the_problem_small_maps_stay_whole(tmp_path, monkeypatch):
    small = grid_scene(2)
    lim = _limits(small, tmp_path, monkeypatch)
    assert lim["x"] == (small.bounds[0] - 0.5, small.bounds[2] + 0.5)
    x0, y0 = small.bounds[:2]
    big = replace(small, bounds=(x0, y0, x0 + 1000.0, y0 + 1000.0))
    lim = _limits(big, tmp_path, monkeypatch)
    xs = [small.start[0], small.goal[0]]
    assert lim["x"][1] < max(xs) + ZOOM_PAD_M + 5.0 + 0.5  # 5 m: a car length
    assert lim["y"][1] < max(small.start[1], small.goal[1]) + ZOOM_PAD_M + 5.5
