"""Training: determinism, bit-identical resume, refusals, LR schedule, best checkpoint."""

from __future__ import annotations

import itertools
import math

import pytest
import torch

import parknss.nss.train as train_mod
from helpers.synth import make_campaign, make_trial, tiny_config
from parknss.data.windows import whole_trials
from parknss.errors import CheckpointError, DataError
from parknss.nss import train_state
from parknss.nss.batch import make_batch
from parknss.nss.config import with_overrides
from parknss.nss.train import fit, learning_rate, validation_losses

CAMP = make_campaign(130, reps=2)  # 8 trials, 142..186 samples
TRAIN = [tr for tr in CAMP if tr.repetition == 1]
VAL = [tr for tr in CAMP if tr.repetition == 2][:2]


def _cfg(epochs=10, seed=0, dtype="float64", **train):
    return tiny_config(
        dtype,
        train={"epochs": epochs, "seed": seed, "val_every": 2, "smooth_window": 3, **train},
    )


def _fit(cfg, val=VAL, **kw):
    return fit(TRAIN, val, cfg, progress=False, **kw)


def _numbers(hist) -> dict:
    """The history without its CPU times (which differ from run to run)."""
    d = hist.to_json()
    d["rows"] = [{k: v for k, v in r.items() if k != "cpu_s"} for r in d["rows"]]
    return d


def _same_weights(a, b) -> bool:
    sa, sb = a.state_dict(), b.state_dict()
    return sa.keys() == sb.keys() and all(torch.equal(sa[k], sb[k]) for k in sa)


def test_same_seed_bit_identical_other_seed_different():
    a = _fit(_cfg(6, seed=1))
    b = _fit(_cfg(6, seed=1))
    c = _fit(_cfg(6, seed=2))
    assert _same_weights(a.model, b.model)
    assert _numbers(a.history) == _numbers(b.history) and a.best_epoch == b.best_epoch
    cpu = [r["cpu_s"] for r in a.history.rows]  # the fit's CPU time, after every step
    assert all(0.0 < x < y for x, y in itertools.pairwise(cpu)) and a.cpu_s >= cpu[-1]
    assert not _same_weights(a.model, c.model)


@pytest.mark.parametrize("kernels", ["fast", "native"])
def test_fast_kernels_fit_is_deterministic_and_close_to_the_reference(kernels):
    """model.fused_kernels=fast or native: bit-identical under a seed; the same fit as the
    reference kernels up to float32 rounding."""
    fast = {"model": {"fused_kernels": kernels}}
    a = _fit(with_overrides(_cfg(6, seed=1, dtype="float32"), **fast))
    b = _fit(with_overrides(_cfg(6, seed=1, dtype="float32"), **fast))
    ref = _fit(_cfg(6, seed=1, dtype="float32"))
    assert _same_weights(a.model, b.model)
    assert _numbers(a.history) == _numbers(b.history)
    assert not _same_weights(a.model, ref.model)  # the option is in effect: other rounding
    for ra, rr in zip(a.history.rows, ref.history.rows, strict=True):
        assert ra["train_total"] == pytest.approx(rr["train_total"], rel=1e-4)


class _KilledError(Exception):
    pass


FAST = {"window": 40, "batch": 3, "updates": 7, "val_every": 2, "finish_epochs": 5}


