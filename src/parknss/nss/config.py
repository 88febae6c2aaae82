"""Configuration of the NSS model, its losses, data preparation and training (paper §II, §IV-B).

Every default is the paper's; ``configs/nss.yaml`` lists them all. A YAML file overrides
any subset, section by section (``model``, ``loss``, ``data``, ``train``, ``fast``,
``coarse``, ``limiter``). The ``fast`` and ``coarse`` sections are this toolkit's training
recipes, not the paper's.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from parknss.config import StrictModel, load_config, override, parse_set
from parknss.signals import BLIND_ZONE_KMH, DT

FusedKernels = Literal["reference", "fast", "native"]
FUSED_KERNELS: tuple[str, ...] = FusedKernels.__args__
"""The fused engine's kernel sets (``model.fused_kernels``; :data:`parknss.nss.fused.KERNELS`)."""


class ModelConfig(StrictModel):
    """Architecture (§II): state net f on [x̂, u] -> dx/dt, output net g -> [ax, ay]."""

    state_layers: int = Field(6, ge=1, description="hidden layers of the state network")
    state_units: int = Field(128, ge=1, description="units per hidden layer of the state net")
    output_layers: int = Field(3, ge=1, description="hidden layers of the output network")
    output_units: int = Field(128, ge=1, description="units per hidden layer of the output net")
    activation: Literal["tanh"] = "tanh"
    integrator: Literal["euler", "midpoint", "rk4"] = "euler"
    residual_yaw: bool = Field(
        True, description="state [vx, ω_res], yaw read out as ω_ref + ω_res (False: direct yaw)"
    )
    dt: float = Field(DT, gt=0.0, description="integration step, s (the log's sample interval)")
    engine: Literal["auto", "fused", "eager"] = Field(
        "auto",
        description="recurrence engine: fused (whole-rollout autograd.Function, Euler only), "
        "eager (plain per-step autograd loop), auto (fused when possible)",
    )
    fused_kernels: FusedKernels = Field(
        "reference",
        description="arithmetic of the fused engine: reference (the rounding the stored fits "
        "were made with), fast (the same functions by cheaper kernels, tanh as 2σ(2a)-1; "
        "rounded differently, measured against float64 in docs/nss.md) or native (the "
        "reference formulation in C built for this machine, the per-step loops, their "
        "gradients and the output net; float32 only; rounded its own way)",
    )


class LossConfig(StrictModel):
    """Training objective (eq. 8): masked state loss + output loss + λ·physics terms."""

    # added after run folders and fits in progress existed: their digests stay as before
    omit_at_default = frozenset(
        {"blind_zone", "blind_zone_width_kmh", "lambda_torque", "torque_gain_min",
         "torque_step_nm", "torque_prior_states", "torque_prior_samples", "lambda_decouple",
         "decouple_tolerance_ms2"}
    )
    kind: Literal["mae", "mse", "logcosh"] = "mae"
    lambda_vx: float = Field(0.1, ge=0.0, description="weight of the gear-conditioned vx loss")
    lambda_yaw: float = Field(0.5, ge=0.0, description="weight of the yaw-prior loss")
    blind_zone_kmh: float = Field(
        BLIND_ZONE_KMH, ge=0.0, description="the wheel-speed blind zone: a measured |vx| below "
        "this is a blind-zone sample (masked out of the state loss, or observed)"
    )
    blind_zone: Literal["mask", "observe"] = Field(
        "mask",
        description="mask: blind-zone samples leave the vx state loss (the paper's); observe: "
        "they enter it through the sensor's observation model (the predicted reading of v̂x, "
        "~0 inside the zone, must match the logged 0; nss/losses.py)",
    )
    blind_zone_width_kmh: float = Field(
        0.05, gt=0.0, description="observe: width of the smooth sensor gate around the zone "
        "edge, km/h (the reading is v·σ((|v| − zone)/width))"
    )
    lambda_torque: float = Field(
        0.0, ge=0.0, description="weight of the torque-gain prior (0: off, the paper's): on "
        "moving samples in gear, more drive torque must not decelerate the car (nss/losses.py)"
    )
    torque_gain_min: float = Field(
        0.0, ge=0.0, description="torque-gain prior: the least gear·∂(dvx/dt)/∂τ demanded, "
        "(m/s²)/(N·m) (0: monotone only; the reference car's i/(r·m) is 0.0119)"
    )
    torque_step_nm: float = Field(
        10.0, gt=0.0, description="torque-gain prior: the finite-difference torque step, N·m"
    )
    torque_prior_states: Literal["logged", "envelope", "both"] = Field(
        "logged", description="torque-gain prior: where it is evaluated: logged (the "
        "rollout's moving samples in gear), envelope (seeded states and inputs drawn over "
        "the normalizer's range, brake released: the steady torque above what a speed needs "
        "that a speed-controlling driver never logs) or both (the mean of the two)"
    )
    torque_prior_samples: int = Field(
        2048, ge=2, le=1_000_000, description="torque-gain prior, envelope: the number of "
        "drawn (state, input) points, half in each drive gear, fixed for a fit (train.seed)"
    )
    lambda_decouple: float = Field(
        0.0, ge=0.0, description="weight of the yaw-state decoupling prior (0: off, the "
        "paper's): at the envelope's points, the longitudinal acceleration must not move "
        "with the second state (yaw residual or yaw rate) by more than decouple_tolerance_ms2 "
        "(nss/losses.py)"
    )
    decouple_tolerance_ms2: float = Field(
        0.05, ge=0.0, description="decoupling prior: the change of dvx/dt, m/s², that the "
        "second state may cause over the yaw range"
    )


