"""Data-parallel training (nss/parallel.py): shards add up to the batch, the fit equals the
one-process fit up to rounding, is deterministic and resumable, and its workers never
outlive it."""

from __future__ import annotations

import multiprocessing
import os
import signal

import pytest
import torch

from helpers.synth import make_campaign, tiny_config, tiny_model
from parknss.data.windows import make_windows
from parknss.errors import CheckpointError, ParknssError
from parknss.nss import parallel, train_state
from parknss.nss.batch import make_batch
from parknss.nss.config import fit_identity, with_overrides
from parknss.nss.losses import Share
from parknss.nss.parallel import shard_indices
from parknss.nss.step import epoch_loss
from parknss.nss.train import fit

CAMP = make_campaign(130, reps=2)  # 8 trials, 142..186 samples
TRAIN = [tr for tr in CAMP if tr.repetition == 1]
VAL = [tr for tr in CAMP if tr.repetition == 2][:2]
FAST = {"window": 40, "batch": 3, "updates": 5, "finish_epochs": 2, "val_every": 2}


def _cfg(processes=1, epochs=6, recipe="paper", **train):
    cfg = tiny_config("float64", train={"epochs": epochs, "seed": 4, "val_every": 2,
                                        "smooth_window": 3, "processes": processes,
                                        "recipe": recipe, **train})
    if recipe == "coarse":
        return with_overrides(cfg, coarse={"factor": 3, "epochs": 4, "finish_epochs": 2,
                                           "val_every": 2})
    return with_overrides(cfg, fast=FAST) if recipe == "fast" else cfg


def _fit(cfg, **kw):
    return fit(TRAIN, VAL, cfg, progress=False, **kw)


def _rows(res):
    return [{k: v for k, v in r.items() if k != "cpu_s"} for r in res.history.rows]


def _workers() -> list:
    """This process's live data-parallel workers (other tests' pools may live beside)."""
    return [p for p in multiprocessing.active_children() if p.name.startswith("parknss-dp")]


def _same_weights(a, b) -> bool:
    sa, sb = a.state_dict(), b.state_dict()
    return sa.keys() == sb.keys() and all(torch.equal(sa[k], sb[k]) for k in sa)


@pytest.mark.parametrize(("n", "p"), [(29, 2), (29, 3), (8, 2), (3, 4), (1, 2), (7, 7)])
def test_shards_are_contiguous_balanced_and_cover_the_batch(n, p):
    shards = shard_indices(n, p)
    assert len(shards) == min(n, p) and all(len(s) for s in shards)
    assert torch.equal(torch.cat(shards), torch.arange(n))
    sizes = [len(s) for s in shards]
    assert max(sizes) - min(sizes) <= 1


