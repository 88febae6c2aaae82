"""Commands that write artefact folders refuse an occupied --out unless --overwrite and
write atomically (issue 13, item 9): campaign import, campaign generate, train."""

from __future__ import annotations

import json

import pytest

from helpers.synth import make_campaign
from parknss.cli import main
from parknss.data.io import read_campaign, write_campaign, write_trial_csv
from parknss.data.trial import Campaign


def _one_error(capsys) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("parknss: error: ")]
    assert len(lines) == 1, err
    return lines[0]


def _files(folder) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


@pytest.fixture(scope="module")
def sixteen():
    return make_campaign(n=400, reps=4)


@pytest.fixture
def existing(tmp_path, sixteen):
    """An earlier 16-trial campaign at OUT, and a folder SRC of 2 new logs."""
    out = write_campaign(sixteen, tmp_path / "campaign")
    src = tmp_path / "logs"
    src.mkdir()
    for tr in list(sixteen)[:2]:
        write_trial_csv(tr, src / f"{tr.id}.csv")
    return src, out


# -- campaign import ----------------------------------------------------------------------------


def test_import_over_an_existing_campaign_is_refused(existing, capsys):
    """The issue's scenario: no 2-trial campaign.json over a 16-trial folder."""
    src, out = existing
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert main(["campaign", "import", str(src), "--out", str(out)]) == 2
    line = _one_error(capsys)
    assert line == (
        f"parknss: error: {out}: holds a campaign (campaign.json) already; "
        "pass --overwrite to replace it with the campaign"
    )
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert len(read_campaign(out)) == 16


def test_import_overwrite_replaces_the_whole_campaign(existing, capsys):
    src, out = existing
    assert main(["campaign", "import", str(src), "--out", str(out), "--overwrite"]) == 0
    camp = read_campaign(out)
    assert len(camp) == 2
    # no orphaned trials of the earlier campaign, no temporary folders
    assert _files(out) == sorted(["campaign.json", *(f"{i}.parquet" for i in camp.ids)])
    assert [p.name for p in out.parent.iterdir() if p.name.startswith(".")] == []


def test_failed_import_leaves_the_earlier_campaign_whole(existing, capsys, monkeypatch):
    src, out = existing
    import parknss.data.io as io

    def broken(trial, path):
        raise OSError("disk full")

    monkeypatch.setattr(io, "write_trial_parquet", broken)
    with pytest.raises(OSError, match="disk full"):
        io.write_campaign(io.import_folder(src), out, overwrite=True)
    monkeypatch.undo()
    assert len(read_campaign(out)) == 16
    assert [p.name for p in out.parent.iterdir() if p.name.startswith(".")] == []


def test_import_refuses_to_replace_its_own_logs(existing, capsys):
    src, _ = existing
    assert main(["campaign", "import", str(src), "--out", str(src), "--overwrite"]) == 2
    assert "holds the logs being imported" in _one_error(capsys)
    assert len(list(src.glob("*.csv"))) == 2


# -- campaign generate --------------------------------------------------------------------------


@pytest.fixture
def tiny_generator(monkeypatch):
    """generate_campaign replaced by a 2-trial one (the real one takes seconds)."""
    import parknss.reference.campaign as rc

    calls = []

    def fake(seed=0, vehicle_yaml=None, progress=False):
        calls.append(seed)
        return Campaign(list(make_campaign(n=400, reps=1))[:2], name=f"reference_seed{seed}")

    monkeypatch.setattr(rc, "generate_campaign", fake)
    return calls


def test_generate_refuses_then_overwrites(existing, tiny_generator, capsys):
    _, out = existing
    assert main(["campaign", "generate", "--out", str(out), "--seed", "3"]) == 2
    assert "holds a campaign (campaign.json) already; pass --overwrite" in _one_error(capsys)
    assert tiny_generator == []  # refused before the long work
    assert len(read_campaign(out)) == 16
    assert main(["campaign", "generate", "--out", str(out), "--seed", "3", "--overwrite"]) == 0
    camp = read_campaign(out)
    assert camp.name == "reference_seed3" and len(camp) == 2 and len(_files(out)) == 3


def test_generate_into_a_fresh_folder(tmp_path, tiny_generator):
    out = tmp_path / "new" / "c"
    assert main(["campaign", "generate", "--out", str(out)]) == 0
    assert len(read_campaign(out)) == 2


# -- train ----------------------------------------------------------------------------------------

TINY_SETS = [
    "--set", "model.state_units=8", "--set", "model.state_layers=1",
    "--set", "model.output_units=8", "--set", "model.output_layers=1",
    "--set", "train.val_every=1", "--set", "train.smooth_window=1",
    "--set", "train.checkpoint_every=1",
]  # fmt: skip


@pytest.mark.slow
def test_train_refuses_an_earlier_run_overwrites_and_resumes(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("MPLBACKEND", "Agg")
    data = write_campaign(make_campaign(n=400, reps=4), tmp_path / "data")
    out = tmp_path / "run"
    base = ["train", "--data", str(data), "--out", str(out), *TINY_SETS]
    assert main([*base, "--epochs", "2", "--seed", "1", "--json"]) == 0
    capsys.readouterr()
    model = out / "model" / "model.json"
    first = model.read_bytes()
    assert json.loads(first)["config"]["train"]["seed"] == 1

    # another seed over the earlier model: refused, the model untouched
    assert main([*base, "--epochs", "2", "--seed", "2"]) == 2
    assert "holds a run (" in _one_error(capsys) and model.read_bytes() == first

    # --resume continues in the same folder on purpose (no --overwrite needed); a finished
    # state resumes to the same model
    assert main([*base, "--epochs", "2", "--seed", "1", "--resume", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["epochs"] == 2 and doc["model"] == str(out / "model")
    assert json.loads(model.read_text())["weights"] == json.loads(first)["weights"]

    # --overwrite: a fresh fit replaces the model folder whole
    assert main([*base, "--epochs", "2", "--seed", "2", "--overwrite"]) == 0
    meta = json.loads(model.read_text())
    assert meta["config"]["train"]["seed"] == 2
    assert sorted(p.name for p in model.parent.iterdir()) == [
        "SHA256SUMS", "model.json", "model.safetensors"]
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []
