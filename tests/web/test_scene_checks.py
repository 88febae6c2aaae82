"""Posted scenes with numbers beyond the physical range or mistyped meta fields are refused
at once with a one-line 422 (parknss.web.scene_checks), never planned into a 500."""

from __future__ import annotations

import json

import pytest
from fastapi.testclient import TestClient

from parknss.sim.scenarios import grid_scene
from parknss.web.app import create_app
from parknss.web.config import load_web_config
from parknss.web.errors import BadSceneError
from parknss.web.scene_checks import check_scene_json

CELL = 26


@pytest.fixture(scope="module")
def client():
    with TestClient(create_app(load_web_config()), base_url="http://localhost") as c:
        yield c


def _scene(**changes) -> dict:
    doc = grid_scene(CELL).to_json()
    doc.update(changes)
    return doc


def _vertex(value) -> dict:
    doc = _scene()
    doc["obstacles"][0]["vertices"][0][0] = value
    return doc


HOSTILE = [
    ("name a number", _scene(meta={"name": 123}), "meta.name: Input should be a valid string"),
    ("tier a word", _scene(meta={"tier": "third"}), "scene.meta.tier"),
    ("vertex 1e308", _vertex(1e308), "obstacles[0].vertices[0][0]: 1e+308 m is outside"),
    ("vertex 10**400", _vertex(10**400), "a huge number m is outside"),
    ("bounds 1e6", _scene(bounds=[-1e6, -1e6, 1e6, 1e6]), "scene.bounds[0]: -1e+06 m"),
    ("bounds 1e308", _scene(bounds=[-1e308, -1e308, 1e308, 1e308]), "±1000 m"),
    ("goal far", _scene(goal=[5000.0, 0.0, 0.0]), "scene.goal[0]"),
    (
        "map outline far",
        _scene(map_outline=[[0.0, 0.0], [1e6, 0.0], [0.0, 10.0]]),
        "scene.map_outline[1][0]: 1e+06 m",
    ),
    ("heading 1e308", _scene(start=[0.0, 0.0, 1e308]), "scene.start[2]: 1e+308 rad"),
]


@pytest.mark.parametrize(("what", "scene", "needle"), HOSTILE, ids=lambda v: v)
def test_hostile_scenes_get_422_at_once(client, what, scene, needle):
    for path, extra in (("/api/plan", {}), ("/api/simulate", {"plant": "kinematic"})):
        resp = client.post(path, json={"scene": scene, **extra})
        assert resp.status_code == 422, resp.text
        msg = resp.json()["error"]
        assert needle in msg and "\n" not in msg


def test_an_edited_start_out_of_range_is_422(client):
    resp = client.post("/api/plan", json={"index": CELL, "start": [1e6, 0.0, 0.0]})
    assert resp.status_code == 422 and resp.json()["error"].startswith("start[0]: 1e+06 m")
    resp = client.post("/api/plan", json={"index": CELL, "start": [0.0, 0.0, -1e9]})
    assert resp.status_code == 422 and "start[2]" in resp.json()["error"]


def test_bodies_that_break_the_json_parser_are_400(client):
    deep = "[" * 100_000 + "]" * 100_000
    for body in (deep, '{"index": ' + "9" * 5000 + "}", b'{"index": "\xff"}'):
        resp = client.post("/api/plan", content=body, headers={"content-type": "application/json"})
        assert resp.status_code == 400, resp.text
        assert resp.json()["error"].startswith("request body is not valid JSON")


def test_the_range_is_a_config_value_and_real_scenes_pass():
    check_scene_json(grid_scene(CELL).to_json(), 1000.0, 100.0)
    wide = _scene(bounds=[-999.0, -999.0, 999.0, 999.0])
    check_scene_json(wide, 1000.0, 100.0)
    with pytest.raises(BadSceneError, match="±500 m"):
        check_scene_json(wide, 500.0, 100.0)
    check_scene_json(json.loads(json.dumps(_scene(meta={"name": "mine", "tier": 2}))), 1e3, 1e2)
