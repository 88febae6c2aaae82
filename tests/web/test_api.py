"""The simulator API (parknss.web.app) through FastAPI's TestClient: plans that start at
the scene's start and end at its goal, runs equal to ``parknss simulate --json``, one-line
4xx/5xx JSON errors for every malformed request, the missing chain as a clear 503."""

from __future__ import annotations

import asyncio
import json
import math
import threading

import numpy as np
import pytest
from fastapi.testclient import TestClient

from parknss.sim.scenarios import Scene, grid_scene
from parknss.sim.session import simulate_scene
from parknss.web.app import create_app
from parknss.web.config import load_web_config
from parknss.web.errors import BusyError
from parknss.web.jobs import ComputeRunner
from parknss.web.payload import decimate_series, resample_poses

CELL = 26  # angled-left-t1-open: one cusp, plans in a fraction of a second
# generous wall-clock budgets (a loaded machine must not fail a test); a small cache
BUDGETS = {"plan_budget_s": 300.0, "simulate_budget_s": 600.0, "plan_cache_size": 4}
LOCAL = "http://localhost"  # TestClient's default Host, "testserver", is not this server


@pytest.fixture(scope="module")
def client():
    with TestClient(create_app(load_web_config(**BUDGETS)), base_url=LOCAL) as c:
        yield c


def _error(resp, status: int, needle: str) -> str:
    assert resp.status_code == status, resp.text
    doc = resp.json()
    assert set(doc) == {"error", "status"} and doc["status"] == status
    msg = doc["error"]
    assert needle.lower() in msg.lower(), msg
    assert "\n" not in msg and "Traceback" not in msg
    return msg


def test_health_lists_every_plant_and_the_vehicle(client):
    doc = client.get("/api/health").json()
    assert doc["status"] == "ok" and doc["version"]
    plants = {p["kind"]: p for p in doc["plants"]}
    assert set(plants) == {"kinematic", "chain", "reference"}
    assert plants["kinematic"]["available"]
    for p in plants.values():
        assert p["available"] or p["reason"]
    assert doc["vehicle"]["length_m"] == pytest.approx(4.95)
    assert doc["grids"] == {"36": 36, "252": 252}


def test_cells_and_scenes_are_the_grid(client):
    cells = client.get("/api/cells").json()["cells"]
    assert [c["index"] for c in cells] == list(range(36))
    assert cells[CELL]["name"] == grid_scene(CELL).meta.name
    robust = client.get("/api/cells", params={"grid": "252"}).json()["cells"]
    assert len(robust) == 252 and robust[40]["cell"] == 4
    assert robust[40]["perturbation"] == "skew_neg"
    doc = client.get("/api/scene", params={"index": CELL}).json()
    scene = Scene.from_json(doc["scene"])
    assert scene.start == grid_scene(CELL).start and scene.goal == grid_scene(CELL).goal
    assert len(scene.obstacles) == len(grid_scene(CELL).obstacles)


def test_a_planned_cell_runs_from_the_start_to_the_goal(client):
    doc = client.post("/api/plan", json={"index": CELL}).json()
    assert doc["plannable"] and doc["reason"] == "ok"
    scene = grid_scene(CELL)
    first = doc["path"][0]["poses"][0]
    last = doc["path"][-1]["poses"][-1]
    assert first == pytest.approx(list(scene.start), abs=1e-3)
    assert last == pytest.approx(list(scene.goal), abs=1e-3)
    assert doc["cusps"] == len(doc["path"]) - 1 == len(doc["cusp_poses"])
    assert {s["direction"] for s in doc["path"]} == {1, -1}
    # the closed-loop plan margin of configs/closed_loop.yaml (20 cm) holds
    assert doc["min_clearance_cm"] >= 20.0 - 1e-6
    length = sum(
        float(np.sum(np.hypot(*np.diff(np.asarray(s["poses"])[:, :2], axis=0).T)))
        for s in doc["path"]
    )
    assert length == pytest.approx(doc["length_m"], rel=0.01)
    assert all(len(fp) == 4 for fp in doc["footprints"]) and len(doc["footprints"]) > 5
    again = client.post("/api/plan", json={"index": CELL}).json()
    assert again["cached"] and again["scene_key"] == doc["scene_key"]


def test_an_edited_start_or_a_scene_file_is_planned_as_given(client):
    x, y, th = grid_scene(CELL).start
    start = [x + 0.5, y + 0.3, th + math.radians(5.0)]
    doc = client.post("/api/plan", json={"index": CELL, "start": start}).json()
    assert doc["plannable"]
    assert doc["path"][0]["poses"][0] == pytest.approx(start, abs=1e-3)
    assert doc["start"] == pytest.approx(start)
    scene = grid_scene(CELL).to_json()
    custom = client.post("/api/plan", json={"scene": scene}).json()
    by_index = client.post("/api/plan", json={"index": CELL}).json()
    assert custom["scene_key"] == by_index["scene_key"]
    assert custom["length_m"] == by_index["length_m"]


