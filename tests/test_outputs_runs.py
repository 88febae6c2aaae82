"""Run folders (issue 13, item 9): every command that writes a run folder (cv, evaluate,
study, reproduce, demo, plan, simulate, grid, tune, rate, actuators study) refuses an --out
holding another artefact or another run unless --overwrite, resumes the same run (its
cache reused), and a run that fails midway leaves the earlier run's products whole.
First :func:`parknss.outputs.run_folder` itself, then one test per command."""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import yaml

from helpers.actuators import tiny_config
from helpers.experiments import tiny_setup
from helpers.synth import make_campaign
from parknss.cli import main
from parknss.config import SHIPPED_CHAIN, SHIPPED_NSS
from parknss.data.io import write_campaign
from parknss.errors import ParknssWarning
from parknss.nss.checkpoint import save_model
from parknss.outputs import (
    RUN_MANIFEST,
    OutputExistsError,
    atomic_file,
    describe_contents,
    read_manifest,
    run_folder,
)

BOOM = "disk full midway"


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def _leftovers(parent: Path) -> list[str]:
    return sorted(p.name for p in parent.iterdir() if p.name.startswith("."))


def _held(folder: Path, marker: str) -> None:
    """An earlier artefact at ``folder``: a campaign, model or chain (``marker``), a run of
    another command, or a run folder written before manifests existed ("legacy")."""
    folder.mkdir(parents=True)
    if marker == "other-command":
        with run_folder(folder, command="parknss other", args={}, overwrite=False) as run:
            run.write_text("other.txt", "x")
        return
    (folder / ("summary.json" if marker == "legacy" else marker)).write_text('{"n": 16}')
    (folder / "t0.parquet").write_text("0")


def _dead_pid() -> int:
    return int(subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                              capture_output=True, text=True).stdout)


# -- parknss.outputs.run_folder ------------------------------------------------------------------


def test_a_new_run_writes_its_manifest(tmp_path):
    out = tmp_path / "runs" / "cv"
    with run_folder(out, command="parknss cv", args={"data": tmp_path, "epochs": 3},
                    overwrite=False) as run:
        assert run.state == "new" and (out / RUN_MANIFEST).is_file()
        assert read_manifest(out)["finished_utc"] is None  # running
        run.write_json("cv.json", {"ok": True})
    doc = read_manifest(out)
    assert doc["command"] == "parknss cv" and len(doc["digest"]) == 16
    assert doc["args"] == {"data": str(tmp_path.resolve()), "epochs": 3}  # paths resolved
    assert set(doc) >= {"parknss", "git_revision", "started_utc", "finished_utc"}
    assert doc["finished_utc"] and describe_contents(out) == "a run of parknss cv (run.json)"
    assert _leftovers(out) == [] and _leftovers(out.parent) == []


def test_the_same_arguments_resume_with_the_cache(tmp_path):
    out = tmp_path / "run"
    args = {"quick": True, "data": Path("campaign")}
    with run_folder(out, command="parknss study limiter", args=args, overwrite=False) as run:
        (out / "cache").mkdir()
        (out / "cache" / "job.json").write_text("{}")
    started = read_manifest(out)["started_utc"]
    with run_folder(out, command="parknss study limiter", args=dict(args),
                    overwrite=False) as run:
        assert run.state == "resumed" and (out / "cache" / "job.json").is_file()
    doc = read_manifest(out)
    assert doc["started_utc"] == started and doc["resumed_utc"]


@pytest.mark.parametrize("marker,what", [
    ("campaign.json", "a campaign (campaign.json)"),
    ("model.json", "a model (model.json)"),
    ("chain.json", "a chain (chain.json)"),
    ("other-command", "a run of parknss other (run.json)"),
    ("legacy", "a run (2 entries)"),
])  # fmt: skip
def test_a_folder_holding_something_else_is_refused_untouched(tmp_path, marker, what):
    out = tmp_path / "x"
    _held(out, marker)
    before = _snapshot(out)
    ran = False
    with (pytest.raises(OutputExistsError) as ei,
          run_folder(out, command="parknss cv", args={}, overwrite=False)):
        ran = True
    assert str(ei.value) == (f"{out}: holds {what} already; pass --overwrite to replace it "
                             "with this run of parknss cv")
    assert not ran and _snapshot(out) == before and _leftovers(tmp_path) == []


