"""Training of the NSS model (paper §IV-B): BPTT through the full open-loop rollout.

All training windows are rolled out at once from their measured initial states and the
loss of eq. 8 is backpropagated through every step (by default through the fused Euler
kernel of :mod:`parknss.nss.fused`). Adam, cosine learning rate from 2e-3 to ``lr_min``
over the epoch cap, continuous best-checkpoint tracking on the smoothed criterion of
:mod:`parknss.nss.history`. One torch intra-op thread by default.

Order within epoch e (1-based): validation of the current weights θ_e (every
``val_every`` epochs and at the last), the training forward/backward of θ_e, the history
row, a snapshot of θ_e if the smoothed criterion is a new minimum, then the Adam step to
θ_{e+1}. Every ``checkpoint_every`` epochs (and at the end) the whole state (weights,
best weights, Adam moments, RNG, history) is written to ``out_dir`` as
``train_state.safetensors`` + ``train_state.json``; a fit started with ``resume=True``
continues from there and ends bit-identically to an uninterrupted one.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import torch

from parknss.data.normalize import Normalizer
from parknss.data.trial import Campaign, Trial
from parknss.data.windows import make_windows, whole_trials, window_length
from parknss.errors import DataError, ParknssError
from parknss.nss import train_state
from parknss.nss.batch import Batch, make_batch
from parknss.nss.config import NSSConfig
from parknss.nss.history import History
from parknss.nss.losses import LossTerms, nss_loss, output_loss, state_loss
from parknss.nss.model import NORMALIZED, NSSModel
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

    def training_meta(self) -> dict:
        """JSON metadata for the model artefact."""
        return {
            "epochs": self.epochs_run,
            "epoch_cap": self.config.train.epochs,
            "best_epoch": self.best_epoch,
            "best_criterion": self.best_value,
            "criterion": self.history.criterion,
            "wall_s": self.wall_s,
            "seed": self.config.train.seed,
            "data_hash": self.data_hash,
            "window_length": self.window_length,
            "n_windows": self.n_windows,
            "train_trials": self.train_ids,
            "val_trials": self.val_ids,
        }


def learning_rate(cfg: NSSConfig, epoch: int) -> float:
    """LR of epoch (1-based): cosine from lr to lr_min over the cap, or constant."""
    t = cfg.train
    if t.schedule == "constant" or t.epochs <= 1:
        return t.lr
    frac = (epoch - 1) / (t.epochs - 1)
    return t.lr_min + 0.5 * (t.lr - t.lr_min) * (1.0 + math.cos(math.pi * frac))


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


def epoch_loss(
    model: NSSModel, batch: Batch, cfg: NSSConfig, engine: str | None = None
) -> LossTerms:
    """Roll out every sequence of the batch and evaluate eq. 8."""
    r = model.rollout(batch.x0, batch.u, engine=engine)
    return nss_loss(r, batch.targets, cfg.loss, model.vx_zero_s())


def validation_losses(model: NSSModel, batch: Batch, cfg: NSSConfig) -> tuple[float, float]:
    """(moving-region state loss, output loss) of whole-trial open-loop rollouts."""
    with torch.no_grad():
        r = model.rollout(batch.x0, batch.u)
        ls = state_loss(r, batch.targets, cfg.loss.kind, moving_yaw=True)
        ly = output_loss(r, batch.targets, cfg.loss.kind)
    return float(ls), float(ly)


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

    ``out_dir`` receives the resumable state every ``checkpoint_every`` epochs;
    ``resume=True`` continues from it. ``on_epoch(e)`` is called after each epoch.
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
    t0 = time.perf_counter()
    norm = Normalizer.fit(train, NORMALIZED, cfg.data.normalizer, cfg.data.clip_percentiles)
    L = window_length([tr.n for tr in train], cfg.data.window)
    model = build_model(cfg, norm, geometry)
    batch = make_batch(model, make_windows(train, L), cfg.loss.blind_zone_kmh)
    vbatch = make_batch(model, whole_trials(val), cfg.loss.blind_zone_kmh) if val else None
    data_hash = Campaign(train + val).data_hash()
    fp = train_state.fingerprint(cfg, data_hash, [t.id for t in train], [t.id for t in val], L)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.train.lr)
    crit = "val_state_moving" if val else "train_total"
    hist = History(crit, cfg.train.smooth_window)
    best_state: dict[str, torch.Tensor] | None = None
    start, wall_before = 0, 0.0
    out = Path(out_dir) if out_dir is not None else None
    if resume and out is not None and train_state.exists(out):
        st = train_state.load(out, model, opt, fp)
        start, hist, best_state, wall_before = st.epoch, st.history, st.best, st.wall_s
    best_epoch, best_value = hist.best()
    E = cfg.train.epochs
    bar = _progress(E, start, progress)
    try:
        for e in range(start + 1, E + 1):
            lr = learning_rate(cfg, e)
            for g in opt.param_groups:
                g["lr"] = lr
            row: dict = {"epoch": e, "lr": lr}
            smoothed = None
            if vbatch is not None and ((e - 1) % cfg.train.val_every == 0 or e == E):
                vs, vy = validation_losses(model, vbatch, cfg)
                row.update(val_state_moving=vs, val_output=vy)
                smoothed = hist.add_criterion(e, vs)
            opt.zero_grad(set_to_none=True)
            terms = epoch_loss(model, batch, cfg)
            if not torch.isfinite(terms.total):
                raise ParknssError(f"training diverged at epoch {e} (loss {float(terms.total)})")
            terms.total.backward()
            row.update({f"train_{k}": v for k, v in terms.as_floats().items()})
            del terms  # frees the graph now, so the fused kernels' buffers are recycled
            if vbatch is None:
                smoothed = hist.add_criterion(e, row["train_total"])
            hist.add_row(row)
            if smoothed is not None and smoothed < best_value:
                best_epoch, best_value = e, smoothed
                best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
            opt.step()
            if out is not None and (e % cfg.train.checkpoint_every == 0 or e == E):
                wall = wall_before + time.perf_counter() - t0
                train_state.save(out, model, opt, hist, best_state, e, wall, fp)
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
        n_windows=batch.n,
        train_ids=[t.id for t in train],
        val_ids=[t.id for t in val],
        data_hash=data_hash,
    )
