"""The fold state of ``cv``/``study`` (``fold_job(state_dir=...)``): SIGKILLed over 20
times, inside its state write and between, it resumes every time and saves the weights of
an uninterrupted fold fit, byte for byte."""

from __future__ import annotations

import random
import signal

from helpers.kills import KILL_SCHEDULE, run_killed
from parknss.experiments.folds import fold_job
from parknss.nss import train_state

OVERRIDES = {"model": {"state_layers": 1, "state_units": 4, "output_layers": 1, "output_units": 4},
             "train": {"epochs": 60, "checkpoint_every": 1, "val_every": 1}}


def test_a_fold_state_killed_anywhere_resumes_to_the_uninterrupted_weights(tiny_study, tmp_path):
    data, _ = tiny_study
    kw = {"split": "cv", "index": 1, "data": str(data), "overrides": OVERRIDES}
    ref = fold_job(**kw, save_dir=str(tmp_path / "ref"))
    state = tmp_path / "state"
    rng = random.Random(1)
    kills: list[tuple[str | None, float | None]] = []
    for crash in KILL_SCHEDULE:  # 15 inside the write, each followed by one at random
        kills.append((crash, None))
        if len(kills) % 2:
            kills.append((None, rng.uniform(0.05, 0.2)))
    killed = 0
    for crash, after in kills:
        sig = run_killed(lambda: fold_job(**kw, state_dir=str(state)), crash=crash, after_s=after)
        assert sig in (signal.SIGKILL, 0), (crash, after, sig)
        killed += sig == signal.SIGKILL
    assert killed >= 20 and train_state.exists(state)
    res = fold_job(**kw, state_dir=str(state), save_dir=str(tmp_path / "resumed"))
    weights = [(tmp_path / d / "model.safetensors").read_bytes() for d in ("ref", "resumed")]
    assert weights[0] == weights[1]
    assert res["errors"] == ref["errors"] and res["history"]["raw"] == ref["history"]["raw"]


def test_a_running_study_keeps_the_nss_config_it_read_at_its_start(tmp_path):
    """fold_config reads each file once per process: a later edit of the file (an upgrade
    adding a field this process's schema lacks) does not reach a study in progress."""
    from parknss.experiments.folds import fold_config

    p = tmp_path / "nss.yaml"
    p.write_text("train:\n  epochs: 7\n")
    first = fold_config(str(p), {"train": {"seed": 3}})
    p.write_text("train:\n  epochs: 9\n  a_field_from_the_future: 1\n")
    again = fold_config(str(p), {"train": {"seed": 4}})
    assert (first.train.epochs, first.train.seed) == (7, 3)
    assert (again.train.epochs, again.train.seed) == (7, 4)
    assert fold_config(str(p), None) == fold_config(str(p), {})
