"""Training of the NSS model (paper §IV-B): BPTT through the full open-loop rollout.

Each step rolls out the sequences of its batch from their measured initial states and
backpropagates the loss of eq. 8 through every step of them (by default through the
fused Euler kernel of :mod:`parknss.nss.fused`). Which batch and learning rate a step
has is the recipe's (:mod:`parknss.nss.recipes`): the paper's (every training window at
once, Adam, cosine from 2e-3 to ``lr_min`` over the epoch cap) or the fast one.
Continuous best-checkpoint tracking on the smoothed criterion of
:mod:`parknss.nss.history`. One torch intra-op thread by default.

Order within step e (1-based; an epoch of the paper recipe): validation of the current
weights θ_e (when the recipe says, always at the last step), the training
forward/backward of θ_e, the history row (with the fit's CPU time so far, ``cpu_s``), a
snapshot of θ_e if the smoothed criterion is a new minimum, then the Adam step to
θ_{e+1}. Every ``checkpoint_every`` steps (and at the end) the whole state (weights,
best weights, Adam moments, RNG, history, wall and CPU time) is written to ``out_dir``
as ``train_state.safetensors`` + ``train_state.json``; a fit started with ``resume=True``
continues from there and ends bit-identically to an uninterrupted one (the minibatches
of the fast recipe are a function of the step, not of an RNG stream).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import torch

from parknss.data.normalize import Normalizer
from parknss.data.trial import Campaign, Trial
from parknss.data.windows import whole_trials, window_length
from parknss.errors import DataError, ParknssError
from parknss.nss import train_state
from parknss.nss.averaging import WeightAverage
from parknss.nss.batch import Batch, make_batch
from parknss.nss.config import NSSConfig
from parknss.nss.history import History
from parknss.nss.losses import output_loss, state_loss
from parknss.nss.model import NORMALIZED, NSSModel
from parknss.nss.parallel import DataParallelSteps
from parknss.nss.recipes import cosine, make_recipe
from parknss.nss.step import local_step
from parknss.vehicle import VehicleGeometry

DTYPES = {"float32": torch.float32, "float64": torch.float64}


@dataclass
class FitResult:
    """The best model of a fit and how it was found."""

    model: NSSModel
    config: NSSConfig
    history: History
    best_epoch: int
    best_value: float
    epochs_run: int
    wall_s: float
    window_length: int
    n_windows: int
    train_ids: list[str]
    val_ids: list[str]
    data_hash: str
    cpu_s: float | None = None
    recipe: str = "paper"

    def training_meta(self) -> dict:
        """JSON metadata for the model artefact."""
        return {
            "recipe": self.recipe,
            "epochs": self.epochs_run,
            "epoch_cap": self.config.train.epochs,
            "best_epoch": self.best_epoch,
            "best_criterion": self.best_value,
            "criterion": self.history.criterion,
            "wall_s": self.wall_s,
            "cpu_s": self.cpu_s,
            "seed": self.config.train.seed,
            "data_hash": self.data_hash,
            "window_length": self.window_length,
            "n_windows": self.n_windows,
            "train_trials": self.train_ids,
            "val_trials": self.val_ids,
        }


def learning_rate(cfg: NSSConfig, epoch: int) -> float:
    """LR of epoch (1-based) of the paper recipe: cosine from lr to lr_min over the cap, or
    constant."""
    t = cfg.train
    if t.schedule == "constant":
        return t.lr
    return cosine(epoch, t.epochs, t.lr, t.lr_min)


def check_trials(trials: Sequence[Trial], dt: float, who: str) -> None:
    """Every trial sampled at 1/dt (the model's integration step)."""
    for tr in trials:
        if abs(1.0 / tr.sample_rate_hz - dt) > 1e-9:
            raise DataError(
                f"trial {tr.id}: sample rate {tr.sample_rate_hz} Hz does not match the model "
                f"step dt = {dt} s ({who})"
            )
        if tr.n < 2:
            raise DataError(f"trial {tr.id}: fewer than 2 samples ({who})")


def build_model(cfg: NSSConfig, normalizer: Normalizer, geometry: VehicleGeometry) -> NSSModel:
    """A freshly initialised model, deterministic under cfg.train.seed."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(cfg.train.seed)
        model = NSSModel(cfg.model, normalizer, geometry)
    return model.to(DTYPES[cfg.train.dtype])


def validation_losses(model: NSSModel, batch: Batch, cfg: NSSConfig) -> tuple[float, float]:
    """(moving-region state loss, output loss) of whole-trial open-loop rollouts."""
    with torch.no_grad():
        r = model.rollout(batch.x0, batch.u)
        ls = state_loss(r, batch.targets, cfg.loss.kind, moving_yaw=True)
        ly = output_loss(r, batch.targets, cfg.loss.kind)
    return float(ls), float(ly)


class _LocalSteps:
    """The one-process step (:func:`parknss.nss.step.local_step`), shaped as
    :class:`~parknss.nss.parallel.DataParallelSteps` (no other process, no CPU time but
    this one's)."""

    worker_cpu_s = 0.0

    def __enter__(self) -> _LocalSteps:
        return self

    def __exit__(self, *exc) -> None:
        return None

    def __call__(self, model, batch, cfg, step):
        return local_step(model, batch, cfg, step)


def _check_gradient(model: NSSModel, step: int, loss: float) -> None:
    """Refuse a step whose loss is finite but whose gradient is not (the sensitivity of a
    long rollout can overflow the float range where the rollout itself stays bounded):
    Adam would turn it into non-finite weights, and the fit would fail one step later
    without saying why. One line, before the weights change."""
    grads = [p.grad for p in model.parameters() if p.grad is not None]
    if grads and not bool(torch.stack([g.abs().amax() for g in grads]).isfinite().all()):
        raise ParknssError(
            f"training diverged at step {step}: the loss is finite ({loss:.6g}) but its "
            f"gradient is not (the rollout's sensitivity overflows "
            f"{str(model.dtype).removeprefix('torch.')}); "
            "try another train.seed or recipe")


def _stepper(model: NSSModel, cfg: NSSConfig, steps_left: int):
    """The training step of this fit: data-parallel over ``train.processes`` processes
    (:mod:`parknss.nss.parallel`) or in this process alone (1, or nothing left to train)."""
    if cfg.train.processes > 1 and steps_left > 0:
        return DataParallelSteps(model, cfg, cfg.train.processes)
    return _LocalSteps()


def geometry_of(campaign: Campaign | None) -> VehicleGeometry:
    """The campaign's vehicle geometry (meta 'vehicle_geometry'), else the paper's."""
    g = (campaign.meta or {}).get("vehicle_geometry") if campaign is not None else None
    return VehicleGeometry.from_dict(g) if g else VehicleGeometry()


class _Threads:
    def __init__(self, n: int) -> None:
        self.n = n

    def __enter__(self):
        self.prev = torch.get_num_threads()
        torch.set_num_threads(self.n)

    def __exit__(self, *exc):
        torch.set_num_threads(self.prev)


def _progress(total: int, initial: int, enabled: bool):
    from tqdm import tqdm

    return tqdm(
        total=total, initial=initial, file=sys.stderr, disable=not enabled, desc="fit", unit="ep"
    )


def fit(
    train: Sequence[Trial],
    val: Sequence[Trial] = (),
    cfg: NSSConfig | None = None,
    geometry: VehicleGeometry | None = None,
    out_dir: str | Path | None = None,
    resume: bool = False,
    progress: bool = True,
    on_epoch: Callable[[int], None] | None = None,
) -> FitResult:
    """Train on ``train`` (best checkpoint on ``val``, or the training loss if empty).

    The fit is the recipe's Adam steps (``train.recipe``, :mod:`parknss.nss.recipes`: a
    paper step is one epoch, a fast phase-1 step one minibatch update). ``out_dir``
    receives the resumable state every ``checkpoint_every`` steps; ``resume=True``
    continues from it. ``on_epoch(k)`` is called after step k.
    """
    cfg = cfg or NSSConfig()
    train, val = list(train), list(val)
    if not train:
        raise DataError("no training trials")
    check_trials(train, cfg.model.dt, "training")
    check_trials(val, cfg.model.dt, "validation")
    with _Threads(cfg.train.threads):
        return _fit(
            train, val, cfg, geometry or VehicleGeometry(), out_dir, resume, progress, on_epoch
        )


def _fit(train, val, cfg, geometry, out_dir, resume, progress, on_epoch) -> FitResult:
    t0, c0 = time.perf_counter(), time.process_time()
    norm = Normalizer.fit(train, NORMALIZED, cfg.data.normalizer, cfg.data.clip_percentiles)
    L = window_length([tr.n for tr in train], cfg.data.window)
    model = build_model(cfg, norm, geometry)
    recipe = make_recipe(cfg, model, train, L)
    vbatch = make_batch(model, whole_trials(val), cfg.loss.blind_zone_kmh) if val else None
    data_hash = Campaign(train + val).data_hash()
    fp = train_state.fingerprint(cfg, data_hash, [t.id for t in train], [t.id for t in val], L)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.train.lr)
    crit = "val_state_moving" if val else "train_total"
    hist = History(crit, cfg.train.smooth_window)
    best_state: dict[str, torch.Tensor] | None = None
    avg = None  # fast.ema: validate and keep a moving average of the weights
    if recipe.name == "fast" and cfg.fast.ema > 0:
        avg = WeightAverage(model, cfg.fast.ema)
    start, wall_before, cpu_before = 0, 0.0, 0.0
    out = Path(out_dir) if out_dir is not None else None
    if resume and out is not None and train_state.exists(out):
        st = train_state.load(out, model, opt, fp)
        start, hist, best_state = st.epoch, st.history, st.best
        wall_before, cpu_before = st.wall_s, st.cpu_s
        if avg is not None:
            if st.avg is None:
                raise ParknssError(f"{out}: the training state lacks the weight average")
            avg.load(st.avg)
    best_epoch, best_value = hist.best()
    E = recipe.steps
    bar = _progress(E, start, progress)
    stepper = _stepper(model, cfg, E - start)

    def cpu_now() -> float:  # this fit's CPU time so far: its process and its workers'
        return cpu_before + time.process_time() - c0 + stepper.worker_cpu_s

    try:
        with stepper as train_step:
            for e in range(start + 1, E + 1):
                step = recipe.step(e)
                for g in opt.param_groups:
                    g["lr"] = step.lr
                row: dict = {"epoch": e, "lr": step.lr}
                if recipe.name != "paper":
                    row["phase"] = step.phase
                smoothed = None
                if vbatch is not None and step.validate:
                    if avg is None:
                        vs, vy = validation_losses(model, vbatch, cfg)
                    else:
                        with avg.swapped_in(model):
                            vs, vy = validation_losses(model, vbatch, cfg)
                    row.update(val_state_moving=vs, val_output=vy)
                    smoothed = hist.add_criterion(e, vs)
                opt.zero_grad(set_to_none=True)
                terms = train_step(model, step.batch, cfg, e)  # forward + backward into .grad
                row.update({f"train_{k}": v for k, v in terms.items()})
                if vbatch is None and step.full:
                    smoothed = hist.add_criterion(e, row["train_total"])
                if cpu_before is not None:
                    row["cpu_s"] = cpu_now()
                hist.add_row(row)
                if smoothed is not None and smoothed < best_value:
                    best_epoch, best_value = e, smoothed
                    best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
                    if avg is not None:
                        best_state.update({k: v.clone() for k, v in avg.avg.items()})
                _check_gradient(model, e, row["train_total"])
                opt.step()
                if avg is not None:
                    avg.update(model)
                if out is not None and (e % cfg.train.checkpoint_every == 0 or e == E):
                    wall = wall_before + time.perf_counter() - t0
                    cpu = None if cpu_before is None else cpu_now()
                    train_state.save(out, model, opt, hist, best_state, e, wall, fp, cpu,
                                     None if avg is None else avg.avg)
                bar.update(1)
                bar.set_postfix(loss=f"{row['train_total']:.4f}", best=best_epoch)
                if on_epoch is not None:
                    on_epoch(e)
    finally:
        bar.close()
    if best_state is not None:
        model.load_state_dict(best_state)
    return FitResult(
        model=model,
        config=cfg,
        history=hist,
        best_epoch=best_epoch,
        best_value=best_value,
        epochs_run=E,
        wall_s=wall_before + time.perf_counter() - t0,
        window_length=L,
        n_windows=recipe.full.n,
        cpu_s=None if cpu_before is None else cpu_now(),
        recipe=recipe.name,
        train_ids=[t.id for t in train],
        val_ids=[t.id for t in val],
        data_hash=data_hash,
    )