def test_other_arguments_are_refused_naming_them(tmp_path):
    out = tmp_path / "x"
    with run_folder(out, command="parknss cv", args={"epochs": 3, "seed": 1}, overwrite=False):
        pass
    before = _snapshot(out)
    with (pytest.raises(OutputExistsError) as ei,
          run_folder(out, command="parknss cv", args={"epochs": 4, "seed": 1}, overwrite=False)):
        pass
    assert str(ei.value) == (f"{out}: holds a run of parknss cv with other arguments "
                             "(epochs) already; pass --overwrite to replace it")
    assert _snapshot(out) == before


def test_overwrite_replaces_and_a_failing_run_puts_the_earlier_content_back(tmp_path):
    out = tmp_path / "x"
    _held(out, "campaign.json")
    before = _snapshot(out)
    with (pytest.raises(RuntimeError, match=BOOM),
          run_folder(out, command="parknss grid", args={}, overwrite=True) as run):
        assert run.state == "replacing" and not (out / "campaign.json").exists()
        run.write_text("grid_36_cells.csv", "half")
        raise RuntimeError(BOOM)
    assert _snapshot(out) == before and _leftovers(tmp_path) == []
    # the failed run's own work is kept beside it, never deleted (see the test below)
    (kept,) = tmp_path.glob("x.unfinished-*")
    assert (kept / "grid_36_cells.csv").read_text() == "half"
    shutil.rmtree(kept)
    with run_folder(out, command="parknss grid", args={}, overwrite=True) as run:
        run.write_text("grid_36.json", "{}")
    assert sorted(_snapshot(out)) == ["grid_36.json", RUN_MANIFEST]
    assert _leftovers(tmp_path) == []


def test_a_new_run_that_fails_before_writing_leaves_no_folder(tmp_path):
    out = tmp_path / "runs" / "deep" / "x"
    with pytest.raises(RuntimeError), run_folder(out, command="c", args={}, overwrite=False):
        raise RuntimeError(BOOM)
    assert list(tmp_path.iterdir()) == []  # the folders it created are gone
    kept = tmp_path / "mine"
    kept.mkdir()
    with pytest.raises(RuntimeError), run_folder(kept, command="c", args={}, overwrite=False):
        raise RuntimeError(BOOM)
    assert kept.is_dir() and list(kept.iterdir()) == []  # the user's empty folder stays
    # a new run that got as far as its cache keeps it, to resume
    with pytest.raises(RuntimeError), run_folder(out, command="c", args={}, overwrite=False):
        (out / "cache").mkdir()
        raise RuntimeError(BOOM)
    with run_folder(out, command="c", args={}, overwrite=False) as run:
        assert run.state == "resumed"


@pytest.mark.parametrize("finished", [False, True])
def test_a_killed_overwrite_is_rolled_back_by_the_next_look(tmp_path, finished):
    out = tmp_path / "x"
    _held(out, "model.json")
    before = _snapshot(out)
    code = textwrap.dedent(f"""
        import json, os, signal
        import parknss.outputs as o
        with o.run_folder({str(out)!r}, command="parknss tune", args={{}}, overwrite=True) as r:
            r.write_text("tune.json", "{{}}")
            if {finished}:  # killed after marking the run finished, before tidying
                r.manifest["finished_utc"] = "now"
                o.write_text_atomic(r.path / o.RUN_MANIFEST, json.dumps(r.manifest))
            os.kill(os.getpid(), signal.SIGKILL)
    """)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True)
    assert res.returncode == -signal.SIGKILL
    assert len(_leftovers(tmp_path)) == 1  # the earlier model, renamed away
    # the next claim puts things right, then refuses
    with (pytest.raises(OutputExistsError),
          run_folder(out, command="parknss cv", args={}, overwrite=False)):
        pass
    if finished:  # the killed run had finished: it stays, the earlier model goes
        assert read_manifest(out)["command"] == "parknss tune"
        assert list(tmp_path.glob("x.unfinished-*")) == []
    else:
        assert _snapshot(out) == before
        (kept,) = tmp_path.glob("x.unfinished-*")  # the killed run's work, kept
        assert (kept / "tune.json").read_text() == "{}"
    assert _leftovers(tmp_path) == []