@pytest.mark.parametrize(
    ("dtype", "val", "recipe"),
    [("float64", VAL, "paper"), ("float32", (), "paper"), ("float64", VAL, "fast"),
     ("float64", VAL, "fast-ema"), ("float64", VAL, "coarse")],
)
def test_killed_and_resumed_fit_is_bit_identical(tmp_path, dtype, val, recipe):
    """Validated fit in float64, the deployment shape (float32, no validation set), and
    the fast recipe, killed in its minibatch phase (its draws are a function of the step),
    also with a weight average (fast.ema: its state is saved and restored), and the coarse
    recipe, killed in its coarse phase."""
    cfg = _cfg(12, seed=3, checkpoint_every=4, dtype=dtype, recipe=recipe.split("-")[0])
    if recipe.startswith("fast"):
        cfg = with_overrides(cfg, fast={**FAST, "ema": 0.8 if recipe == "fast-ema" else 0.0})
    if recipe == "coarse":  # killed in its coarse phase
        cfg = with_overrides(cfg, coarse={"factor": 4, "epochs": 8, "val_every": 3,
                                          "finish_epochs": 4})
    ref = _fit(cfg, val=val)

    def killer(e):
        if e == 7:
            raise _KilledError

    with pytest.raises(_KilledError):
        _fit(cfg, val=val, out_dir=tmp_path, on_epoch=killer)
    assert train_state.exists(tmp_path)
    seen = []
    res = _fit(cfg, val=val, out_dir=tmp_path, resume=True, on_epoch=seen.append)
    assert seen == [5, 6, 7, 8, 9, 10, 11, 12]  # continued after the epoch-4 state
    assert _same_weights(res.model, ref.model)
    assert (res.best_epoch, res.best_value) == (ref.best_epoch, ref.best_value)
    assert _numbers(res.history) == _numbers(ref.history)
    cpu = [r["cpu_s"] for r in res.history.rows]  # carried across the kill
    assert all(x < y for x, y in itertools.pairwise(cpu))
    # a finished state resumes to the same result without training again
    again = _fit(cfg, val=val, out_dir=tmp_path, resume=True, on_epoch=seen.append)
    assert len(seen) == 8 and _same_weights(again.model, ref.model)


def test_resume_refuses_another_config_or_data(tmp_path):
    _fit(_cfg(2, seed=0, checkpoint_every=1), out_dir=tmp_path)
    with pytest.raises(CheckpointError, match="another config"):
        _fit(_cfg(2, seed=0, checkpoint_every=1, lr=1e-3), out_dir=tmp_path, resume=True)
    with pytest.raises(CheckpointError, match="another config"):
        _fit(_cfg(2, seed=0, checkpoint_every=1), val=VAL[:1], out_dir=tmp_path, resume=True)
    other = [make_trial(tr.n, seed=99, maneuver=tr.maneuver) for tr in TRAIN]
    with pytest.raises(CheckpointError, match="another config"):
        fit(other, VAL, _cfg(2, seed=0, checkpoint_every=1), out_dir=tmp_path, resume=True,
            progress=False)  # fmt: skip
    # the thread count is not part of the fingerprint
    _fit(_cfg(2, seed=0, checkpoint_every=1, threads=2), out_dir=tmp_path, resume=True)


def _flip(p):
    data = bytearray(p.read_bytes())
    data[-3] ^= 0xFF
    p.write_bytes(bytes(data))


def test_resume_uses_the_previous_generation_and_says_so_or_refuses(tmp_path, capsys):
    """A newest state damaged on disk: the previous generation (step 1) resumes, with a
    note; both damaged, or the JSON too: one-line refusals naming what is wrong."""
    cfg = _cfg(2, seed=0, checkpoint_every=1)
    ref = _fit(cfg)
    _fit(cfg, out_dir=tmp_path)
    assert (tmp_path / train_state.PREV_META).is_file()
    assert len(list(tmp_path.glob("train_state.*.safetensors"))) == 2  # two generations
    _flip(train_state.tensors_path(tmp_path))
    seen = []
    res = _fit(cfg, out_dir=tmp_path, resume=True, on_epoch=seen.append)
    assert seen == [2] and _same_weights(res.model, ref.model)  # from the step-1 state
    err = capsys.readouterr().err
    assert "corrupt or truncated" in err and "resuming from the previous one, step 1" in err
    for p in tmp_path.glob("train_state.*.safetensors"):  # now both generations
        _flip(p)
    with pytest.raises(CheckpointError, match="corrupt or truncated"):
        _fit(cfg, out_dir=tmp_path, resume=True)
    (tmp_path / train_state.META).write_text("{not json")
    with pytest.raises(CheckpointError, match="unreadable"):
        _fit(cfg, out_dir=tmp_path, resume=True)


def test_cosine_schedule():
    cfg = tiny_config(train={"epochs": 101, "lr": 2e-3, "lr_min": 1e-5})
    assert learning_rate(cfg, 1) == pytest.approx(2e-3, rel=1e-15)
    assert learning_rate(cfg, 101) == pytest.approx(1e-5, rel=1e-12)
    assert learning_rate(cfg, 51) == pytest.approx(0.5 * (2e-3 + 1e-5), rel=1e-12)
    # quarter point: lr_min + (lr - lr_min)(1 + cos(π/4))/2
    q = 1e-5 + (2e-3 - 1e-5) * (1 + math.cos(math.pi / 4)) / 2
    assert learning_rate(cfg, 26) == pytest.approx(q, rel=1e-12)
    lrs = [learning_rate(cfg, e) for e in range(1, 102)]
    assert all(a > b for a, b in itertools.pairwise(lrs))
    const = tiny_config(train={"epochs": 101, "schedule": "constant"})
    assert {learning_rate(const, e) for e in (1, 50, 101)} == {const.train.lr}
    assert tiny_config().train.lr == 2e-3 and tiny_config().train.epochs == 3200


