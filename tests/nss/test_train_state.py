"""Crash-consistent training states: a fit SIGKILLed over 20 times (every window of the
state write, three times each, and at random instants between) resumes every time and
ends with the weights of an uninterrupted fit, bit for bit."""

from __future__ import annotations

import contextlib
import json
import random
import signal

import torch

from helpers.kills import KILL_SCHEDULE, run_killed
from helpers.synth import make_campaign, tiny_config
from parknss.nss import train_state
from parknss.nss.train import fit

CAMP = make_campaign(60, reps=2)
TRAIN = [tr for tr in CAMP if tr.repetition == 1][:3]
VAL = [tr for tr in CAMP if tr.repetition == 2][:1]
CFG = tiny_config(train={"epochs": 60, "seed": 5, "val_every": 2, "smooth_window": 3,
                         "checkpoint_every": 1})


def _same(a, b) -> bool:
    sa, sb = a.state_dict(), b.state_dict()
    return sa.keys() == sb.keys() and all(torch.equal(sa[k], sb[k]) for k in sa)


def test_a_fit_killed_anywhere_resumes_to_the_uninterrupted_weights(tmp_path):
    ref = fit(TRAIN, VAL, CFG, progress=False)

    def body():
        fit(TRAIN, VAL, CFG, progress=False, out_dir=tmp_path, resume=True)

    rng = random.Random(0)
    kills: list[tuple[str | None, float | None]] = []
    for crash in KILL_SCHEDULE:  # 15 inside the write, each followed by one at random
        kills.append((crash, None))
        if len(kills) % 2:
            kills.append((None, rng.uniform(0.01, 0.06)))
    killed, steps = 0, []
    for crash, after in kills:
        sig = run_killed(body, crash=crash, after_s=after)
        assert sig in (signal.SIGKILL, 0), (crash, after, sig)  # never a refused resume
        killed += sig == signal.SIGKILL
        if train_state.exists(tmp_path):  # what a kill leaves: the newest generation whole
            assert train_state.tensors_path(tmp_path).is_file()
            steps.append(json.loads((tmp_path / train_state.META).read_text())["epoch"])
    assert killed >= 20
    assert steps == sorted(steps) and 0 < steps[-1] < CFG.train.epochs
    res = fit(TRAIN, VAL, CFG, progress=False, out_dir=tmp_path, resume=True)
    assert _same(res.model, ref.model) and res.best_epoch == ref.best_epoch
    assert res.history.crit_raw == ref.history.crit_raw
    left = sorted(p.name for p in tmp_path.iterdir())  # two generations, no temporary files
    assert left[-2:] == [train_state.META, train_state.PREV_META] and len(left) == 4


def test_a_state_written_before_generations_resumes(tmp_path):
    """A state of the earlier layout (``train_state.safetensors`` beside a JSON that names
    no tensor file) resumes bit-identically, and its next write is a generation."""
    cfg = tiny_config(train={"epochs": 6, "seed": 2, "val_every": 2, "smooth_window": 3,
                             "checkpoint_every": 3})
    ref = fit(TRAIN, VAL, cfg, progress=False)

    def stop(e):
        if e == 4:
            raise KeyboardInterrupt

    with contextlib.suppress(KeyboardInterrupt):
        fit(TRAIN, VAL, cfg, progress=False, out_dir=tmp_path, on_epoch=stop)
    meta = json.loads((tmp_path / train_state.META).read_text())
    train_state.tensors_path(tmp_path).rename(tmp_path / train_state.TENSORS)
    del meta["tensors"]
    (tmp_path / train_state.META).write_text(json.dumps(meta))
    assert not (tmp_path / train_state.PREV_META).exists()
    res = fit(TRAIN, VAL, cfg, progress=False, out_dir=tmp_path, resume=True)
    assert _same(res.model, ref.model)
    newest = json.loads((tmp_path / train_state.META).read_text())
    assert newest["epoch"] == 6 and newest["tensors"] != train_state.TENSORS
