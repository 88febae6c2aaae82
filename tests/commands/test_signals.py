"""SIGINT exits 130 and SIGTERM 143, each with one line saying what was kept and how to
resume, for ``train``, ``grid``, ``campaign import`` and ``reproduce``; a grid's pool
workers stop with it. Each case runs the real ``parknss`` in a subprocess, waits until
the job has started (a state file, a worker, an open log, a cached fit), signals it and
reads its exit status and last stderr line."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
import yaml

from helpers.experiments import tiny_setup
from helpers.synth import make_trial
from parknss.data.io import write_trial_csv

PARKNSS = shutil.which("parknss") or str(Path(sys.executable).with_name("parknss"))
TINY_SET = ["--set", "model.state_units=4", "--set", "model.state_layers=1",
            "--set", "model.output_units=4", "--set", "model.output_layers=1"]
SIGNALS = [(signal.SIGINT, 130, "interrupted"), (signal.SIGTERM, 143, "terminated")]


def _env(tmp_path: Path) -> dict:
    src = Path(__file__).resolve().parents[2] / "src"
    return {**os.environ, "PYTHONPATH": f"{src}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
            "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "MPLBACKEND": "Agg",
            "HOME": os.environ.get("HOME", str(tmp_path))}


def _children(pid: int) -> list[int]:
    kids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            kids.append(int(stat.parent.name))
    return kids


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def _interrupt(argv: list[str], started: Callable[[int], bool], sig: int, tmp_path: Path,
               *, timeout: float = 90.0) -> tuple[int, list[str], int]:
    """Run ``parknss argv`` in ``tmp_path``, send ``sig`` once ``started(pid)`` holds;
    (exit status, stderr lines, pid)."""
    err = tmp_path / "stderr.txt"
    with err.open("wb") as fh:
        proc = subprocess.Popen([PARKNSS, *argv], cwd=tmp_path, env=_env(tmp_path),
                                stdout=subprocess.DEVNULL, stderr=fh)
        deadline = time.monotonic() + timeout
        try:
            while not started(proc.pid):
                assert proc.poll() is None, err.read_text()[-2000:]
                assert time.monotonic() < deadline, "the job never started"
                time.sleep(0.05)
            proc.send_signal(sig)
            rc = proc.wait(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    text = err.read_text().replace("\r", "\n")
    return rc, [ln for ln in text.splitlines() if ln.strip()], proc.pid


def _one_line(lines: list[str], word: str) -> str:
    ours = [ln for ln in lines if ln.startswith("parknss: ")]
    assert ours == [lines[-1]], lines[-5:]
    assert ours[0].startswith(f"parknss: {word}: ")
    assert not any("Traceback" in ln for ln in lines)
    return ours[0]


@pytest.mark.parametrize(("sig", "code", "word"), SIGNALS)
def test_train(sig, code, word, tmp_path):
    out = tmp_path / "t"
    argv = ["train", "--out", str(out), *TINY_SET, "--set", "train.epochs=100000",
            "--set", "train.checkpoint_every=1", "--set", "train.val_every=1"]
    state = out / "state" / "train_state.json"
    rc, lines, _ = _interrupt(argv, lambda _pid: state.is_file(), sig, tmp_path)
    assert rc == code
    line = _one_line(lines, word)
    assert f"training state kept in {out / 'state'}" in line
    assert f"resume with `parknss train --out {out} --resume`" in line
    assert not (out / "model").exists()


@pytest.mark.parametrize(("sig", "code", "word"), SIGNALS)
def test_data_parallel_train_stops_its_worker(sig, code, word, tmp_path):
    """``train --processes 2``: the same exit and line, the state kept, and the worker
    process (which ignores SIGINT: the fit decides) gone with the fit."""
    out = tmp_path / "t"
    argv = ["train", "--out", str(out), *TINY_SET, "--set", "train.epochs=100000",
            "--set", "train.checkpoint_every=1", "--processes", "2"]
    state = out / "state" / "train_state.json"
    workers: list[int] = []

    def started(pid: int) -> bool:
        workers[:] = [k for k in _children(pid) if "multiprocessing" in _cmdline(k)
                      and "resource_tracker" not in _cmdline(k)]
        return state.is_file() and bool(workers)

    rc, lines, _ = _interrupt(argv, started, sig, tmp_path)
    assert rc == code, "\n".join(lines[-30:])
    line = _one_line(lines, word)
    assert f"resume with `parknss train --out {out} --resume`" in line
    deadline = time.monotonic() + 10
    while any(_alive(w) for w in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not [w for w in workers if _alive(w)], "the worker outlived the fit"


@pytest.mark.parametrize(("sig", "code", "word"), SIGNALS)
def test_grid_stops_its_workers(sig, code, word, tmp_path):
    out = tmp_path / "g"
    argv = ["grid", "--grid", "36", "--cells", "0-11", "--plants", "kinematic",
            "--workers", "2", "--out", str(out)]
    workers: list[int] = []

    def started(pid: int) -> bool:
        kids = [k for k in _children(pid) if "loky" in _cmdline(k) or "joblib" in _cmdline(k)]
        workers[:] = kids
        return len(kids) >= 2

    rc, lines, _ = _interrupt(argv, started, sig, tmp_path)
    assert rc == code, "\n".join(lines[-30:])
    line = _one_line(lines, word)
    assert str(out) in line and "run the same command again" in line
    deadline = time.monotonic() + 10
    while any(_alive(w) for w in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not [w for w in workers if _alive(w)], "pool workers outlived the command"
    assert not (out / "grid_36.json").exists()


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


def _opened(path: Path) -> Callable[[int], bool]:
    """Whether process ``pid`` has ``path`` open."""
    target = str(path)

    def check(pid: int) -> bool:
        try:
            fds = list(Path(f"/proc/{pid}/fd").iterdir())
        except OSError:
            return False
        for fd in fds:
            try:
                if os.readlink(fd) == target:
                    return True
            except OSError:
                continue
        return False

    return check


@pytest.mark.parametrize(("sig", "code", "word"), SIGNALS)
def test_campaign_import(sig, code, word, tmp_path):
    src = tmp_path / "logs"
    src.mkdir()
    log = src / "park_in_left_r1.csv"
    write_trial_csv(make_trial(400_000), log)  # a long log: seconds to read
    out = tmp_path / "camp"
    (out).mkdir()
    (out / "keep.txt").write_text("earlier")
    argv = ["campaign", "import", str(src), "--out", str(out), "--overwrite"]
    rc, lines, _ = _interrupt(argv, _opened(log), sig, tmp_path)
    assert rc == code
    line = _one_line(lines, word)
    assert "run the same command again" in line
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".camp")] == []
    assert (out / "keep.txt").read_text() == "earlier"  # the earlier folder untouched


@pytest.mark.parametrize(("sig", "code", "word"), SIGNALS)
def test_reproduce_keeps_its_cache(sig, code, word, tmp_path):
    data, cfg = tiny_setup(tmp_path)
    doc = yaml.safe_load(Path(cfg).read_text())
    doc["quick"]["seeds"] = list(range(200))  # many tiny fits: time to interrupt
    Path(cfg).write_text(yaml.safe_dump(doc))
    out = tmp_path / "rep"
    argv = ["reproduce", "seed_noise", "--quick", "--workers", "1", "--store", "off",
            "--data", str(data), "--config", str(cfg), "--out", str(out)]
    cache = out / "cache"
    rc, lines, _ = _interrupt(argv, lambda _pid: len(list(cache.glob("*.json"))) >= 2,
                              sig, tmp_path)
    assert rc == code
    line = _one_line(lines, word)
    assert "jobs (fits, cells) finished and kept in the run cache" in line
    assert f"{out / 'report.html'}" in line and "run the same command again to resume" in line
    assert len(list(cache.glob("*.json"))) >= 2
    assert not list(cache.glob(".*tmp*"))