class DataConfig(StrictModel):
    """Normalisation and training windows (§II, §IV-B)."""

    normalizer: Literal["clipped", "minmax", "zscore"] = "clipped"
    clip_percentiles: tuple[float, float] = (0.5, 99.5)
    window: Literal["shortest"] | int = Field(
        "shortest", description="training-window length: the shortest training trial, or N"
    )

    @field_validator("clip_percentiles")
    @classmethod
    def _pct(cls, v: tuple[float, float]) -> tuple[float, float]:
        if not 0.0 <= v[0] < v[1] <= 100.0:
            raise ValueError("clip_percentiles must satisfy 0 <= lo < hi <= 100")
        return v

    @field_validator("window")
    @classmethod
    def _window(cls, v):
        if isinstance(v, int) and v < 2:
            raise ValueError("window must be 'shortest' or an integer >= 2")
        return v


class TrainConfig(StrictModel):
    """Optimisation (§IV-B): Adam, cosine LR from 2e-3, cap 3200 epochs, best checkpoint."""

    # added after fits and run folders were stored: their keys stay as before
    omit_at_default = frozenset({"processes"})

    recipe: Literal["paper", "fast", "coarse"] = Field(
        "paper",
        description="paper: full-batch BPTT over the end-aligned windows for `epochs`; fast: "
        "the `fast` section's minibatch phase, then a full-window finish; coarse: the "
        "`coarse` section's coarse-step epochs, then a full-rate finish (nss/recipes.py)",
    )
    epochs: int = Field(3200, ge=1)
    lr: float = Field(2.0e-3, gt=0.0)
    lr_min: float = Field(0.0, ge=0.0, description="final LR of the cosine schedule")
    schedule: Literal["cosine", "constant"] = "cosine"
    seed: int = 0
    threads: int = Field(1, ge=1, description="torch intra-op threads during training")
    processes: int = Field(
        1, ge=1, le=64, description="processes sharing each step's windows (data-parallel, "
        "nss/parallel.py): the same objective and Adam steps, rounded differently; 1: the "
        "fit's own process only")
    val_every: int = Field(5, ge=1, description="validate every N epochs")
    smooth_window: int = Field(
        20, ge=1, description="trailing moving average over this many criterion points"
    )
    checkpoint_every: int = Field(50, ge=1, description="save the resumable state every N")
    selection: Literal["scored", "inner"] = Field(
        "scored", description="where a fold fit's checkpoint is chosen: scored = on the "
        "fold's held-out trials, which are also scored (the paper's protocol); inner = on "
        "one training trial per maneuver class held out of the fit, never on a scored trial")
    dtype: Literal["float32", "float64"] = "float32"


FAST_IGNORES: tuple[str, ...] = ("epochs", "lr", "schedule")
"""Fields of the train section the fast and coarse recipes do not read (they have their own)."""

RECIPE_SECTIONS: tuple[str, ...] = ("fast", "coarse")
"""The non-paper recipes; each reads the config section of its name (a fit names only its
own)."""