@pytest.mark.parametrize("loss", [
    {},
    {"blind_zone": "observe", "kind": "mse"},
    {"lambda_torque": 0.3, "torque_prior_states": "both", "torque_prior_samples": 16,
     "lambda_decouple": 0.2, "kind": "logcosh"},
])
def test_shard_losses_and_gradients_add_up_to_the_batch(loss):
    """Eq. 8 (and the opt-in priors) of three shards with their Share: the terms and the
    gradients sum to the whole batch's (float64, to rounding)."""
    model, cfg = tiny_model(CAMP, seed=2, loss=loss)
    batch = make_batch(model, make_windows(TRAIN, 60), cfg.loss.blind_zone_kmh)
    params = list(model.parameters())

    def grads_of(terms):
        model.zero_grad(set_to_none=True)
        terms.total.backward()
        return [p.grad.clone() for p in params]

    whole = epoch_loss(model, batch, cfg)
    ref = whole.as_floats()
    g_ref = grads_of(whole)
    sums = dict.fromkeys(ref, 0.0)
    g_sum = [torch.zeros_like(p) for p in params]
    for rank, idx in enumerate(shard_indices(batch.n, 3)):
        part = epoch_loss(model, batch.select(idx), cfg,
                          share=Share.of(batch.targets, first=rank == 0))
        for k, v in part.as_floats().items():
            sums[k] += v
        g_sum = [a + b for a, b in zip(g_sum, grads_of(part), strict=True)]
    assert sums.keys() == ref.keys()
    for k in ref:
        assert sums[k] == pytest.approx(ref[k], rel=1e-12, abs=1e-15), k
    for a, b in zip(g_sum, g_ref, strict=True):
        torch.testing.assert_close(a, b, rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("recipe", ["paper", "fast", "coarse"])
def test_two_process_fit_is_the_one_process_fit_up_to_rounding(recipe):
    """Same objective and Adam steps: every history value within 1e-9 relative (float64);
    the fit's CPU time counts its worker's too."""
    one = _fit(_cfg(1, recipe=recipe))
    two = _fit(_cfg(2, recipe=recipe))
    assert len(_rows(one)) == len(_rows(two))
    for a, b in zip(_rows(one), _rows(two), strict=True):
        assert a.keys() == b.keys()
        for k, v in a.items():
            want = v if isinstance(v, str) else pytest.approx(v, rel=1e-9, abs=1e-12)
            assert b[k] == want, (a["epoch"], k)
    for k, v in one.model.state_dict().items():
        torch.testing.assert_close(two.model.state_dict()[k], v, rtol=1e-8, atol=1e-10)
    assert one.best_epoch == two.best_epoch
    assert two.cpu_s > two.history.rows[0]["cpu_s"] > 0.0


def test_two_process_native_fit_is_the_one_process_fit_up_to_float32_rounding():
    """The native kernels (float32, C) in each worker: the same fit within float32 rounding."""
    def cfg(processes):
        base = tiny_config("float32", train={"epochs": 6, "seed": 4, "val_every": 2,
                                             "smooth_window": 3, "processes": processes})
        return with_overrides(base, model={"fused_kernels": "native"})

    one, two = _fit(cfg(1)), _fit(cfg(2))
    for a, b in zip(_rows(one), _rows(two), strict=True):
        for k, v in a.items():
            assert b[k] == (v if isinstance(v, str) else pytest.approx(v, rel=1e-4, abs=1e-7))
    assert one.model.kernels() == two.model.kernels() == "native"


def test_two_process_fit_is_deterministic_resumable_and_its_own_identity(tmp_path):
    """Bit-identical on a rerun and across a kill and resume; another fit than P = 1 for
    the fingerprint (a one-process resume of its state is refused)."""
    cfg = _cfg(2, epochs=8, checkpoint_every=3)
    ref = _fit(cfg)

    class KilledError(Exception):
        pass

    def killer(e):
        if e == 5:
            raise KilledError

    with pytest.raises(KilledError):
        _fit(cfg, out_dir=tmp_path, on_epoch=killer)
    assert not _workers()  # the worker went with the fit
    seen = []
    res = _fit(cfg, out_dir=tmp_path, resume=True, on_epoch=seen.append)
    assert seen == [4, 5, 6, 7, 8]
    assert _same_weights(res.model, ref.model) and _rows(res) == _rows(ref)
    assert fit_identity(cfg)["train"]["processes"] == 2
    assert "processes" not in fit_identity(_cfg(1))["train"]
    assert train_state.exists(tmp_path)
    with pytest.raises(CheckpointError, match="another config"):
        _fit(_cfg(1, epochs=8, checkpoint_every=3), out_dir=tmp_path, resume=True)


def test_a_worker_killed_mid_fit_is_one_line_error_and_nothing_is_left(tmp_path):
    def kill_worker(e):
        if e == 2:
            (proc,) = _workers()
            os.kill(proc.pid, signal.SIGKILL)

    with pytest.raises(ParknssError, match=r"data-parallel worker 1 exited unexpectedly"):
        _fit(_cfg(2, checkpoint_every=1), out_dir=tmp_path, on_epoch=kill_worker)
    assert not _workers()
    res = _fit(_cfg(2, checkpoint_every=1), out_dir=tmp_path, resume=True)
    assert res.epochs_run == 6


def test_more_processes_than_cores_is_said_in_one_note(monkeypatch, capsys):
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0})
    with parallel.DataParallelSteps(tiny_model(CAMP)[0], _cfg(2), 2):
        pass
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("parknss: note: train.processes 2 > the 1 ")
    assert not _workers()


