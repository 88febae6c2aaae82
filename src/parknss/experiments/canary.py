"""The canary: a few tiny deterministic fits whose exact results stand for the training code.

The result store keys every fit by the training-code version
(:func:`~parknss.experiments.store.code_version`), a hash of the code of
:data:`~parknss.experiments.store.CODE_FILES`: any code edit there (an atomic write, a
range check, a new option that defaults to the old behaviour) makes every stored fit miss,
although it changes no number. The canary tells the two apart: :func:`run_canary` runs
:data:`CASES`, one tiny fit per code path the stored fits use (both recipes; MAE, MSE and
log-cosh losses; cosine and constant schedules; the shortest-trial and a fixed window;
Euler through the fused and the eager engine, midpoint and RK4; the clipped, min-max and
z-score normalizers; residual and direct yaw readout; 2 to 3 hidden layers; the cv and
the leave-r-out splits; the linear baseline; the limiter job; a fit interrupted after a
checkpoint and resumed from its training state), on a slice of the default campaign
(:data:`SLICE`: every trial cut to a few seconds), a few steps each, and hashes what they
produce: each fit's final weights (the bytes of ``model.safetensors``), its validation
history, best epoch and scores, with wall and CPU times left out (:func:`strip_times`).

Bit-identical results under two code versions on the same kind of machine (CPU model:
floating-point results differ across CPUs) are taken as evidence that the two compute
the same numbers; :mod:`parknss.experiments.lineage` records them, and the store then
accepts fits of either. The canary's own definition is part of its digest
(:func:`spec_digest`), so a changed case set is never compared with an old one.
Not in ``CODE_FILES`` itself: editing it changes no stored fit.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from parknss.errors import ParknssError

CANARY_FORMAT = 1
"""Bumped when what :func:`run_canary` hashes changes (not the cases: those are in
:func:`spec_digest`)."""

SLICE: tuple[int, int] = (600, 900)
"""Samples [start, stop) kept of every trial of the default campaign (3 s at 100 Hz)."""

TINY: dict[str, dict] = {
    "model": {"state_layers": 2, "state_units": 16, "output_layers": 1, "output_units": 16},
    "train": {"epochs": 4, "val_every": 1, "smooth_window": 2, "checkpoint_every": 2,
              "threads": 1},
    "fast": {"window": 100, "batch": 2, "updates": 4, "val_every": 2, "finish_epochs": 2},
}
"""The overrides every NSS case starts from: a net of 2x16 and 1x16 units, 4 steps."""

CASES: dict[str, dict[str, Any]] = {
    "paper_fused_mae": {"overrides": {}},
    "paper_eager_mse_constant_minmax": {"overrides": {
        "model": {"engine": "eager"}, "loss": {"kind": "mse"},
        "train": {"schedule": "constant", "lr": 0.004}, "data": {"normalizer": "minmax"}}},
    "paper_midpoint_logcosh_zscore_direct": {"index": 1, "overrides": {
        "model": {"integrator": "midpoint", "residual_yaw": False},
        "loss": {"kind": "logcosh"}, "train": {"seed": 1}, "data": {"normalizer": "zscore"}}},
    "paper_rk4_window_deep": {"index": 2, "overrides": {
        "model": {"integrator": "rk4", "state_layers": 3},
        "train": {"lr": 0.001}, "data": {"window": 200}}},
    "fast_recipe": {"index": 3, "overrides": {"train": {"recipe": "fast"}}},
    "leave_r2": {"split": "leave", "r": 2, "overrides": {"train": {"seed": 2}}},
    "linear": {"model": "linear"},
    "limiter": {"job": "limiter", "index": 1, "overrides": {}},
    "resumed": {"job": "resume", "stop_after": 2, "overrides": {}},
}
"""Name -> fold-job arguments (``overrides`` merged over :data:`TINY`); ``job``:
``fold`` (default), ``limiter`` (:func:`~parknss.experiments.folds.limiter_job`) or
``resume`` (the fold's fit stopped after step ``stop_after``, then resumed)."""

TIME_FIELDS = ("wall_s", "cpu_s", "model_dir")


@dataclass
class CanaryResult:
    """The canary's ``digest`` (hex), one digest per case, the digest of the case
    definitions it ran (``spec``) and how long it took (s, not hashed)."""

    digest: str
    cases: dict[str, str]
    spec: str
    seconds: float
    details: dict[str, Any] = field(default_factory=dict, repr=False)


def spec_digest(names: list[str] | None = None) -> str:
    """Hash of what the canary runs: its format, slice, base overrides and cases (all, or
    ``names``: a canary of some cases is never compared with one of all)."""
    cases = CASES if names is None else {n: CASES[n] for n in names}
    doc = {"format": CANARY_FORMAT, "slice": SLICE, "tiny": TINY, "cases": cases}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:16]


def _merge(base: dict, extra: dict) -> dict:
    out = {k: dict(v) for k, v in base.items()}
    for sec, vals in extra.items():
        out.setdefault(sec, {}).update(vals)
    return out