class FastConfig(StrictModel):
    """The fast recipe (``train.recipe: fast``; not the paper's, see nss/recipes.py).
    It reads these instead of ``train.epochs``, ``train.lr`` and ``train.schedule``.

    Phase 1: ``updates`` Adam steps, each on ``batch`` windows of ``window`` samples tiled
    over every training trial, LR cosine from ``lr`` to ``train.lr_min``. Phase 2:
    ``finish_epochs`` full-batch steps on the paper's windows, LR cosine from
    ``finish_lr`` to ``train.lr_min``. Validation every ``val_every`` updates in phase 1
    and every ``train.val_every`` steps in phase 2.
    """

    # added after fast-recipe fits were stored: their keys stay as before
    omit_at_default = frozenset({"ema"})
    window: int = Field(1024, ge=2, description="samples per phase-1 window (10.24 s at 100 Hz)")
    batch: int = Field(8, ge=1, description="windows per phase-1 update")
    updates: int = Field(2000, ge=0, description="phase-1 updates")
    lr: float = Field(2.0e-3, gt=0.0, description="phase-1 initial LR (cosine to lr_min)")
    val_every: int = Field(20, ge=1, description="validate every N phase-1 updates")
    finish_epochs: int = Field(100, ge=0, description="phase-2 full-batch steps")
    finish_lr: float = Field(5.0e-4, gt=0.0, description="phase-2 initial LR (cosine)")
    ema: float = Field(
        0.0, ge=0.0, lt=1.0, description="decay of an exponential moving average of the "
        "weights over every step, validated and kept instead of them (0: off; nss/averaging.py)"
    )

    @model_validator(mode="after")
    def _some_steps(self) -> FastConfig:
        if self.updates + self.finish_epochs < 1:
            raise ValueError("the fast recipe needs updates + finish_epochs >= 1")
        return self


class CoarseConfig(StrictModel):
    """The coarse-to-fine recipe (``train.recipe: coarse``; not the paper's, see
    nss/recipes.py). It reads these instead of ``train.epochs``, ``train.lr`` and
    ``train.schedule``.

    Phase 1: ``epochs`` full-batch Adam steps on the paper's windows of the training
    trials decimated by ``factor`` (data/decimate.py), rolled out with an Euler step of
    factor·dt; LR cosine from ``lr`` to ``train.lr_min``; validation (held-out trials at
    the full rate, the deployment criterion) every ``val_every`` epochs. Phase 2:
    ``finish_epochs`` paper epochs at the full rate, LR cosine from ``finish_lr`` to
    ``train.lr_min``, validation every ``train.val_every``.
    """

    factor: int = Field(
        16, ge=1, le=100, description="phase 1: samples per coarse step (Euler step factor·dt)")
    epochs: int = Field(4000, ge=0, description="phase-1 full-batch steps at the coarse step")
    lr: float = Field(4.0e-3, gt=0.0, description="phase-1 initial LR (cosine to lr_min)")
    val_every: int = Field(25, ge=1, description="validate every N phase-1 epochs")
    finish_epochs: int = Field(150, ge=0, description="phase-2 full-rate, full-batch steps")
    finish_lr: float = Field(5.0e-4, gt=0.0, description="phase-2 initial LR (cosine)")

    @model_validator(mode="after")
    def _some_steps(self) -> CoarseConfig:
        if self.epochs + self.finish_epochs < 1:
            raise ValueError("the coarse recipe needs epochs + finish_epochs >= 1")
        return self


class LimiterConfig(StrictModel):
    """Inference-time gear-conditioned kinematic limiter (§V-B); off by default."""

    enabled: bool = False
    mode: Literal["reconstructed", "residual"] = Field(
        "reconstructed",
        description="clamp the reconstructed yaw rate (correct) or the residual channel",
    )
    yaw_margin: float = Field(
        0.1, ge=0.0, description="relative margin on the kinematic yaw envelope |vx|/R_min"
    )
    yaw_tol_degs: float = Field(1.0, ge=0.0, description="absolute yaw envelope floor, deg/s")


