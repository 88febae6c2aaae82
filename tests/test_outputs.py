"""parknss.outputs: atomic artefact folders, refused over another artefact without
--overwrite."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from parknss.errors import ParknssError
from parknss.outputs import OutputExistsError, artefact_folder, check_writable, describe_contents


def _artefact(path, n: int, marker: str = "campaign.json") -> None:
    path.mkdir(parents=True, exist_ok=True)
    (path / marker).write_text(f'{{"n": {n}}}')
    for i in range(n):
        (path / f"t{i}.parquet").write_text(str(i))


def _leftovers(parent):
    return sorted(p.name for p in parent.iterdir() if p.name.startswith("."))


def test_fresh_folder_is_written_in_place(tmp_path):
    out = tmp_path / "a" / "b" / "camp"
    with artefact_folder(out, overwrite=False, kind="campaign") as tmp:
        assert tmp != out and tmp.parent == out.parent and tmp.name.startswith(".camp.tmp-")
        assert not out.exists()
        _artefact(tmp, 2)
    assert sorted(p.name for p in out.iterdir()) == ["campaign.json", "t0.parquet", "t1.parquet"]
    assert _leftovers(out.parent) == []


def test_empty_existing_folder_is_not_an_artefact(tmp_path):
    out = tmp_path / "camp"
    out.mkdir()
    check_writable(out, overwrite=False, kind="campaign")
    with artefact_folder(out, overwrite=False, kind="campaign") as tmp:
        _artefact(tmp, 1)
    assert (out / "campaign.json").is_file()


@pytest.mark.parametrize(
    "marker,what", [("campaign.json", "a campaign (campaign.json)"),
                    ("model.json", "a model (model.json)"),
                    ("chain.json", "a chain (chain.json)"),
                    ("summary.json", "a run (3 entries)")]
)
def test_refused_without_overwrite(tmp_path, marker, what):
    out = tmp_path / "x"
    _artefact(out, 2, marker)
    assert describe_contents(out) == what
    before = sorted(p.name for p in out.iterdir())
    with pytest.raises(OutputExistsError) as ei:
        check_writable(out, overwrite=False, kind="campaign")
    msg = str(ei.value)
    assert msg == f"{out}: holds {what} already; pass --overwrite to replace it with the campaign"
    ran = False
    with (
        pytest.raises(ParknssError, match="--overwrite"),
        artefact_folder(out, overwrite=False, kind="campaign"),
    ):
        ran = True
    assert not ran
    assert sorted(p.name for p in out.iterdir()) == before
    assert _leftovers(tmp_path) == []


def test_replaced_with_overwrite(tmp_path):
    out = tmp_path / "camp"
    _artefact(out, 16)
    with artefact_folder(out, overwrite=True, kind="campaign") as tmp:
        _artefact(tmp, 2)
        assert len(list(out.iterdir())) == 17  # the old one is whole while writing
    assert sorted(p.name for p in out.iterdir()) == ["campaign.json", "t0.parquet", "t1.parquet"]
    assert _leftovers(tmp_path) == []


@pytest.mark.parametrize("overwrite", [False, True])
def test_failing_writer_leaves_earlier_artefact_whole(tmp_path, overwrite):
    out = tmp_path / "camp"
    if overwrite:
        _artefact(out, 16)
    with (
        pytest.raises(RuntimeError, match="boom"),
        artefact_folder(out, overwrite=overwrite, kind="campaign") as tmp,
    ):
        _artefact(tmp, 2)
        raise RuntimeError("boom")
    if overwrite:
        assert len(list(out.iterdir())) == 17 and (out / "t15.parquet").is_file()
        assert (out / "campaign.json").read_text() == '{"n": 16}'
    else:
        assert not out.exists()
    assert _leftovers(tmp_path) == []


def test_killed_writer_leaves_earlier_artefact_whole(tmp_path):
    out = tmp_path / "camp"
    _artefact(out, 16)
    code = textwrap.dedent(f"""
        import os, signal
        from parknss.outputs import artefact_folder
        with artefact_folder({str(out)!r}, overwrite=True, kind="campaign") as tmp:
            (tmp / "campaign.json").write_text("{{}}")
            os.kill(os.getpid(), signal.SIGKILL)
    """)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True)
    assert res.returncode == -9
    assert (out / "campaign.json").read_text() == '{"n": 16}'
    assert len(list(out.iterdir())) == 17
    assert len(_leftovers(tmp_path)) == 1  # the killed writer's temporary folder
    # the next writer tidies it and is not confused by it
    with artefact_folder(out, overwrite=True, kind="campaign") as tmp:
        _artefact(tmp, 1)
    assert (out / "campaign.json").read_text() == '{"n": 1}'
    assert _leftovers(tmp_path) == []


def test_crash_between_the_renames_puts_the_old_artefact_back(tmp_path):
    """A writer killed after renaming the old artefact away, before renaming the new one
    in: the next look at ``out`` restores the old one (it is whole under its .old name)."""
    out = tmp_path / "camp"
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True).stdout.strip()
    _artefact(tmp_path / f".camp.old-{dead}", 16)
    _artefact(tmp_path / f".camp.tmp-{dead}", 2)
    with pytest.raises(OutputExistsError, match="campaign"):
        check_writable(out, overwrite=False, kind="campaign")
    assert (out / "campaign.json").read_text() == '{"n": 16}' and len(list(out.iterdir())) == 17
    assert _leftovers(tmp_path) == []


def test_an_artefact_replaced_and_killed_anywhere_is_always_whole(tmp_path):
    """A model folder saved over and over (``save_model`` through :func:`artefact_folder`)
    and SIGKILLed at the crash point after the flush and at random instants: ``out``
    loads right after every kill, no tidying first, as the one model or the other (the
    new folder is exchanged into place in one step)."""
    import random
    import signal

    import torch

    from helpers.kills import run_killed
    from helpers.synth import make_campaign, tiny_model
    from parknss.nss.checkpoint import load_model, save_model

    camp = make_campaign(60, reps=1)
    models = [tiny_model(camp, seed=s) for s in (1, 2)]
    out = tmp_path / "m"
    save_model(out, *models[0])

    def body():
        for i in range(10000):
            save_model(out, *models[i % 2])

    rng = random.Random(0)
    kills = [("artefact.tmp:1", None), ("artefact.tmp:2", None)]
    kills += [(None, rng.uniform(0.0, 0.3)) for _ in range(10)]
    for crash, after in kills:
        assert run_killed(body, crash, after) == signal.SIGKILL
        w = load_model(out).model.state_net[0].weight
        assert any(torch.equal(w, m.state_net[0].weight) for m, _ in models)


def test_refuses_a_file_and_the_working_directory(tmp_path, monkeypatch):
    f = tmp_path / "f"
    f.write_text("x")
    with pytest.raises(OutputExistsError, match="is a file"):
        check_writable(f, overwrite=True, kind="run")
    d = tmp_path / "d"
    _artefact(d, 1)
    monkeypatch.chdir(d)
    with pytest.raises(OutputExistsError, match="working directory"):
        check_writable(d, overwrite=True, kind="run")
    with pytest.raises(OutputExistsError, match="working directory"):
        check_writable(tmp_path, overwrite=True, kind="run")
    assert os.path.isfile(d / "campaign.json")