def test_best_checkpoint_is_argmin_of_smoothed_criterion(monkeypatch):
    cfg = _cfg(14, seed=4, lr=2e-2)
    models, snaps = [], {}

    def snap(m):
        return {k: v.clone() for k, v in m.state_dict().items()}

    def build(*a, **k):  # keep a handle on the model being trained, and θ_1
        m = orig_build(*a, **k)
        models.append(m)
        snaps[1] = snap(m)
        return m

    def grab(e):  # on_epoch(e) runs after epoch e's step: the weights are θ_{e+1}
        snaps[e + 1] = snap(models[0])

    orig_build = train_mod.build_model
    monkeypatch.setattr(train_mod, "build_model", build)
    res = _fit(cfg, on_epoch=grab)
    h = res.history
    assert h.crit_epochs == [1, 3, 5, 7, 9, 11, 13, 14]  # every val_every and the last
    for i in range(len(h.crit_raw)):
        tail = h.crit_raw[max(0, i - 2) : i + 1]
        assert h.crit_smooth[i] == pytest.approx(sum(tail) / len(tail), rel=1e-15)
    i = min(range(len(h.crit_smooth)), key=lambda j: h.crit_smooth[j])
    assert res.best_epoch == h.crit_epochs[i] and res.best_value == h.crit_smooth[i]
    # the returned model holds θ at the best epoch
    best = snaps[res.best_epoch]
    assert all(torch.equal(v, best[k]) for k, v in res.model.state_dict().items())
    # and the criterion of epoch e was the validation loss of θ_e (before its step)
    m = res.model
    vb = make_batch(m, whole_trials(VAL), cfg.loss.blind_zone_kmh)
    for e, raw in zip(h.crit_epochs[:3], h.crit_raw[:3], strict=True):
        m.load_state_dict(snaps[e])
        assert validation_losses(m, vb, cfg)[0] == raw


def test_training_lowers_the_loss():
    res = _fit(_cfg(40, seed=0, lr=1e-2), val=())
    tot = [r["train_total"] for r in res.history.rows]
    assert res.history.criterion == "train_total"
    assert min(tot[-5:]) < 0.75 * tot[0]
    assert res.best_value < tot[0]
    assert res.n_windows == sum(math.ceil(tr.n / res.window_length) for tr in TRAIN)


def test_sample_rate_mismatch_raises():
    bad = make_trial(150, seed=1)
    bad.sample_rate_hz = 50.0
    with pytest.raises(DataError, match="sample rate"):
        fit([*TRAIN, bad], (), _cfg(1), progress=False)
    with pytest.raises(DataError, match="sample rate"):
        fit(TRAIN, [bad], _cfg(1), progress=False)
    with pytest.raises(DataError):
        fit([], (), _cfg(1), progress=False)


def test_a_finite_loss_with_a_non_finite_gradient_stops_that_step(monkeypatch, tmp_path):
    """The sensitivity of a long rollout can overflow where the rollout stays bounded (a
    coarse fit's first full-rate step, docs/nss.md): the step is refused, named, before
    Adam turns it into non-finite weights; the state saved before it is kept whole."""
    from parknss.errors import ParknssError

    real = train_mod.local_step

    def overflowing(model, batch, cfg, step, share=None):
        terms = real(model, batch, cfg, step, share)
        if step == 3:
            next(model.parameters()).grad[0, 0] = float("inf")
        return terms

    monkeypatch.setattr(train_mod, "local_step", overflowing)
    out = tmp_path / "fit"
    with pytest.raises(ParknssError, match=r"diverged at step 3: the loss is finite .* "
                                           r"gradient is not") as e:
        _fit(with_overrides(_cfg(6), train={"checkpoint_every": 1}), out_dir=out)
    assert "\n" not in str(e.value)
    import json

    assert json.loads((out / "train_state.json").read_text())["epoch"] == 2  # before it