def test_an_unfinished_overwrite_keeps_its_training_state_and_resumes_there(tmp_path):
    """An --overwrite run that fails after hours of fitting must not lose its resumable
    state when the earlier content is put back: the state moves to a visible sibling,
    a one-line warning names it, and the same command with --out there resumes it."""
    out = tmp_path / "floor"
    args = {"config": "f2.yaml"}
    with run_folder(out, command="parknss study seed-noise", args=args,
                    overwrite=False) as run:
        run.write_text("seed_noise.json", "{}")
    before = _snapshot(out)
    with (pytest.warns(ParknssWarning, match=r"this run's work is kept in .*floor\.unfinished-"),
          pytest.raises(ValueError, match="schema"),
          run_folder(out, command="parknss study seed-noise", args=args,
                     overwrite=True) as run):
        run.write_text("state/fit/train_state.json", '{"epoch": 3000}')
        raise ValueError("schema changed under the running fit")
    assert _snapshot(out) == before and _leftovers(tmp_path) == []
    (kept,) = tmp_path.glob("floor.unfinished-*")
    assert json.loads((kept / "state/fit/train_state.json").read_text())["epoch"] == 3000
    with run_folder(kept, command="parknss study seed-noise", args=args,
                    overwrite=False) as run:
        assert run.state == "resumed"
    # a replacing run that wrote nothing but its manifest leaves nothing beside
    with (pytest.raises(ValueError),
          run_folder(out, command="parknss other", args={}, overwrite=True)):
        raise ValueError("early")
    assert _snapshot(out) == before
    assert [p.name for p in tmp_path.glob("floor.unfinished-*")] == [kept.name]


def test_atomic_files_keep_the_earlier_file_and_stale_ones_are_tidied(tmp_path):
    target = tmp_path / "run" / "table.csv"
    target.parent.mkdir()
    target.write_text("earlier")
    with pytest.raises(RuntimeError), atomic_file(target) as tmp:
        assert tmp.suffix == ".csv" and tmp.parent == target.parent
        tmp.write_text("half")
        raise RuntimeError(BOOM)
    assert target.read_text() == "earlier" and _leftovers(target.parent) == []
    # a killed writer's temporary file in a run folder goes at the next claim of the folder
    run = tmp_path / "run2"
    with run_folder(run, command="c", args={}, overwrite=False):
        pass
    stale = run / "figs" / f".fig.tmp-{_dead_pid()}.png"
    stale.parent.mkdir()
    stale.write_text("torn")
    with run_folder(run, command="c", args={}, overwrite=False) as claimed:
        assert claimed.state == "resumed" and not stale.exists()


# -- the commands ----------------------------------------------------------------------------------


def _one_error(capsys) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("parknss: error: ")]
    assert len(lines) == 1, err
    return lines[0]


def _break(monkeypatch, target: str) -> None:
    """Make ``target`` ("module.attr" or "module.Class.attr") raise RuntimeError(BOOM)."""

    def broken(*args, **kwargs):
        raise RuntimeError(BOOM)

    monkeypatch.setattr(target, broken)


