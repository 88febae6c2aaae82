"""The plan figure: a large map is drawn zoomed to the problem, a small one whole; the
SVG plan figure holds every layer (obstacles, map, start, goal, footprints, both paths
forward solid and reverse dashed, cusps), its path points where the poses are, and the
scene's name escaped."""

import xml.etree.ElementTree as ET
from dataclasses import replace

import matplotlib.pyplot as plt
import numpy as np
import pytest

from parknss.report.plan_figure import (
    ZOOM_PAD_M,
    draw_plan,
    finish_scene,
    scene_axes,
    view_box,
)
from parknss.report.svg import SvgAxes
from parknss.sim.scenarios import grid_scene
from parknss.sim.trajectory import Segment, Trajectory
from parknss.vehicle import VehicleGeometry

NS = {"s": "http://www.w3.org/2000/svg"}


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


def _plan(scene):
    """A two-segment plan (forward, then reverse into the goal) over ``scene``."""
    s, g = np.array(scene.start), np.array(scene.goal)
    mid = (s + g) / 2 + np.array([0.0, 2.0, 0.0])
    fwd = Segment(np.linspace(s, mid, 12), 1)
    rev = Segment(np.linspace(mid, g, 9), -1)
    return Trajectory([fwd, rev], source="refined")


def test_the_plan_figure_is_svg_with_every_layer(tmp_path):
    scene = replace(grid_scene(2), meta=replace(grid_scene(2).meta, name='bay <2> & "x"'))
    plan = _plan(scene)
    coarse = Trajectory([Segment(np.linspace(scene.start, scene.goal, 5), -1)])
    path = draw_plan(scene, tmp_path / "p.svg", coarse=coarse, refined=plan,
                     geom=VehicleGeometry())
    root = ET.parse(path).getroot()  # well-formed, the name escaped
    assert root.find("s:title", NS).text == 'bay <2> & "x"'

    def layer(cls):
        return root.findall(f".//*[@class='{cls}']", NS)

    assert len(layer("obstacle")) == len(scene.obstacles)
    assert len(layer("map")) == len(layer("start")) == len(layer("goal")) == 1
    assert len(layer("cusp")) == 1 and len(layer("footprint")) > 5
    refined = layer("path-refined")
    assert [bool(e.get("stroke-dasharray")) for e in refined] == [False, True]  # fwd, rev
    assert len(layer("path-coarse")) == 1
    # the path's points are drawn where its poses are
    ax = SvgAxes(*_view(scene, root))
    for el, seg in zip(refined, plan.segments, strict=True):
        pts = np.array([[float(v) for v in p.split(",")] for p in el.get("points").split()])
        assert np.allclose(pts, ax.px(seg.poses), atol=0.006)


def _view(scene, root):
    """The (xlim, ylim) of a small map's figure: its bounds with the 0.5 m border."""
    return (scene.bounds[0] - 0.5, scene.bounds[2] + 0.5), (scene.bounds[1] - 0.5,
                                                            scene.bounds[3] + 0.5)


def test_the_svg_plan_of_a_large_map_is_zoomed_like_the_png_figures():
    small = grid_scene(2)
    plan = _plan(small)
    pts = np.concatenate([s.poses[:, :2] for s in plan.segments])
    assert view_box(small.bounds, pts) == tuple(
        np.add(small.bounds, [-0.5, -0.5, 0.5, 0.5]))
    x0, y0 = small.bounds[:2]
    big = (x0, y0, x0 + 1000.0, y0 + 1000.0)
    box = view_box(big, pts)
    assert box[2] == pytest.approx(pts[:, 0].max() + ZOOM_PAD_M + 0.5)
    assert box[3] == pytest.approx(pts[:, 1].max() + ZOOM_PAD_M + 0.5)