class NSSConfig(StrictModel):
    """Everything that defines one NSS fit."""

    model: ModelConfig = ModelConfig()
    loss: LossConfig = LossConfig()
    data: DataConfig = DataConfig()
    train: TrainConfig = TrainConfig()
    fast: FastConfig = FastConfig()
    coarse: CoarseConfig = CoarseConfig()
    limiter: LimiterConfig = LimiterConfig()

    @model_validator(mode="after")
    def _fused_needs_euler(self) -> NSSConfig:
        if self.model.engine == "fused" and self.model.integrator != "euler":
            raise ValueError("engine 'fused' implements forward Euler only; use 'auto'/'eager'")
        if self.model.fused_kernels == "native" and self.train.dtype != "float32":
            raise ValueError("fused_kernels 'native' trains in float32 only; set train.dtype "
                             "float32 or another fused_kernels")
        return self


def fit_identity(cfg: NSSConfig) -> dict:
    """The fields of ``cfg`` that decide a fit's numbers, as JSON: all but the torch thread
    count; for a paper-recipe fit also without the recipe field, for a fast or coarse
    fit without the paper recipe's epoch cap, LR and schedule, and for every fit without
    the sections of the recipes it does not use (none reads another's). Resume
    fingerprints and result-store keys use it."""
    doc = cfg.model_dump(mode="json")
    doc["train"].pop("threads", None)
    if cfg.train.selection == "scored":  # the default keeps the keys it had without it
        doc["train"].pop("selection", None)
    if cfg.model.fused_kernels == "reference":  # likewise
        doc["model"].pop("fused_kernels", None)
    if cfg.loss.blind_zone == "mask":  # likewise (the width is read only by observe)
        doc["loss"].pop("blind_zone", None)
        doc["loss"].pop("blind_zone_width_kmh", None)
    else:  # an observe fit names its gate's width, at its default too (omit_at_default)
        doc["loss"]["blind_zone_width_kmh"] = cfg.loss.blind_zone_width_kmh
    if cfg.loss.lambda_torque > 0.0:  # a fit with the torque-gain prior names its settings
        doc["loss"]["torque_gain_min"] = cfg.loss.torque_gain_min
        doc["loss"]["torque_step_nm"] = cfg.loss.torque_step_nm
        if cfg.loss.torque_prior_states != "logged":  # the envelope names its draw size
            doc["loss"]["torque_prior_samples"] = cfg.loss.torque_prior_samples
        else:  # the fits made before the envelope keep their keys
            doc["loss"].pop("torque_prior_states", None)
            doc["loss"].pop("torque_prior_samples", None)
    else:  # off: the settings are read by nobody
        for k in ("torque_gain_min", "torque_step_nm", "torque_prior_states"):
            doc["loss"].pop(k, None)
    if cfg.loss.lambda_decouple > 0.0:  # the decoupling prior names its settings
        doc["loss"]["decouple_tolerance_ms2"] = cfg.loss.decouple_tolerance_ms2
        doc["loss"]["torque_prior_samples"] = cfg.loss.torque_prior_samples
    else:
        doc["loss"].pop("decouple_tolerance_ms2", None)
        if cfg.loss.lambda_torque == 0.0 or cfg.loss.torque_prior_states == "logged":
            doc["loss"].pop("torque_prior_samples", None)
    if cfg.train.recipe == "paper":
        doc["train"].pop("recipe", None)
    else:
        for k in FAST_IGNORES:
            doc["train"].pop(k, None)
    for section in RECIPE_SECTIONS:  # only the fit's own recipe section
        if cfg.train.recipe != section:
            doc.pop(section, None)
    return doc


def load_nss_config(path=None, **sections) -> NSSConfig:
    """Read an NSSConfig from ``path`` (default: the shipped configs/nss.yaml, the paper's
    values) plus per-section overrides, e.g. ``train={"epochs": 30}``."""
    return load_config(NSSConfig, path, default="nss.yaml", overrides=sections)


def with_overrides(cfg: NSSConfig, **sections: dict) -> NSSConfig:
    """A copy of ``cfg`` with fields of sections replaced, e.g. train={"epochs": 30};
    :func:`parknss.config.override` (validated, one-line ConfigError)."""
    return override(cfg, sections)


def cli_overrides(
    sets: list[str] | None, epochs: int | None = None, seed: int | None = None
) -> dict[str, dict]:
    """The overrides of the NSS commands: ``--set section.field=value`` items
    (:func:`parknss.config.parse_set`) plus ``--epochs`` and ``--seed`` (train section),
    as {section: {field: value}}."""
    out = parse_set(sets)
    if epochs is not None:
        out.setdefault("train", {})["epochs"] = epochs
    if seed is not None:
        out.setdefault("train", {})["seed"] = seed
    return out