def _check_command(
    capsys, monkeypatch, out: Path, argv: list[str], other: list[str], *, held: str,
    command: str, fail: str = "parknss.outputs.RunFolder.write_json", cache_job: str = "",
) -> dict:
    """The four cases of a command whose run folder is ``out`` (``argv`` writes it; ``other``
    is the same command with other arguments); returns the finished run's manifest.

    1. ``out`` holds ``held`` (see :func:`_held`): refused in one line naming it and
       --overwrite, the folder untouched;
    2. --overwrite replaces it with the run;
    3. the same arguments again resume the run (with ``cache_job`` broken when the command
       has a result cache: every job comes from the cache);
    4. other arguments are refused in one line; with --overwrite and ``fail`` raising
       midway, the earlier run's products are whole, byte for byte.
    """
    _held(out, held)
    before = _snapshot(out)
    assert main(argv) == 2
    line = _one_error(capsys)
    assert line.startswith(f"parknss: error: {out}: holds a") and "--overwrite" in line
    assert _snapshot(out) == before

    assert main([*argv, "--overwrite"]) == 0
    capsys.readouterr()
    manifest = read_manifest(out)
    assert manifest["command"] == command and manifest["finished_utc"]
    marker = "other.txt" if held == "other-command" else "t0.parquet"
    assert not (out / marker).exists() and _leftovers(out.parent) == []

    with monkeypatch.context() as mp:
        if cache_job:
            _break(mp, cache_job)
        assert main(argv) == 0
    capsys.readouterr()
    again = read_manifest(out)
    assert again["started_utc"] == manifest["started_utc"] and again["resumed_utc"]
    earlier = _snapshot(out)

    assert main(other) == 2
    assert "with other arguments" in _one_error(capsys)
    with monkeypatch.context() as mp, pytest.raises(RuntimeError, match=BOOM):
        _break(mp, fail)
        main([*other, "--overwrite"])
    capsys.readouterr()
    assert _snapshot(out) == earlier and _leftovers(out.parent) == []
    return again


FIT = "parknss.nss.train.fit"
"""What a study's resumed run must not call: the NSS fit (not the fold job, whose signature
names the study fits' state folders, :func:`parknss.experiments.store.fit_key`)."""


@pytest.fixture
def tiny(tmp_path) -> tuple[Path, Path]:
    """(campaign folder, tiny experiments YAML)."""
    return tiny_setup(tmp_path / "in")


def test_cv(tiny, tmp_path, capsys, monkeypatch):
    data, _ = tiny
    out = tmp_path / "cv"
    argv = ["cv", "--data", str(data), "--variants", "linear", "--workers", "1",
            "--out", str(out)]
    _check_command(capsys, monkeypatch, out, argv, [*argv, "--seed", "7"], held="model.json",
                   command="parknss cv", cache_job="parknss.experiments.folds.fold_job")
    assert (out / "table2.txt").is_file() and len(list((out / "cache").glob("*.json"))) == 4


def test_evaluate(tiny, tmp_path, capsys, monkeypatch):
    data, _ = tiny
    out = tmp_path / "ev"
    argv = ["evaluate", "--data", str(data), "--out", str(out)]
    _check_command(capsys, monkeypatch, out, argv, [*argv, "--limiter"],
                   held="campaign.json", command="parknss evaluate")
    assert json.loads((out / "evaluate.json").read_text())["source"] == str(SHIPPED_NSS)


def test_study(tiny, tmp_path, capsys, monkeypatch):
    data, cfg = tiny
    out = tmp_path / "seed"
    argv = ["study", "seed-noise", "--quick", "--workers", "1", "--data", str(data),
            "--config", str(cfg), "--out", str(out)]
    _check_command(capsys, monkeypatch, out, argv, [*argv, "--floor", "paper"],
                   held="chain.json", command="parknss study",
                   cache_job=FIT)
    assert (out / "seed-noise.json").is_file() and (out / "seed_noise.png").is_file()


def test_studies_share_one_folder_and_its_cache(tiny, tmp_path, capsys, monkeypatch):
    """``study limiter`` after ``study seed-noise`` in the same --out (docs/experiments.md):
    allowed, and its floor comes from the seed-noise fits cached there."""
    import parknss.experiments.folds as folds

    real, calls = folds.fold_job, []

    def counted(*args, **kwargs):
        calls.append(kwargs)
        return real(*args, **kwargs)

    monkeypatch.setattr(folds, "fold_job", counted)
    data, cfg = tiny
    base = ["--quick", "--workers", "1", "--data", str(data), "--config", str(cfg)]
    shared = tmp_path / "shared"
    assert main(["study", "seed-noise", *base, "--out", str(shared)]) == 0
    calls.clear()
    assert main(["study", "limiter", *base, "--out", str(shared)]) == 0
    in_shared = len(calls)
    calls.clear()
    assert main(["study", "limiter", *base, "--out", str(tmp_path / "fresh")]) == 0
    assert in_shared < len(calls)
    assert read_manifest(shared)["studies"] == ["limiter", "seed-noise"]
    assert {"seed-noise.json", "limiter.json"} <= {p.name for p in shared.iterdir()}