def test_simulate_equals_the_cli(client):
    """The browser's run is ``parknss simulate``'s: the same plan and the same outcome."""
    cli = simulate_scene(str(CELL), ["kinematic"]).to_json()
    doc = client.post("/api/simulate", json={"index": CELL, "plant": "kinematic"}).json()
    out = doc["outcome"]
    assert out["completed"] and out["reason"] == "completed" and out["plant"] == "kinematic"
    for key in ("goal_error_cm", "heading_error_deg", "clearance_cm", "duration_s"):
        assert out[key] == pytest.approx(cli[key], rel=1e-9, abs=1e-9), key
    assert doc["plan"]["cusps"] == cli["cusps"] and doc["plan"]["refined"] == cli["refined"]
    assert doc["plan"]["length_m"] == pytest.approx(cli["planned_length_m"], abs=1e-3)
    s = doc["series"]
    assert s["rate_hz"] == pytest.approx(25.0) and s["stride"] == 4
    assert len(s["t"]) == math.ceil(out["steps"] / 4) + ((out["steps"] - 1) % 4 != 0)
    assert s["t"][-1] == pytest.approx(out["duration_s"])
    assert np.all(np.diff(s["t"]) > 0)
    gx, gy, _ = grid_scene(CELL).goal
    final = math.hypot(s["x"][-1] - gx, s["y"][-1] - gy) * 100.0
    assert final == pytest.approx(out["goal_error_cm"], abs=0.02)
    assert [s["x"][0], s["y"][0]] == pytest.approx(list(grid_scene(CELL).start[:2]), abs=1e-4)
    assert set(s["gear"]) <= {-1.0, 0.0, 1.0} and {-1.0, 1.0} <= set(s["gear"])
    assert max(abs(v) for v in s["vx"]) <= 0.76  # the tracker's 0.75 m/s ceiling


def test_fidelity_equals_the_cli(client):
    """The page's chain-vs-truth view of a cell is ``parknss fidelity``'s for that cell: the
    same noise seed, the same CellFidelity numbers, the targets checked on the one cell, and
    both runs' series for the overlay."""
    from parknss.experiments.fidelity import fidelity_job
    from parknss.sim.closed_loop import SimConfigFiles
    from parknss.sim.fidelity import cell_seed, load_fidelity_config

    fcfg = load_fidelity_config()
    seed = cell_seed(fcfg.seed, str(CELL))
    cli = fidelity_job(str(CELL), seed, SimConfigFiles().to_json(), fcfg.iso.model_dump())
    doc = client.post("/api/fidelity", json={"index": CELL}).json()
    assert doc["seed"] == seed and doc["truth"]["outcome"]["seed"] == seed
    assert doc["chain"]["outcome"]["plant"] == "chain"
    assert doc["truth"]["outcome"]["plant"] == "reference"
    for key, want in cli["fidelity"].items():
        got = doc["fidelity"][key]
        if isinstance(want, float):
            assert got == pytest.approx(want, rel=1e-5, abs=1e-9), key
        else:
            assert got == want, key
    assert len(doc["targets"]) == 7
    dev = abs(cli["fidelity"]["duration_ratio"] - 1.0)
    line = next(t for t in doc["targets"] if t["label"] == "median |duration ratio - 1|")
    assert line["measured"] == pytest.approx(dev) and line["passed"] == (dev <= line["limit"])
    for run in ("chain", "truth"):
        s = doc[run]["series"]
        assert s["t"][-1] == pytest.approx(doc[run]["outcome"]["duration_s"])
    other = client.post("/api/fidelity", json={"index": CELL, "seed": seed + 1}).json()
    assert other["seed"] == seed + 1 and other["plan"]["cached"]


MALFORMED = [
    ("bad json", '{"index": 1', 400, "not valid JSON"),
    ("unknown plant", {"index": 1, "plant": "bicycle"}, 422, "unknown plant 'bicycle'"),
    ("cell out of range", {"index": 36}, 422, "0..35"),
    ("robust out of range", {"grid": "252", "index": 252}, 422, "0..251"),
    ("negative cell", {"index": -1}, 422, "0..35"),
    ("unknown grid", {"grid": "12", "index": 1}, 422, "grid"),
    ("index not a number", {"index": "two"}, 422, "index"),
    ("no scene", {}, 422, "exactly one"),
    ("two scenes", {"index": 1, "scene": {}}, 422, "exactly one"),
    ("unknown field", {"index": 1, "speed": 3}, 422, "speed"),
    ("nan start", '{"index": 1, "start": [NaN, 0, 0]}', 422, "finite"),
    ("short start", {"index": 1, "start": [0, 0]}, 422, "start"),
    ("start in collision", {"index": CELL, "start": [-4.0, -3.0, 0.0]}, 422, "overlaps"),
    ("start off the map", {"index": CELL, "start": [30.0, 0.0, 0.0]}, 422, "leaves the map"),
]


