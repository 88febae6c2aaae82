"""The simulator page in a real headless Chromium (Python playwright driving the system
browser): load the page, run a kinematic cell, see the outcome, drawn canvases, no console
errors; edit the start pose by dragging; see the API's error for an unavailable plant.

The ``browser`` fixture (tests/conftest.py) skips when playwright or chromium is missing,
unless PARKNSS_BROWSER_TESTS=1 (CI), where a missing prerequisite fails. Install:
``apt-get install -y chromium`` and ``pip install playwright`` (never ``playwright
install``: the system browser is used).
"""

from __future__ import annotations

import socket
import threading
import time

import pytest

from parknss.web.app import create_app
from parknss.web.config import load_web_config

CELL = "26"
TIMEOUT_MS = 240_000  # generous: the machine may be loaded


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """The app under uvicorn on a free 127.0.0.1 port, in a thread; the chain made missing."""
    import uvicorn

    cfg_file = tmp_path_factory.mktemp("web") / "closed_loop.yaml"
    cfg_file.write_text(f"chain_path: {cfg_file.parent / 'no_chain_here'}\n")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cfg = load_web_config(
        port=port,
        closed_loop_config=str(cfg_file),
        plan_budget_s=300.0,
        simulate_budget_s=600.0,
    )
    srv = uvicorn.Server(
        uvicorn.Config(create_app(cfg), host="127.0.0.1", port=port, log_level="warning")
    )
    thread = threading.Thread(target=srv.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 30.0
    while not srv.started:
        if time.monotonic() > deadline or not thread.is_alive():
            pytest.fail("the simulator server did not start")
        time.sleep(0.05)
    yield f"http://127.0.0.1:{port}/"
    srv.should_exit = True
    thread.join(10.0)


@pytest.fixture
def page(browser, server):
    ctx = browser.new_context(viewport={"width": 1440, "height": 1000})
    pg = ctx.new_page()
    pg.set_default_timeout(TIMEOUT_MS)
    pg.console_errors = []
    pg.on("console", lambda m: m.type == "error" and pg.console_errors.append(m.text))
    pg.on("pageerror", lambda e: pg.console_errors.append(f"page error: {e}"))
    pg.goto(f"{server}?grid=36&cell={CELL}")
    pg.wait_for_selector(f"#cell option[value='{CELL}']", state="attached")
    yield pg
    ctx.close()


def _settled(page) -> None:
    """Wait until the selected cell is planned and nothing is running."""
    page.wait_for_function(
        "document.querySelector('#busy').hidden && !state.planning && state.plan !== null && "
        "state.plan.name === state.cells[state.index].name"
    )


def _pixels_like(page, selector: str, hex_colour: str, tol: int = 40) -> int:
    """Pixels of a canvas within ``tol`` (per channel) of a colour, and the canvas size."""
    return page.evaluate(
        """([sel, hex, tol]) => {
            const c = document.querySelector(sel);
            const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
            const rgb = [1, 3, 5].map((i) => parseInt(hex.slice(i, i + 2), 16));
            let n = 0;
            for (let i = 0; i < d.length; i += 4) {
                if (d[i + 3] > 0 && Math.abs(d[i] - rgb[0]) <= tol &&
                    Math.abs(d[i + 1] - rgb[1]) <= tol && Math.abs(d[i + 2] - rgb[2]) <= tol) n++;
            }
            return n;
        }""",
        [selector, hex_colour, tol],
    )


def _distinct_colours(page, selector: str) -> int:
    return page.evaluate(
        """(sel) => {
            const c = document.querySelector(sel);
            const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
            const seen = new Set();
            for (let i = 0; i < d.length; i += 28) {
                seen.add((d[i] << 16) | (d[i + 1] << 8) | d[i + 2]);
            }
            return seen.size;
        }""",
        selector,
    )


def test_a_kinematic_cell_runs_and_plays_back(page, tmp_path):
    _settled(page)
    assert page.input_value("#cell") == CELL
    assert "planned" in page.inner_text("#plan-info")
    for kind in ("chain", "reference"):
        page.uncheck(f"#plant-{kind}")
    page.check("#plant-kinematic")
    page.click("#run-btn")
    page.wait_for_function(
        "document.querySelectorAll('#outcome tbody tr').length === 1 && "
        "document.querySelector('#busy').hidden"
    )
    row = page.inner_text("#outcome tbody tr")
    assert "kinematic" in row and "completed" in row
    page.wait_for_timeout(1500)  # let the playback advance
    t_now = page.evaluate("state.t")
    assert 0.0 < t_now < page.evaluate("state.tmax")
    colours = page.evaluate("state.health.plants").copy()
    cyan = next(p["colour"] for p in colours if p["kind"] == "kinematic")
    planned = page.evaluate("state.health.planned_colour")
    assert _pixels_like(page, "#view", cyan) > 500  # the driven path and the moving car
    assert _pixels_like(page, "#view", planned) > 200  # the planned path
    assert _distinct_colours(page, "#view") > 20
    for channel in ("vx", "yaw_rate", "ax", "ay", "steer", "gear"):
        assert _pixels_like(page, f".plot[data-channel='{channel}']", cyan) > 50, channel
    page.screenshot(path=str(tmp_path / "simulator.png"), full_page=True)
    assert page.is_hidden("#error")
    assert page.console_errors == []


def test_dragging_the_start_replans_from_there(page):
    _settled(page)
    before = page.evaluate("state.start.slice()")
    box = page.locator("#view").bounding_box()
    x, y = page.evaluate("[sx(state.start[0] + 1.5), sy(state.start[1])]")
    page.mouse.move(box["x"] + x, box["y"] + y)
    page.mouse.down()
    page.mouse.move(box["x"] + x + 25, box["y"] + y - 10, steps=5)
    page.mouse.up()
    page.wait_for_timeout(200)
    _settled(page)
    after = page.evaluate("state.start.slice()")
    assert after[0] > before[0] + 0.3 and after[1] > before[1] + 0.1
    assert "(edited)" in page.inner_text("#start-readout")
    first = page.evaluate("state.plan.path[0].poses[0]")
    assert first == pytest.approx(after, abs=1e-3)
    assert page.console_errors == []


def test_an_unavailable_plant_shows_the_api_error(page):
    _settled(page)
    page.uncheck("#plant-kinematic")
    page.check("#plant-chain")
    page.click("#run-btn")
    page.wait_for_selector("#error:not([hidden])")
    assert "chain" in page.inner_text("#error")
    assert "chain" in page.inner_text("#outcome tbody")
    assert not [e for e in page.console_errors if "page error" in e]


def test_a_scene_file_and_the_robustness_grid_are_planned(page, tmp_path):
    from parknss.sim.scenarios import grid_scene

    _settled(page)
    scene_file = tmp_path / "my_scene.json"
    grid_scene(int(CELL)).save(scene_file)
    page.set_input_files("#scene-file", str(scene_file))
    page.wait_for_function(
        "state.custom && document.querySelector('#busy').hidden && !state.planning && "
        "state.plan !== null"
    )
    assert page.input_value("#cell") == "custom"
    assert "planned" in page.inner_text("#plan-info")
    page.select_option("#cell", CELL)  # back to the grid cell
    page.select_option("#grid", "252")  # the same cell, first perturbation (skew +5°)
    page.wait_for_function("state.cells.length === 252")
    # the page may plan the list's first cell while it repopulates the selector; wait for
    # the plan of the kept cell (a page that never plans it times out and fails)
    page.wait_for_function(
        "state.plan !== null && state.plan.name === 'angled-left-t1-open-skew_pos'"
    )
    _settled(page)
    assert page.evaluate("state.plan.name") == "angled-left-t1-open-skew_pos"
    assert page.url.endswith(f"?grid=252&cell={CELL}")
    assert page.console_errors == []