def test_reproduce(tiny, tmp_path, capsys, monkeypatch):
    data, cfg = tiny
    out = tmp_path / "rep"
    base = ["--quick", "--workers", "1", "--data", str(data), "--config", str(cfg),
            "--out", str(out)]
    doc = _check_command(capsys, monkeypatch, out, ["reproduce", "seed_noise", *base],
                         ["reproduce", "campaign", *base], held="legacy",
                         command="parknss reproduce",
                         fail="parknss.experiments.reproduce.write_report",
                         cache_job=FIT)
    assert doc["artefacts"] == ["seed_noise"] and doc["report"] == str(out / "report.html")


@pytest.mark.slow
def test_demo(tmp_path, capsys, monkeypatch):
    """On 4 short trials, parking under the kinematic plant only (seconds, not minutes)."""
    import parknss.experiments.demo as demo

    real = demo.simulate_scene
    monkeypatch.setattr(demo, "simulate_scene", lambda spec, plants: real(spec, ["kinematic"]))
    data = write_campaign(make_campaign(n=300, reps=1), tmp_path / "campaign")
    out = tmp_path / "demo"
    argv = ["demo", "--data", str(data), "--cell", "14", "--out", str(out)]
    _check_command(capsys, monkeypatch, out, argv, [*argv, "--cell", "15"],
                   held="other-command", command="parknss demo",
                   fail="parknss.experiments.demo.run_rate")
    assert (out / "summary.json").is_file() and (out / "rate" / "ratings.csv").is_file()


def test_plan(tmp_path, capsys, monkeypatch):
    out = tmp_path / "plan"
    argv = ["plan", "--scene", "14", "--no-refine", "--out", str(out)]
    _check_command(capsys, monkeypatch, out, argv,
                   ["plan", "--scene", "15", "--no-refine", "--out", str(out)],
                   held="campaign.json", command="parknss plan")
    assert sorted(p.suffix for p in out.iterdir()) == [".json", ".json", ".svg"]
    grid = tmp_path / "plan_grid"
    assert main(["plan", "--grid", "12", "--no-refine", "--out", str(grid)]) == 0
    assert (grid / "plan_grid_12.json").is_file()
    assert main(["plan", "--grid", "12", "--no-refine", "--out", str(out)]) == 2
    assert "holds a run of parknss plan with other arguments" in _one_error(capsys)


def test_plan_and_simulate_default_to_one_folder_per_scene(tmp_path, capsys, monkeypatch):
    """Without --out, scene after scene needs no --overwrite (runs/<command>/<scene>)."""
    monkeypatch.chdir(tmp_path)
    for scene in ("14", "15"):
        assert main(["plan", "--scene", scene, "--no-refine", "--json"]) == 0
        assert Path(json.loads(capsys.readouterr().out)["figure"]).parent.parent == Path(
            "runs/plan")
    assert len(list(Path("runs/plan").iterdir())) == 2
    assert main(["simulate", "--scene", "26", "--json"]) == 0
    fig8 = json.loads(capsys.readouterr().out)["figures"]["fig8"]
    assert Path(fig8).parent == Path("runs/simulate/angled-left-t1-open")


def test_simulate(tmp_path, capsys, monkeypatch):
    out = tmp_path / "sim"
    argv = ["simulate", "--scene", "26", "--out", str(out)]
    _check_command(capsys, monkeypatch, out, argv, [*argv, "--series"],
                   held="model.json", command="parknss simulate")
    assert {p.suffix for p in out.iterdir()} == {".json", ".png"}