def strip_times(doc: Any) -> Any:
    """``doc`` without its timing fields (:data:`TIME_FIELDS`, at any depth), which
    differ from run to run."""
    if isinstance(doc, dict):
        return {k: strip_times(v) for k, v in doc.items() if k not in TIME_FIELDS}
    if isinstance(doc, list):
        return [strip_times(v) for v in doc]
    return doc


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def write_slice(folder: Path) -> Path:
    """Write the canary's campaign (:data:`SLICE` of each trial of the default campaign)
    to ``folder``; returns it."""
    from parknss.data.io import write_campaign
    from parknss.data.trial import Campaign
    from parknss.nss.campaigns import default_campaign

    full = default_campaign()
    a, b = SLICE
    if min(tr.n for tr in full) < b:
        raise ParknssError(f"the default campaign has a trial shorter than {b} samples: "
                           "the canary cannot slice it")
    cut = Campaign([tr.slice(a, b) for tr in full], name="canary", meta=dict(full.meta))
    return write_campaign(cut, folder, overwrite=True)


def _weights(folder: Path) -> str:
    return _sha((folder / "model.safetensors").read_bytes())


def _resumed(kwargs: dict, stop_after: int, tmp: Path) -> dict:
    """The fold's fit stopped (an exception) after step ``stop_after`` and resumed from its
    training state; its weights and history hashed, and whether they equal an
    uninterrupted fit's."""
    from parknss.experiments.folds import fold_config, make_fold
    from parknss.nss.campaigns import load_campaign
    from parknss.nss.checkpoint import save_model
    from parknss.nss.train import fit, geometry_of

    class _StopError(Exception):
        pass

    def stop(e: int) -> None:
        if e == stop_after:
            raise _StopError

    campaign = load_campaign(kwargs["data"])
    fold = make_fold(campaign, "cv", 0)
    train = [campaign[i] for i in fold.train]
    val = [campaign[i] for i in fold.val]
    cfg = fold_config(None, kwargs["overrides"])
    state = tmp / "state"
    with contextlib.suppress(_StopError):
        fit(train, val, cfg, geometry_of(campaign), out_dir=state, progress=False, on_epoch=stop)
    res = fit(train, val, cfg, geometry_of(campaign), out_dir=state, resume=True, progress=False)
    save_model(tmp / "resumed", res.model, cfg, res.training_meta())
    whole = fit(train, val, cfg, geometry_of(campaign), progress=False)
    save_model(tmp / "whole", whole.model, cfg, whole.training_meta())
    return {"weights": _weights(tmp / "resumed"),
            "history": strip_times(res.history.rows), "best_epoch": res.best_epoch,
            "same_as_uninterrupted": _weights(tmp / "resumed") == _weights(tmp / "whole")}


def run_case(name: str, data: Path, tmp: Path) -> dict:
    """Run case ``name`` of :data:`CASES` on the campaign folder ``data``; its result
    without times, with its final weights' SHA-256 (NSS cases)."""
    from parknss.experiments.folds import fold_job, limiter_job

    spec = dict(CASES[name])
    kind = spec.pop("job", "fold")
    stop_after = spec.pop("stop_after", None)
    kwargs = {"data": str(data), **spec}
    if "overrides" in kwargs:
        kwargs["overrides"] = _merge(TINY, kwargs["overrides"])
    out = tmp / name
    out.mkdir()
    if kind == "resume":
        return _resumed(kwargs, int(stop_after), out)
    if kind == "limiter":
        return strip_times(limiter_job(**kwargs))
    result = strip_times(fold_job(**kwargs, save_dir=str(out / "model")
                                  if kwargs.get("model", "nss") == "nss" else None))
    if kwargs.get("model", "nss") == "nss":
        result["weights"] = _weights(out / "model")
    return result


def run_canary(names: list[str] | None = None) -> CanaryResult:
    """Run the canary (every case, or ``names``) in a temporary folder; its digest."""
    t0 = time.perf_counter()
    names = list(CASES) if names is None else names
    unknown = [n for n in names if n not in CASES]
    if unknown:
        raise ParknssError(f"no canary case {unknown[0]!r} (cases: {', '.join(CASES)})")
    details: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="parknss-canary-") as tmp:
        data = write_slice(Path(tmp) / "campaign")
        from parknss.data.io import read_campaign

        details["data_hash"] = read_campaign(data).data_hash()
        for n in names:
            details[n] = run_case(n, data, Path(tmp))
    cases = {n: _sha(json.dumps(v, sort_keys=True).encode())[:16] for n, v in details.items()}
    spec = spec_digest(None if names == list(CASES) else names)
    doc = {"format": CANARY_FORMAT, "spec": spec, "cases": cases}
    digest = _sha(json.dumps(doc, sort_keys=True).encode())[:16]
    return CanaryResult(digest, cases, spec, time.perf_counter() - t0, details)
