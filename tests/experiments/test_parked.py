"""Parked training states (parknss.experiments.parked): a study fit killed at the end of
one sitting is parked in the store, resumed from it in another run folder, and finishes
with the numbers of the uninterrupted fit; its parked state goes when its result is
stored. On the tiny campaign, a 1x4 net, 6 epochs checkpointed every 2."""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import pytest

from parknss.cli import main
from parknss.errors import CheckpointError
from parknss.experiments import parked
from parknss.experiments.store import ResultStore
from parknss.experiments.sweep import Sweep, fold_spec
from parknss.nss import train_state

OVERRIDES = {"model": {"state_layers": 1, "state_units": 4, "output_layers": 1, "output_units": 4},
             "train": {"epochs": 6, "checkpoint_every": 2, "val_every": 1}}


class KilledError(Exception):
    """The end of a sitting, in the middle of a fit."""


def _sweep(data, run, store) -> Sweep:
    return Sweep(data=str(data), progress=False, workers=1, cache_dir=run / "cache",
                 state_root=run / "state", store=store)


def _run(data, run, store):
    sweep = _sweep(data, run, store)
    job = fold_spec(sweep, "cv", 1, OVERRIDES, name="tiny fold 1")
    return job, sweep.run([job], "tiny")[0]


def _kill_after(monkeypatch, saves: int):
    real, seen = train_state.save, []

    def save(*a, **k):
        real(*a, **k)
        seen.append(1)
        if len(seen) == saves:
            raise KilledError

    monkeypatch.setattr(train_state, "save", save)


@dataclass
class KilledFit:
    data: Path  # the campaign
    root: Path  # the store
    run: Path  # the run folder the fit was killed in
    key: str  # the fit's store key


@pytest.fixture
def killed(tmp_path, tiny_study, monkeypatch) -> KilledFit:
    """A fit killed after its step-2 checkpoint, in run folder ``a``."""
    data, _ = tiny_study
    root = tmp_path / "results"
    store = ResultStore(root, log=lambda msg: None)
    _kill_after(monkeypatch, 1)
    with pytest.raises(KilledError):
        _run(data, tmp_path / "a", store)
    monkeypatch.undo()
    job = fold_spec(_sweep(data, tmp_path / "a", store), "cv", 1, OVERRIDES)
    return KilledFit(data, root, tmp_path / "a", store.entry_key(job)[0])


def test_a_killed_fit_parks_and_finishes_elsewhere_as_if_never_stopped(killed, tmp_path,
                                                                         monkeypatch):
    data, root, run_a, key = killed.data, killed.root, killed.run, killed.key
    folder, = (run_a / "state").iterdir()
    label = json.loads((folder / parked.JOB_FILE).read_text())
    assert label["key"] == key and label["name"] == "tiny fold 1"
    outcomes = parked.park_run(run_a, root)
    assert [o.parked.step for o in outcomes] == [2]
    assert (root / parked.INFLIGHT / key / train_state.META).is_file()
    there = root / parked.INFLIGHT / key  # one generation (and its sittings), what git carries
    assert sorted(p.name for p in there.iterdir()) == sorted(
        [parked.JOB_FILE, train_state.META, train_state.tensors_path(there).name,
         parked.SITTINGS])
    assert parked.listing(root) == ([f"inflight/{key}  {outcomes[0].parked.line()}  "
                                     "(unfinished)"], [])
    # parking again the same state adds nothing
    again = parked.park_run(run_a, root)
    assert again[0].parked is None and "at step 2, this one at 2" in again[0].why

    loads = []
    real_load = train_state.load
    monkeypatch.setattr(train_state, "load", lambda *a, **k: loads.append(1) or real_load(*a, **k))
    logs = []
    store_b = ResultStore(root, log=logs.append)
    _, resumed = _run(data, tmp_path / "b", store_b)  # another sitting: a fresh run folder
    assert loads == [1]  # it started from the parked step-2 state, not from step 0
    assert any("resumes from its parked state (step 2" in m for m in logs)
    assert not (root / parked.INFLIGHT / key).exists()  # stored, so no longer parked
    assert (root / "fold_job" / f"{key}.json").is_file()

    _, plain = _run(data, tmp_path / "c", None)  # the uninterrupted fit, no store
    assert resumed["errors"] == plain["errors"]
    assert resumed["best_epoch"] == plain["best_epoch"]
    for curve in ("epochs", "raw", "smooth", "output"):  # the validation curve, step by step
        assert resumed["history"][curve] == plain["history"][curve]
    assert resumed["cpu_s"] >= resumed["history"]["cpu_s"][1]  # sitting a's steps included
    # a finished fit is not parked
    assert "finished, in the store" in parked.park_run(run_a, root)[0].why