def _scene(**changes) -> dict:
    doc = grid_scene(CELL).to_json()
    doc.update(changes)
    return doc


BAD_SCENES = [
    ("one vertex", _scene(obstacles=[{"kind": "car", "vertices": [[0, 0]]}]), "2"),
    (
        "self-intersecting",
        _scene(obstacles=[{"kind": "car", "vertices": [[0, 0], [4, 4], [4, 0], [0, 4]]}]),
        "not simple",
    ),
    ("too many", _scene(obstacles=[{"vertices": [[0, 0], [1, 0], [0, 1]]}] * 2001), "max_obst"),
    ("vertex text", _scene(obstacles=[{"vertices": [["a", 0], [1, 0], [0, 1]]}]), "numbers"),
    ("missing goal", {k: v for k, v in _scene().items() if k != "goal"}, "goal"),
    ("bounds reversed", _scene(bounds=[5, 5, -5, -5]), "xmin < xmax"),
    ("not an object", _scene(obstacles="cars"), "list"),
]


@pytest.mark.parametrize(("what", "body", "status", "needle"), MALFORMED, ids=lambda v: v)
def test_malformed_requests_get_one_line(client, what, body, status, needle):
    for path in ("/api/plan", "/api/simulate"):
        if isinstance(body, str):
            resp = client.post(path, content=body, headers={"content-type": "application/json"})
        else:
            resp = client.post(path, json=body)
        if what == "unknown plant" and path == "/api/plan":
            assert resp.status_code == 422  # plan takes no plant: unknown field
            continue
        _error(resp, status, needle)


@pytest.mark.parametrize(("what", "scene", "needle"), BAD_SCENES, ids=lambda v: v)
def test_bad_scene_json_gets_one_line(client, what, scene, needle):
    _error(client.post("/api/plan", json={"scene": scene}), 422, needle)


def test_nan_inside_a_scene_is_refused(client):
    body = json.dumps({"scene": _scene(start=[float("nan"), 2.0, 0.0])})
    assert "NaN" in body
    resp = client.post("/api/plan", content=body, headers={"content-type": "application/json"})
    _error(resp, 422, "finite")


def test_bad_queries_and_routes(client):
    _error(client.get("/api/scene", params={"index": 99}), 422, "0..35")
    _error(client.get("/api/scene", params={"index": "x"}), 422, "index")
    _error(client.get("/api/cells", params={"grid": "7"}), 422, "grid")
    _error(client.get("/api/nothing"), 404, "not found")
    _error(client.get("/api/plan"), 405, "not allowed")


def test_missing_chain_is_a_clear_503(tmp_path):
    cfg_file = tmp_path / "closed_loop.yaml"
    cfg_file.write_text(f"chain_path: {tmp_path / 'no_chain_here'}\n")
    cfg = load_web_config(**BUDGETS, closed_loop_config=str(cfg_file))
    with TestClient(create_app(cfg), base_url=LOCAL) as c:
        msg = _error(c.post("/api/simulate", json={"index": CELL, "plant": "chain"}), 503, "chain")
        plants = {p["kind"]: p for p in c.get("/api/health").json()["plants"]}
        assert not plants["chain"]["available"] and plants["chain"]["reason"] == msg


def test_not_plannable_is_a_result_not_an_error(client):
    scene = _scene()
    gx, gy, _ = scene["goal"]
    scene["obstacles"] = [
        *scene["obstacles"],
        {
            "kind": "cone",
            "vertices": [
                [gx - 0.2, gy - 0.2],
                [gx + 0.2, gy - 0.2],
                [gx + 0.2, gy + 0.2],
                [gx - 0.2, gy + 0.2],
            ],
        },
    ]
    doc = client.post("/api/simulate", json={"scene": scene, "plant": "kinematic"}).json()
    assert not doc["plan"]["plannable"] and doc["plan"]["reason"] == "goal in collision"
    assert doc["outcome"]["reason"] == "not plannable" and doc["series"] is None
    assert doc["plan"]["path"] == []


def test_over_budget_is_504_and_unexpected_errors_are_500_without_traceback():
    cfg = load_web_config(**{**BUDGETS, "simulate_budget_s": 0.001})
    app = create_app(cfg)
    with TestClient(app, raise_server_exceptions=False, base_url=LOCAL) as c:
        _error(c.post("/api/simulate", json={"index": CELL}), 504, "budget of 0.001 s")

        def boom(_req):
            raise RuntimeError("secret internals")

        app.state.service.plan_request = boom
        msg = _error(c.post("/api/plan", json={"index": CELL}), 500, "internal error")
        assert "secret" not in msg


