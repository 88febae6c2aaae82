"""Fixtures shared across the test folders: the actuator/chain tests' tiny campaign, NSS and
config, the experiment tests' tiny campaign and studies config, the real logs beside the
checkout, and the headless browser; the checkout's result store is off for every test.
The builders behind them are the ``helpers`` package (tests/helpers/), which test modules
also import directly when they need other sizes or seeds; no test module imports
another."""

from __future__ import annotations

import importlib.util
import os
import shutil
from pathlib import Path

import pytest

from helpers.actuators import tiny_campaign, tiny_config, tiny_nss
from helpers.experiments import tiny_setup
from helpers.paths import REALDATA

# no test writes into the checkout's result store (results/): studies and reproduce runs
# default to it; the store tests name their own folder with --store
os.environ["PARKNSS_RESULTS"] = "off"

# --- the real logs (../shared/realdata, read in place) -------------------------------------

REALDATA_MISSING = f"real logs not found at {REALDATA} (../shared/realdata)"


def pytest_collection_modifyitems(config, items):
    """Tests marked ``realdata`` are skipped, with the reason, when the logs are not there."""
    if REALDATA.is_dir():
        return
    skip = pytest.mark.skip(reason=REALDATA_MISSING)
    for item in items:
        if item.get_closest_marker("realdata"):
            item.add_marker(skip)


@pytest.fixture(scope="session")
def realdata() -> Path:
    """The folder of real cars' public logs (skips the test when it is missing)."""
    if not REALDATA.is_dir():
        pytest.skip(REALDATA_MISSING)
    return REALDATA


# --- the actuator and chain tests: seconds, not minutes -------------------------------------


@pytest.fixture(scope="module")
def actuator_campaign():
    """8 short trials (4 classes x 2 repetitions) whose actuals are first-order lags of
    piecewise commands (helpers.actuators.tiny_campaign); one per test module."""
    return tiny_campaign()


@pytest.fixture(scope="module")
def actuator_nss(actuator_campaign):
    """(model, NSSConfig): a small random NSS normalised on ``actuator_campaign``, seed 0."""
    return tiny_nss(actuator_campaign)


@pytest.fixture
def actuator_config():
    """The tiny ActuatorConfig (few iterations, short windows, two architectures)."""
    return tiny_config()


# --- the experiment tests -------------------------------------------------------------------


@pytest.fixture
def tiny_study(tmp_path) -> tuple[Path, Path]:
    """(campaign folder, experiments YAML) under tmp_path: 16 trials, tiny studies config."""
    return tiny_setup(tmp_path)


# --- the headless browser (system Chromium through playwright) ------------------------------

BROWSER_REQUIRED = os.environ.get("PARKNSS_BROWSER_TESTS") == "1"
CHROMIUM = os.environ.get("PARKNSS_CHROMIUM", "/usr/bin/chromium")
LAUNCH_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking"]


def _browser_missing() -> str | None:
    """Why the browser tests cannot run here (None when they can)."""
    if importlib.util.find_spec("playwright") is None:
        return "python package playwright is not installed (pip install playwright)"
    if not (Path(CHROMIUM).is_file() or shutil.which(CHROMIUM)):
        return f"no chromium at {CHROMIUM} (apt-get install -y chromium)"
    return None


@pytest.fixture(scope="session")
def browser_launch() -> dict:
    """playwright ``chromium.launch`` options for the system browser. Skips when playwright
    or chromium is missing, unless PARKNSS_BROWSER_TESTS=1 (CI), where that fails."""
    reason = _browser_missing()
    if reason:
        if BROWSER_REQUIRED:
            pytest.fail(f"PARKNSS_BROWSER_TESTS=1 but {reason}")
        pytest.skip(reason)
    return {"executable_path": CHROMIUM, "args": LAUNCH_ARGS}


@pytest.fixture(scope="module")
def browser(browser_launch):
    """A headless Chromium, one per test module."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(**browser_launch)
        yield b
        b.close()
