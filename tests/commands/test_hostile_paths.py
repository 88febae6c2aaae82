"""Names never become paths, through the commands: a scene whose ``meta.name`` walks out
of ``--out`` (``../../victim``), has control or bidirectional characters or 300
characters is refused in one line before any planning, by ``plan`` and ``simulate``, with
and without ``--out``, with ``--overwrite``; nothing outside ``--out`` is written or
removed. A safe name plans into ``runs/plan/<name>``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from parknss.cli import main
from parknss.sim.scenarios import grid_scene

HOSTILE = [
    "../../../../victim",
    "../../important",
    "../victim",
    "sub/dir",
    "nul\x00name",
    "new\nline",
    "rtl\u202eevil.json",
    "\u200fmark",
    "x" * 300,
    "..",
]


def _scene(path: Path, name: object) -> Path:
    doc = grid_scene(14).to_json()
    doc["meta"]["name"] = name
    path.write_text(json.dumps(doc))
    return path


def _tree(root: Path) -> dict[str, bytes | None]:
    """Every path under ``root`` with its content (None for folders)."""
    return {str(p.relative_to(root)): (p.read_bytes() if p.is_file() else None)
            for p in sorted(root.rglob("*"))}


@pytest.fixture
def world(tmp_path, monkeypatch):
    """A working folder deep enough for ``../../../../`` to land in tmp_path, with a
    victim file and an unrelated folder ``important/`` beside it; planning must never
    start (the name is checked first)."""
    work = tmp_path / "a" / "b" / "c" / "w"
    work.mkdir(parents=True)
    (tmp_path / "victim").write_text("precious")
    (tmp_path / "important").mkdir()
    (tmp_path / "important" / "data.txt").write_text("keep me")
    for d in (tmp_path / "a", tmp_path / "a" / "b"):
        (d / "victim").write_text("precious")
    monkeypatch.chdir(work)

    def no_planning(*_a, **_k):
        raise AssertionError("planning started before the name was checked")

    import parknss.sim.planner as planner
    import parknss.sim.session as session

    # experiments.scenes imports them where used (fast start-up): patch their homes
    monkeypatch.setattr(planner, "plan_named_scene", no_planning)
    monkeypatch.setattr(session, "simulate_scene", no_planning)
    return tmp_path, work


def _refused(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("parknss: error: scene name "), err
    assert "\x00" not in err[0] and "\u202e" not in err[0] and "\u200f" not in err[0]
    return err[0]


@pytest.mark.parametrize("name", HOSTILE)
@pytest.mark.parametrize("command", ["plan", "simulate"])
def test_a_hostile_scene_name_writes_nothing_anywhere(command, name, world, capsys):
    root, _ = world
    scene = _scene(root / "evil.json", name)
    before = _tree(root)
    for extra in (["--out", "w/out"], [], ["--overwrite"], ["--out", "w/out", "--overwrite"]):
        assert main([command, "--scene", str(scene), *extra]) == 2
        _refused(capsys)
        assert _tree(root) == before  # nothing written, replaced or removed anywhere


def test_a_name_that_is_a_number_is_refused(world, capsys):
    root, _ = world
    assert main(["plan", "--scene", str(_scene(root / "n.json", 123))]) == 2
    assert "is not a string" in _refused(capsys)


def test_a_safe_name_plans_into_runs_plan_name(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    name = "Parkplatz Süd (Ebene 2)"
    scene = _scene(tmp_path / "s.json", name)
    assert main(["plan", "--scene", str(scene), "--no-refine", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    folder = tmp_path / "runs" / "plan" / name
    assert Path(doc["figure"]).resolve() == (folder / f"plan_{name}.svg").resolve()
    assert sorted(p.name for p in folder.iterdir()) == [f"plan_{name}.svg", "run.json"]


def test_a_product_link_out_of_the_folder_is_refused(tmp_path, capsys):
    """A run folder with a planted link where a product goes: the product is refused
    after resolution, the link's target untouched."""
    out = tmp_path / "out"
    scene = _scene(tmp_path / "s.json", "cell")
    assert main(["plan", "--scene", str(scene), "--no-refine", "--out", str(out)]) == 0
    capsys.readouterr()
    target = tmp_path / "elsewhere.json"
    target.write_text("keep")
    (out / "plan_cell.json").unlink()
    (out / "plan_cell.json").symlink_to(target)
    assert main(["plan", "--scene", str(scene), "--no-refine", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "resolves outside the output folder" in err[0]
    assert target.read_text() == "keep"


@pytest.mark.parametrize("stem", ["t" * 200, "a\u202eb\u200fc"])
def test_a_trial_id_from_a_log_file_name_is_safe_or_refused(stem, tmp_path, capsys):
    from helpers.synth import make_trial
    from parknss.data.io import read_campaign, write_trial_csv

    logs = tmp_path / "logs"
    logs.mkdir()
    write_trial_csv(make_trial(300), logs / f"{stem}.csv")
    out = tmp_path / "camp"
    code = main(["campaign", "import", str(logs), "--out", str(out)])
    if len(stem) > 100:  # refused in one line, nothing written
        assert code == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert "trial id" in err[-1] and "at most 100" in err[-1]
        assert sorted(p.name for p in tmp_path.iterdir()) == ["logs"]
    else:  # the control characters become '_' in the id
        assert code == 0
        (trial,) = read_campaign(out)
        assert trial.id == "a_b_c" and (out / "a_b_c.parquet").is_file()


def test_overwrite_replaces_a_linked_out_never_its_target(tmp_path, capsys):
    """``--out`` is a link to an unrelated folder: ``--overwrite`` replaces the link with
    the run folder; the folder it pointed at keeps every file."""
    important = tmp_path / "important"
    important.mkdir()
    (important / "data.txt").write_text("keep me")
    out = tmp_path / "out"
    out.symlink_to(important)
    scene = _scene(tmp_path / "s.json", "cell")
    argv = ["plan", "--scene", str(scene), "--no-refine", "--out", str(out)]
    assert main(argv) == 2  # holds something else: refused without --overwrite
    assert main([*argv, "--overwrite"]) == 0
    capsys.readouterr()
    assert sorted(p.name for p in important.iterdir()) == ["data.txt"]
    assert (important / "data.txt").read_text() == "keep me"
    assert not out.is_symlink() and (out / "plan_cell.json").is_file()