def test_the_runner_refuses_work_beyond_max_pending():
    runner = ComputeRunner(workers=1, max_pending=1)
    gate = threading.Event()

    async def scenario():
        first = asyncio.ensure_future(runner.run(5.0, "first", gate.wait, 5.0))
        await asyncio.sleep(0.05)
        with pytest.raises(BusyError, match="busy"):
            await runner.run(5.0, "second", lambda: None)
        gate.set()
        assert await first is True

    asyncio.run(scenario())
    assert runner.pending == 0
    runner.shutdown()


def test_payload_decimation_keeps_the_ends():
    n = 1003
    series = {
        name: np.arange(n, dtype=float) * 0.01
        for name in (
            "t",
            "x",
            "y",
            "heading",
            "vx",
            "yaw_rate",
            "ax",
            "ay",
            "gear",
            "steer",
            "torque",
            "brake_pressure",
            "gear_cmd",
            "torque_cmd",
            "decel_cmd",
            "steer_cmd",
            "speed_req",
        )
    }
    series["ax"][5] = np.nan
    s = decimate_series(series, rate_hz=25.0, max_points=4000)
    assert s.stride == 4 and s.t[0] == 0.0 and s.t[-1] == pytest.approx(10.02)
    assert len(s.t) == 252 and s.ax[1] == pytest.approx(0.04)
    s = decimate_series(series, rate_hz=25.0, max_points=101)
    assert len(s.t) <= 101 + 1 and s.t[-1] == pytest.approx(10.02)
    poses = np.column_stack([np.linspace(0, 10, 501), np.zeros(501), np.zeros(501)])
    r = resample_poses(poses, 0.5)
    assert r[0, 0] == 0 and r[-1, 0] == 10 and len(r) == 21


def test_config_file_matches_the_defaults():
    from parknss.web.config import WebConfig

    assert load_web_config() == WebConfig()


def test_the_web_command_serves_the_page_and_the_api():
    import socket
    import subprocess
    import sys
    import time

    import httpx

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cmd = [sys.executable, "-m", "parknss.cli", "web", "--no-open", "--port", str(port)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 120.0
        while True:
            assert proc.poll() is None, proc.stderr.read()
            try:
                page = httpx.get(f"{base}/", timeout=5.0)
                break
            except httpx.TransportError:
                assert time.monotonic() < deadline, "parknss web did not start"
                time.sleep(0.25)
        assert page.status_code == 200 and "closed-loop parking simulator" in page.text
        assert httpx.get(f"{base}/static/app.js", timeout=5.0).status_code == 200
        cells = httpx.get(f"{base}/api/cells", timeout=30.0).json()["cells"]
        assert len(cells) == 36
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    assert f"http://127.0.0.1:{port}/" in proc.stderr.read()


def test_benchmark_files_are_imported_as_scenes_and_plan(client):
    """Issue 17: the page opens TPCAP cases and CommonRoad scenarios via /api/import."""
    from helpers.paths import TESTS

    xml = (TESTS / "sim" / "fixtures" / "commonroad_parking.xml").read_text()
    r = client.post("/api/import", json={"filename": "parking.xml", "text": xml})
    assert r.status_code == 200, r.text
    doc = r.json()
    assert doc["scene"]["format"] == "parknss.scene" and len(doc["scene"]["obstacles"]) == 3
    assert doc["scene"]["meta"]["source"] == "parking.xml"
    case = "0,0,0,10,0,0,1,6,3,3,7,3,7,4,4,4,4,6,3,6"  # one L-shaped obstacle
    r = client.post("/api/import", json={"filename": "Case99.csv", "text": case})
    assert r.status_code == 200 and "split into 2 convex parts" in r.json()["notes"][0]
    bad = client.post("/api/import", json={"filename": "Case99.csv", "text": "1,2"})
    assert bad.status_code == 422 and "Case99.csv" in bad.json()["error"]
    other = client.post("/api/import", json={"filename": "scene.json", "text": "{}"})
    assert other.status_code == 422


def test_a_huge_scene_is_refused_at_once(client):
    """Issue 17: 100,000 obstacles posted to the API answered only after 99 s."""
    import time

    box = [[0, 0], [0.1, 0], [0.1, 0.1], [0, 0.1]]
    t0 = time.perf_counter()
    r = client.post("/api/plan", json={"scene": _scene(obstacles=[{"vertices": box}] * 100_000)})
    assert r.status_code == 422 and "max_obstacles" in r.json()["error"]
    assert time.perf_counter() - t0 < 30.0  # JSON parsing only; was 99 s of planning