def test_simulate_refuses_a_plan_run(tmp_path, capsys):
    out = tmp_path / "x"
    assert main(["plan", "--scene", "14", "--no-refine", "--out", str(out)]) == 0
    capsys.readouterr()
    before = _snapshot(out)
    assert main(["simulate", "--scene", "14", "--out", str(out)]) == 2
    assert _one_error(capsys) == (
        f"parknss: error: {out}: holds a run of parknss plan (run.json) already; "
        "pass --overwrite to replace it with this run of parknss simulate")
    assert _snapshot(out) == before


def test_grid(tmp_path, capsys, monkeypatch):
    out = tmp_path / "grid"
    argv = ["grid", "--grid", "36", "--cells", "26", "--plants", "kinematic", "--out", str(out)]
    _check_command(capsys, monkeypatch, out, argv,
                   ["grid", "--grid", "36", "--cells", "14", "--plants", "kinematic", "--out",
                    str(out)], held="chain.json", command="parknss grid")
    assert (out / "grid_36_cells.csv").read_text().count("\n") == 2


def test_tune(tmp_path, capsys, monkeypatch):
    """The descent's grid runs replaced by a quick objective of the gains (the run folder
    is what is tested here, not the closed loop)."""
    import parknss.sim.tuning as tuning

    def fake_grid(grid, plants, cells, workers, *, interface_overrides=None, **kw):
        err = abs(interface_overrides["kp"] - 1.0) * 10.0
        return [{"plannable": True, "goal_error_cm": err, "duration_s": 10.0,
                 "completed": True} for _ in cells]

    monkeypatch.setattr(tuning, "run_grid", fake_grid)
    out = tmp_path / "tune"
    argv = ["tune", "--plant", "kinematic", "--out", str(out)]
    _check_command(capsys, monkeypatch, out, argv, [*argv, "--rounds", "1"],
                   held="legacy", command="parknss tune")
    assert (out / "interface_tuned.yaml").is_file() and (out / "tune.json").is_file()


def test_rate(tiny, tmp_path, capsys, monkeypatch):
    data, _ = tiny
    out = tmp_path / "rate"
    argv = ["rate", "--data", str(data), "--out", str(out)]
    _check_command(capsys, monkeypatch, out, [*argv, "--model", str(SHIPPED_NSS)],
                   [*argv, "--chain", str(SHIPPED_CHAIN)], held="campaign.json",
                   command="parknss rate", fail="parknss.experiments.rating.draw_iso_boxplot")
    assert json.loads((out / "ratings.json").read_text())["source"]["mode"] == "model"


def test_actuators_study(tmp_path, capsys, monkeypatch, actuator_campaign, actuator_nss):
    write_campaign(actuator_campaign, tmp_path / "data")
    model, cfg = actuator_nss
    save_model(tmp_path / "nss", model, cfg, {})
    act = yaml.safe_dump(json.loads(tiny_config().model_dump_json()))
    (tmp_path / "act.yaml").write_text(act)
    (tmp_path / "act2.yaml").write_text(act)
    out = tmp_path / "study"
    base = ["actuators", "study", "--nss", str(tmp_path / "nss"), "--data",
            str(tmp_path / "data"), "--out", str(out), "--config"]
    _check_command(capsys, monkeypatch, out, [*base, str(tmp_path / "act.yaml")],
                   [*base, str(tmp_path / "act2.yaml")], held="other-command",
                   command="parknss actuators study")
    assert (out / "selection.json").is_file()


def test_every_command_with_an_out_folder_has_overwrite():
    """No command writes an --out without offering --overwrite (typer's registered params)."""
    import typer.main

    from parknss.cli import app

    group = typer.main.get_command(app)
    missing = []

    def walk(cmd, name):
        for sub_name, sub in getattr(cmd, "commands", {}).items():
            walk(sub, f"{name} {sub_name}")
        opts = {o for p in getattr(cmd, "params", []) for o in getattr(p, "opts", [])}
        if "--out" in opts and "--overwrite" not in opts:
            missing.append(name)

    walk(group, "parknss")
    assert missing == []