def test_divergence_on_either_shard_and_a_worker_error_are_one_line():
    """A non-finite loss on the fit's own shard or on the worker's stops the step, naming
    it; a worker's exception comes back as one line; no process is left."""
    model, cfg = tiny_model(CAMP, seed=1)
    cfg = with_overrides(cfg, train={"processes": 2})
    batch = make_batch(model, make_windows(TRAIN, 60), cfg.loss.blind_zone_kmh)
    steps = parallel.DataParallelSteps(model, cfg, 2)
    with steps:
        weights = parallel._flat(model.parameters())
        with pytest.raises(ParknssError, match="worker 1: RuntimeError: a step before any"):
            steps._conns[0].send(("step", weights))  # no batch yet: refused there, one line
            steps._recv(1)
        assert torch.isfinite(torch.tensor(steps(model, batch, cfg, 1)["total"]))
        for window, step in ((0, 2), (batch.n - 1, 3)):  # shard 0 (here), shard 1 (worker)
            bad = batch.select(torch.arange(batch.n))
            bad.u[window, 5, 1] = float("nan")
            with pytest.raises(ParknssError, match=f"training diverged at step {step}"):
                steps(model, bad, cfg, step)
    assert not _workers()


def test_the_worker_of_a_killed_fit_exits():
    """SIGKILL of the fit's process closes the worker's pipe: the worker exits instead of
    waiting for steps that never come."""
    import subprocess
    import sys
    import time

    script = """
import os, signal, sys
sys.path.insert(0, "tests")
from helpers.synth import make_campaign, tiny_model
from parknss.data.windows import make_windows
from parknss.nss.batch import make_batch
from parknss.nss.config import with_overrides
from parknss.nss.parallel import DataParallelSteps
camp = make_campaign(130, reps=1)
model, cfg = tiny_model(camp)
cfg = with_overrides(cfg, train={"processes": 2})
steps = DataParallelSteps(model, cfg, 2).__enter__()
steps(model, make_batch(model, make_windows(list(camp), 60), 0.5), cfg, 1)
print(steps._procs[0].pid, flush=True)
os.kill(os.getpid(), signal.SIGKILL)
"""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120, cwd=root,
                          env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert proc.returncode == -9, proc.stderr
    pid = int(proc.stdout.split()[0])

    def running() -> bool:
        try:
            with open(f"/proc/{pid}/stat") as f:
                return f.read().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
        except FileNotFoundError:
            return False

    end = time.monotonic() + 30
    while running() and time.monotonic() < end:
        time.sleep(0.05)
    assert not running()


def _fit_rows_in_a_pool():
    return _rows(_fit(_cfg(2, epochs=3)))


def test_a_fit_in_a_pool_worker_starts_its_workers():
    """A study's fold fits run in the local executor's pool (loky), whose start method a
    fresh interpreter does not know: the fit's worker starts all the same (under spawn)
    and the fit is the one run here."""
    from joblib import Parallel, delayed

    pooled = Parallel(n_jobs=2, backend="loky")(delayed(_fit_rows_in_a_pool)() for _ in "ab")
    assert pooled == [_fit_rows_in_a_pool()] * 2


def test_train_command_on_two_processes_says_so_and_records_it(tmp_path, capsys):
    """`parknss train --processes 2` (bundled campaign, tiny net): the summary names the
    processes and the CPU time of all of them; the model records the setting."""
    import json

    from parknss.cli import main

    out = tmp_path / "t"
    tiny = [a for k, v in (("model.state_units", 4), ("model.state_layers", 1),
                           ("model.output_units", 4), ("model.output_layers", 1))
            for a in ("--set", f"{k}={v}")]
    assert main(["train", "--out", str(out), "--epochs", "2", "--processes", "2",
                 *tiny]) == 0
    assert " s on 2 processes (" in capsys.readouterr().out
    doc = json.loads((out / "model" / "model.json").read_text())
    assert doc["config"]["train"]["processes"] == 2
    assert doc["training"]["cpu_s"] > 0.0
