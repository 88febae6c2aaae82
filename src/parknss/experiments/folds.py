"""One cross-validation fold as an executor job: fit on its training trials, score held out.

:func:`fold_job` is the unit every NSS study is made of (Table II, the learning curve, the
seed-noise floor, the ablations, the limiter study): it loads the campaign, builds the
split (``split="cv"``: the stratified k-fold of :func:`~parknss.data.splits.stratified_folds`;
``split="leave"``: the leave-r-repeats-out grid; on a campaign that is not stratifiable,
unlabelled trials or too few per class, their plain k-fold fallbacks of
:func:`~parknss.data.splits.cv_plan` / :func:`~parknss.data.splits.leave_r_out_plan`),
fits the model named by ``model`` and rolls it out open loop over every held-out trial's
whole length. Its arguments and its result are plain JSON, so the same job runs
in-process, on the local pool or on Ray and is cached by the executor under the hash of
its arguments.

:func:`limiter_job` is the same fit scored three ways (without the inference limiter and
with its two forms), the unit of the limiter study.

Models: ``"nss"`` (the NSS with the given config overrides), ``"linear"`` (the
least-squares linear state-space baseline of :mod:`parknss.nss.linear`). The direct-yaw
NSS is ``"nss"`` with ``{"model": {"residual_yaw": false}}``.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from parknss.config import override
from parknss.data.splits import Fold, FoldPlan, cv_plan, leave_r_out_plan
from parknss.data.trial import Campaign, Trial
from parknss.errors import ConfigError
from parknss.metrics.errors import logged_and_truth_errors
from parknss.nss.campaigns import load_campaign
from parknss.nss.config import NSSConfig, load_nss_config

MODELS: tuple[str, ...] = ("nss", "linear")


@dataclass
class FoldResult:
    """What one fold reports (JSON-ready).

    errors: :class:`~parknss.metrics.errors.OpenLoopErrors` as JSON against the logged
    channels; truth_errors: the same against the noise-free truth channels when the
    campaign has them (synthetic), else None. NSS only: best_epoch, epochs, the history
    of the validation criterion (steps, raw and smoothed moving-region state loss, the
    output loss and the fit's CPU time in s at the same steps), the window length, the
    training recipe and the fit's CPU time (s; None if a resumed state lacked it).
    """

    split: str
    index: int
    model: str
    train: list[str]
    val: list[str]
    errors: dict
    truth_errors: dict | None
    wall_s: float
    best_epoch: int | None = None
    epochs: int | None = None
    window_length: int | None = None
    n_windows: int | None = None
    history: dict | None = None
    model_dir: str | None = None
    recipe: str | None = None
    cpu_s: float | None = None

    def to_json(self) -> dict:
        return asdict(self)


def fold_plan(campaign: Campaign, split: str, r: int = 1, seed: int | None = None) -> FoldPlan:
    """The folds of ``split`` ("cv", or "leave" with r held-out repeats per class), with the
    plain k-fold fallback for a campaign that is not stratifiable (see FoldPlan.note)."""
    if split == "cv":
        return cv_plan(campaign, seed=seed)
    if split == "leave":
        return leave_r_out_plan(campaign, r, seed=seed)
    raise ConfigError(f"split must be 'cv' or 'leave', got {split!r}")


def make_fold(
    campaign: Campaign, split: str, index: int, r: int = 1, seed: int | None = None
) -> Fold:
    """The fold ``index`` of :func:`fold_plan`."""
    folds = fold_plan(campaign, split, r, seed).folds
    if not 0 <= index < len(folds):
        raise ConfigError(f"fold index {index} out of range 0..{len(folds) - 1}")
    return folds[index]


_READ: dict[str, NSSConfig] = {}
"""The NSS config files this process has read, by resolved path ("" the shipped one)."""


def fold_config(config: str | None, overrides: dict | None) -> NSSConfig:
    """The NSS config: a YAML file (default: the shipped configs/nss.yaml, the paper's
    values) with per-section overrides, e.g. ``{"train": {"epochs": 30}}``.

    Each file is read once per process: a study that runs for hours keeps the config it
    read at its start, when it stores its fits too, even if the file (or the shipped file,
    by an upgrade of the checkout) changes under it meanwhile."""
    key = str(Path(config).resolve()) if config else ""
    base = _READ.get(key)
    if base is None:
        base = _READ[key] = load_nss_config(config)
    return override(base, overrides or None, source=str(config or "configs/nss.yaml"))


def fold_job(
    split: str = "cv",
    index: int = 0,
    r: int = 1,
    model: str = "nss",
    data: str | None = None,
    config: str | None = None,
    overrides: dict | None = None,
    split_seed: int | None = None,
    save_dir: str | None = None,
    progress: bool = False,
    state_dir: str | None = None,
) -> dict[str, Any]:
    """Fit one fold and score its held-out trials; returns :class:`FoldResult` as JSON.

    Args:
        split, index, r, split_seed: which fold (see :func:`make_fold`).
        model: "nss" or "linear".
        data: campaign folder (None: the default campaign).
        config, overrides: NSS config YAML and section overrides, e.g.
            ``{"train": {"epochs": 300, "seed": 1}, "model": {"residual_yaw": False}}``.
        save_dir: if given, the fitted NSS is saved there (model.safetensors + model.json).
        state_dir: if given, the fit checkpoints its training state there every
            ``train.checkpoint_every`` epochs and a later call with the same fold and
            config resumes from it (a fold of a study run across several sittings); a
            state of another fit is refused by the fit's fingerprint check.
    """
    if model not in MODELS:
        raise ConfigError(f"model must be one of {', '.join(MODELS)}, got {model!r}")
    campaign = load_campaign(data)
    fold = make_fold(campaign, split, index, r, split_seed)
    train = [campaign[i] for i in fold.train]
    val = [campaign[i] for i in fold.val]
    t0 = time.perf_counter()
    head = (fold.name, index, model, list(fold.train), list(fold.val))
    if model == "linear":
        from parknss.nss.linear import LinearSSM

        lin = LinearSSM.fit(train)
        logged, truth = logged_and_truth_errors(lin.predict_trials(val), val)
        return FoldResult(*head, logged, truth, time.perf_counter() - t0).to_json()
    from parknss.nss.checkpoint import save_model
    from parknss.nss.predict import predict_trials
    from parknss.nss.train import fit, geometry_of

    cfg = fold_config(config, overrides)
    resume = state_dir is not None and (Path(state_dir) / "train_state.json").is_file()
    fit_on, select_on = train, val  # the paper's protocol: the checkpoint on the scored trials
    if cfg.train.selection == "inner":
        fit_on, select_on = inner_split(train)
    res = fit(fit_on, select_on, cfg, geometry_of(campaign), progress=progress,
              out_dir=Path(state_dir) if state_dir is not None else None, resume=resume)
    logged, truth = logged_and_truth_errors(predict_trials(res.model, val), val, res.window_length)
    h = res.history
    saved = None
    if save_dir is not None:
        saved = str(save_model(Path(save_dir), res.model, cfg, res.training_meta()))
    doc = FoldResult(
        *head,
        logged,
        truth,
        res.wall_s,
        best_epoch=res.best_epoch,
        epochs=res.epochs_run,
        window_length=res.window_length,
        n_windows=res.n_windows,
        history={
            "epochs": h.crit_epochs,
            "raw": h.crit_raw,
            "smooth": h.crit_smooth,
            "output": [row.get("val_output") for row in h.rows if "val_output" in row],
            "cpu_s": [row.get("cpu_s") for row in h.rows if "val_output" in row],
        },
        recipe=res.recipe,
        cpu_s=res.cpu_s,
        model_dir=saved,
    ).to_json()
    if select_on is not val:
        doc["fitted_on"], doc["selected_on"] = [t.id for t in fit_on], [t.id for t in select_on]
    return doc


def inner_split(train: list[Trial]) -> tuple[list[Trial], list[Trial]]:
    """The training trials split for inner-validation selection: the last trial of each
    maneuver class that has at least two held out for choosing the checkpoint, the rest
    fitted (unlabelled trials count as one class). Deterministic; a ConfigError when no
    class has two trials."""
    last: dict[str, int] = {}
    count: dict[str, int] = {}
    for i, tr in enumerate(train):
        last[tr.maneuver] = i
        count[tr.maneuver] = count.get(tr.maneuver, 0) + 1
    held = {i for c, i in last.items() if count[c] >= 2}
    if not held:
        raise ConfigError("train.selection=inner needs a maneuver class with two training "
                          "trials to hold one out")
    return ([tr for i, tr in enumerate(train) if i not in held],
            [tr for i, tr in enumerate(train) if i in held])


VARIANTS: tuple[str, ...] = ("none", "reconstructed", "residual")
"""The limiter variants of :func:`limiter_job` (paper §V-B)."""


def limiter_job(**fold_kwargs: Any) -> dict[str, Any]:
    """Fit a fold (:func:`fold_job`), then score the same model under each limiter variant:
    none, clamping the reconstructed yaw rate, clamping the residual channel (the limiter
    study, :mod:`parknss.experiments.limiter_study`).

    Returns ``{"fold": FoldResult JSON, "variants": {variant: OpenLoopErrors JSON}}``.
    """
    from parknss.metrics.errors import open_loop_errors
    from parknss.nss.campaigns import load_campaign
    from parknss.nss.checkpoint import load_model
    from parknss.nss.config import LimiterConfig
    from parknss.nss.predict import predict_trials

    with tempfile.TemporaryDirectory(prefix="parknss-limiter-") as tmp:
        fold = fold_job(**fold_kwargs, save_dir=tmp)
        model = load_model(tmp).model
    campaign = load_campaign(fold_kwargs.get("data"))
    f = make_fold(
        campaign,
        fold_kwargs.get("split", "cv"),
        fold_kwargs.get("index", 0),
        fold_kwargs.get("r", 1),
        fold_kwargs.get("split_seed"),
    )
    val = [campaign[i] for i in f.val]
    variants = {}
    for v in VARIANTS:
        lim = None if v == "none" else LimiterConfig(enabled=True, mode=v)
        pred = predict_trials(model, val, limiter=lim)
        variants[v] = open_loop_errors(pred, val, fold["window_length"]).to_json()
    fold["model_dir"] = None
    return {"fold": fold, "variants": variants}