def test_a_run_folder_further_along_keeps_its_own_state(killed, tmp_path):
    root, run_a, key = killed.root, killed.run, killed.key
    parked.park_run(run_a, root)
    own = tmp_path / "own"
    shutil.copytree(root / parked.INFLIGHT / key, own)
    meta = json.loads((own / train_state.META).read_text())
    meta["epoch"] = 4
    (own / train_state.META).write_text(json.dumps(meta))
    assert parked.seed(root, key, own) is None
    assert parked.read_step(own) == 4
    assert parked.seed(root, key, tmp_path / "empty").step == 2
    assert parked.seed(root, "0" * 24, tmp_path / "other") is None  # nothing under that key


def test_a_torn_or_misfiled_parked_state_is_invalid_and_never_resumed(killed, tmp_path, capsys):
    root, run_a, key = killed.root, killed.run, killed.key
    parked.park_run(run_a, root)
    assert main(["results", "verify", "--store", str(root)]) == 0
    assert "0 fits and 1 parked states" in capsys.readouterr().out
    tensors = train_state.tensors_path(root / parked.INFLIGHT / key)
    tensors.write_bytes(tensors.read_bytes()[:-8])
    assert parked.seed(root, key, tmp_path / "s") is None
    (path, why), = parked.parked_states(root)
    assert "does not match" in why
    assert main(["results", "verify", "--store", str(root)]) != 0
    assert "INVALID inflight/" in capsys.readouterr().out
    shutil.rmtree(path)
    parked.park_run(run_a, root)
    (root / parked.INFLIGHT / key).rename(root / parked.INFLIGHT / ("f" * 24))
    assert "belongs at inflight/" + key in parked.parked_states(root)[0][1]


def test_a_state_torn_on_every_copy_is_refused(killed, monkeypatch):
    root, run_a = killed.root, killed.run
    folder = next((run_a / "state").iterdir())
    real = shutil.copyfile

    def torn(src, dst):
        real(src, dst)
        if str(dst).endswith(".safetensors"):
            with open(dst, "ab") as f:
                f.write(b"x")

    monkeypatch.setattr(shutil, "copyfile", torn)
    with pytest.raises(CheckpointError, match="changed during 3 copies"):
        parked.copy_state(folder, root / "x")
    assert not (root / "x").exists() and not (root / "x.tmp").exists()


def test_park_command_names_what_it_parked_and_why_not(killed, tmp_path, capsys):
    root, run_a = killed.root, killed.run
    (run_a / "state" / "unlabelled").mkdir()
    root.mkdir()  # a store that holds no fit yet
    assert main(["results", "park", str(run_a), "--store", str(root)]) == 0
    out = capsys.readouterr().out
    assert "parked  tiny fold 1" in out and "step      2" in out
    assert "skipped unlabelled: no job.json" in out
    assert "1 of 2 state folders parked" in out
    assert main(["results", "list", "--store", str(root)]) == 0
    assert "(unfinished)" in capsys.readouterr().out
    assert main(["results", "park", str(tmp_path / "nowhere"), "--store", str(root)]) == 2
    assert "no fit of this run has written a training state" in capsys.readouterr().err


def test_parked_step_reads_the_state_of_the_job_that_answers_a_fold(killed, tmp_path):
    from parknss.executor import Job
    from parknss.experiments.jobs import ALIASES, FOLD_JOB

    store = ResultStore(killed.root, log=lambda msg: None)
    fold = fold_spec(_sweep(killed.data, tmp_path / "b", store), "cv", 1, OVERRIDES)
    limiter = Job(ALIASES[FOLD_JOB][0], fold.kwargs, fold.name)
    assert fold.fn == FOLD_JOB
    assert parked.park_run(killed.run, killed.root)  # the fold fit's state, at step 2
    assert store.parked_step(fold) == 2 and store.parked_step(limiter) == 0
    ahead = parked.parked_dir(killed.root, store.entry_key(limiter)[0])
    shutil.copytree(parked.parked_dir(killed.root, killed.key), ahead)
    meta = ahead / train_state.META
    meta.write_text(json.dumps({**json.loads(meta.read_text()), "epoch": 4}))
    assert store.parked_step(fold) == 4  # the limiter fit answers its fold: further along
    assert store.parked_step(limiter) == 4
