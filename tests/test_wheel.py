"""A wheel that works (issue 13): ``pip install <checkout>`` (not editable) into a fresh
venv outside the checkout, then ``parknss demo`` from another directory prints the same
summary as the editable install and ``parknss web`` serves the page and the API.

Slow (a venv with the pinned dependencies, two demos): skipped unless
``PARKNSS_WHEEL_TEST=1``. ``PARKNSS_WHEEL_VENV=DIR`` reuses a venv that already holds
``requirements.lock`` (the wheel itself is always reinstalled).
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

import parknss.config as pc

REPO = pc.REPO_ROOT
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(
        os.environ.get("PARKNSS_WHEEL_TEST") != "1", reason="set PARKNSS_WHEEL_TEST=1"
    ),
]
IGNORE = shutil.ignore_patterns(
    ".git", ".venv", "runs", "build", "dist", "*.egg-info", ".cache", "__pycache__",
    ".pytest_cache", ".ruff_cache",
)  # fmt: skip


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env.update(OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", MPLBACKEND="Agg")
    return env


def _run(args: list, cwd: Path, timeout: float = 900) -> subprocess.CompletedProcess:
    res = subprocess.run(
        [str(a) for a in args], cwd=cwd, env=_env(), capture_output=True, text=True,
        timeout=timeout,
    )  # fmt: skip
    assert res.returncode == 0, f"{args}: {res.stderr[-3000:]}"
    return res


@pytest.fixture(scope="module")
def wheel_venv(tmp_path_factory) -> Path:
    if not (REPO / "pyproject.toml").is_file():
        pytest.skip("needs a checkout")
    work = tmp_path_factory.mktemp("wheel")
    venv = Path(os.environ.get("PARKNSS_WHEEL_VENV") or work / "venv")
    if not (venv / "bin" / "python").is_file():
        _run([sys.executable, "-m", "venv", venv], work)
        _run([venv / "bin" / "python", "-m", "pip", "install", "-q", "-r",
              REPO / "requirements.lock"], work)  # fmt: skip
    # a copy, so that building the wheel leaves nothing in the checkout
    src = work / "src_copy"
    shutil.copytree(REPO, src, ignore=IGNORE, symlinks=True)
    _run([venv / "bin" / "python", "-m", "pip", "install", "-q", "--no-deps",
          "--force-reinstall", src], work)  # fmt: skip
    shutil.rmtree(src)
    return venv


def test_wheel_is_not_the_checkout(wheel_venv, tmp_path):
    code = (
        "import json, parknss.config as c; print(json.dumps({'file': c.__file__, "
        "'configs': c.CONFIG_DIR.is_dir(), 'nss': (c.SHIPPED_NSS / 'model.json').is_file(), "
        "'chain': (c.SHIPPED_CHAIN / 'chain.json').is_file(), "
        "'plant': (c.SHIPPED_PLANT / 'chain.json').is_file(), "
        "'campaign': (c.BUNDLED_CAMPAIGN / 'campaign.json').is_file()}))"
    )
    doc = json.loads(_run([wheel_venv / "bin" / "python", "-c", code], tmp_path).stdout)
    assert "site-packages" in doc["file"] and str(REPO) not in doc["file"]
    assert doc["configs"] and doc["nss"] and doc["chain"] and doc["plant"] and doc["campaign"]


def test_wheel_demo_prints_what_the_editable_install_prints(wheel_venv, tmp_path):
    editable = Path(sys.executable).parent / "parknss"
    here = _run([editable, "demo", "--out", tmp_path / "editable"], tmp_path).stdout
    there = _run([wheel_venv / "bin" / "parknss", "demo", "--out", tmp_path / "wheel"],
                 tmp_path).stdout  # fmt: skip
    assert "closed loop" in here and here == there


def test_wheel_web_serves_the_page(wheel_venv, tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = subprocess.Popen(
        [str(wheel_venv / "bin" / "parknss"), "web", "--host", "127.0.0.1", "--port",
         str(port), "--no-open"],
        cwd=tmp_path, env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 120
        while True:
            try:
                with urllib.request.urlopen(f"{base}/api/health", timeout=5) as r:
                    health = json.loads(r.read())
                break
            except OSError:
                assert proc.poll() is None, proc.stderr.read()
                assert time.monotonic() < deadline, "web did not come up"
                time.sleep(0.5)
        with urllib.request.urlopen(f"{base}/", timeout=10) as r:
            page = r.read().decode()
        with urllib.request.urlopen(f"{base}/api/cells", timeout=30) as r:
            cells = json.loads(r.read())
        with urllib.request.urlopen(f"{base}/static/app.js", timeout=10) as r:
            assert r.status == 200
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    assert health["status"] == "ok" and "<html" in page.lower()
    # the shipped chain and reference vehicle are found inside the installed package
    assert all(p["available"] for p in health["plants"]), health["plants"]
    assert cells
