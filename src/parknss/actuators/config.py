"""Typed configuration of the actuator work (configs/actuators.yaml); defaults = the paper.

Numbers the paper fixes (§III): the candidate structures (Hammerstein 1x8x8x1, NARX on the
command and 5 lagged samples, GRU with a 16-d state, the 1 s long-memory brake), the
deceleration-command domain [-0.8, 0] m/s², the output floors (torque, pressure >= 0), the
steering lock ±400°. Everything else (hidden widths the paper leaves open, optimiser
budgets, split, shortlist size) is a named value here, with the reason in docs/actuators.md.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_serializer

from parknss.config import StrictModel, load_config


class ArchConfig(StrictModel):
    """Candidate structures. Paper-fixed: hammerstein_hidden, narx_lags, gru_hidden."""

    hammerstein_hidden: tuple[int, ...] = (8, 8)  # 1x8x8x1 static perceptron (§III-A)
    narx_lags: int = Field(5, ge=0, description="lagged command samples (5 = 50 ms)")
    narx_long_lags: int = Field(100, ge=1, description="1 s window of the long NARX brake")
    narx_hidden: tuple[int, ...] = (16, 16)
    gru_hidden: int = Field(16, ge=1)
    lstm_hidden: int = Field(16, ge=1)
    tau_init_s: float = Field(0.2, gt=0.0, description="initial first-order time constant")
    tau2_init_s: float = Field(0.1, gt=0.0, description="initial second-order time constant")
    zeta_init: float = Field(0.9, gt=0.0, description="initial second-order damping")
    # monolag (the monotone structured brake, opt-in; not in the paper's candidate set)
    monolag_knots: int = Field(8, ge=1, description="ramps of the monotone static map, "
                               "knots evenly spread over the scaled command domain")
    monolag_sharpness: float = Field(20.0, gt=0.0, description="softplus sharpness of the "
                                     "ramps and of the hold's request gate (scaled units)")
    monolag_max_delay_s: float = Field(0.3, gt=0.0, description="longest dead time, s")
    monolag_delay_init_s: float = Field(0.1, ge=0.0, description="initial dead time, s")
    monolag_hold_speed_ms: float = Field(0.07, gt=0.0, description="initial standstill "
                                         "threshold of the hold gate (state-aware), m/s")
    monolag_hold_speed_max_ms: float | None = Field(
        None, gt=0.0, description="ceiling of the hold gate's standstill threshold, m/s: "
        "v_h = ceiling·σ(ρ) instead of exp(ρ) (None: unbounded). The wheel-speed blind-zone "
        "edge (0.139 m/s) keeps the identified hold a standstill hold (docs/actuators.md)")
    monolag_hold_width_ms: float = Field(0.02, gt=0.0, description="width of the hold "
                                         "gate's speed sigmoid, m/s")
    monolag_hold_request: float = Field(0.25, gt=0.0, lt=1.0, description="initial request "
                                        "that arms the hold, fraction of the domain")
    monolag_hold_tau_s: float = Field(0.3, gt=0.0, description="initial engage time "
                                      "constant of the hold, s")
    monolag_release_tau_s: float = Field(0.4, gt=0.0, description="initial release time "
                                         "of the hold, s: the exponential's time constant, "
                                         "or the ramp's duration from full hold to none")
    monolag_release: Literal["exp", "ramp"] = Field(
        "exp", description="shape of the hold's release: 'exp' (first-order, pole "
        "exp(-dt/τ_off)) or 'ramp' (linear, slope dt/τ_off per sample, the chassis "
        "auto-hold's ramp-out at a launch; docs/actuators.md)")

    @model_serializer(mode="wrap")
    def _omit_default_monolag(self, handler) -> dict:
        """Dump without the monolag fields at their defaults, so every config digest
        (run folders, the derived store's ladder entries) and every artefact of the paper's
        candidates reads as before they existed; a changed one is dumped (and digested)."""
        doc = handler(self)
        for k, f in type(self).model_fields.items():
            if k.startswith("monolag_") and getattr(self, k) == f.default:
                doc.pop(k, None)
        return doc

    def artefact_json(self, arch: str) -> dict:
        """The structure config a chain artefact records for a candidate of ``arch``: every
        monolag field for a monolag candidate, none for the others (written as before)."""
        doc = self.model_dump(mode="json")
        if arch == "monolag":
            return {**doc, **{k: getattr(self, k) for k in type(self).model_fields
                              if k.startswith("monolag_")}}
        return {k: v for k, v in doc.items() if not k.startswith("monolag_")}


class EnvelopeConfig(StrictModel):
    """Physical input-output envelopes (§III-B)."""

    decel_domain_ms2: tuple[float, float] = (-0.8, 0.0)  # paper: a_x* in [-0.8, 0]
    torque_domain_nm: tuple[float, float] | None = None  # None: identified from the data
    steer_domain_deg: tuple[float, float] | None = None  # None: identified from the data
    torque_floor_nm: float = 0.0
    pressure_floor_bar: float = 0.0
    steer_lock_deg: float = 400.0
    steer_rate_margin: float = Field(
        1.05, ge=1.0, description="rate limit = margin x the highest steering slew in the data"
    )
    max_shift_speed_kmh: float = Field(
        0.1, ge=0.0, description="gear rule: a differing request is refused above, km/h"
    )
    shift_time_s: float = Field(
        0.25, ge=0.0, description="gear rule: standstill time before a new gear engages, s"
    )
    hold_latch: bool = Field(
        True, description="closed loop: a brake at or above the highest pressure the car was "
        "seen moving at holds a car inside the blind zone at rest")
    hold_latch_kmh: float = Field(
        0.5, ge=0.0, description="brake-hold latch: |vx| below this (the wheel-speed blind "
        "zone, where the NSS loss does not look) is held at rest, km/h")


class FitConfig(StrictModel):
    """Signal-level fitting of one candidate (Phase A): full-batch Adam on windows."""

    window: int = Field(200, ge=10, description="scored samples per training window")
    max_windows: int = Field(32, ge=1, description="windows per fit, evenly spread")
    burn_in: int = Field(100, ge=0, description="unscored lead-in samples per window (1 s)")
    iters_linear: int = Field(100, ge=1, description="Adam steps, lag1/lag2/static")
    iters_neural: int = Field(80, ge=1, description="Adam steps, hammerstein/narx/gru/lstm")
    lr_linear: float = Field(0.05, gt=0.0)
    lr_neural: float = Field(0.01, gt=0.0)
    seed: int = 0


class SelectConfig(StrictModel):
    """Two-phase selection (§III-C): the split, the shortlist, Phase B assemblies."""

    val_fold: int = Field(0, ge=0, description="stratified fold held out for selection")
    shortlist: int = Field(3, ge=1, description="Phase A shortlist size per channel")
    assembly_top: int = Field(2, ge=1, description="Phase B winners per channel combined")
    nss_state_finetune_iters: int = Field(
        0, ge=0, description="signal fine-tune of state-aware shortlisted candidates on "
        "NSS-supplied states (0: off)"
    )
    step_hold_s: float = Field(4.0, gt=0.0, description="step-response simulation length")
    archs: tuple[str, ...] = ("lag1", "lag2", "hammerstein", "narx", "gru")
    long_archs: tuple[str, ...] = ("narx1s", "lstm")  # long-memory brake candidates
    variants: tuple[str, ...] = ("cmd", "phys", "uniform")


class CotuneConfig(StrictModel):
    """Consequence-level fine-tuning of one submodel through the frozen chain (§V-E)."""

    target: str = "brake/narx1s/cmd"
    iters: int = Field(40, ge=0)
    lr: float = Field(3e-3, gt=0.0)
    window: int = Field(1000, ge=10, description="samples per co-tuning window (10 s)")
    burn_in: int = Field(100, ge=0, description="unscored lead-in per window (1 s)")
    batch: int = Field(8, ge=1, description="windows per Adam step")
    refresh_every: int = Field(
        0, ge=0, description="steps between exact-chain refreshes of the frozen context "
        "(0: once, at the start)"
    )
    seed: int = 0
    loss: str = Field("mse", pattern="^(mse|mae)$")
    eval_every: int = Field(
        10, ge=1, description="steps between all-window evaluations; the best weights are kept"
    )


class LadderConfig(StrictModel):
    """Table IV baselines."""

    monolithic_epochs: int = Field(
        30, ge=0, description="warm-started NSS fine-tune on commands (0: skip the row)"
    )
    monolithic_lr: float = Field(5e-4, gt=0.0)


class StressConfig(StrictModel):
    """Envelope stress study (§V-E)."""

    torque_factor: float = 3.0
    decel_ms2: float = -5.0
    steer_rate_dps: float = 1000.0
    steer_step_deg: float = 600.0
    seconds: float = Field(20.0, gt=0.0)


class ActuatorConfig(StrictModel):
    """Everything issue 4 tunes."""

    arch: ArchConfig = ArchConfig()
    envelope: EnvelopeConfig = EnvelopeConfig()
    fit: FitConfig = FitConfig()
    select: SelectConfig = SelectConfig()
    cotune: CotuneConfig = CotuneConfig()
    ladder: LadderConfig = LadderConfig()
    stress: StressConfig = StressConfig()


def load_actuator_config(path=None, **overrides) -> ActuatorConfig:
    """``path`` (default: the shipped configs/actuators.yaml) plus per-section overrides."""
    return load_config(ActuatorConfig, path, default="actuators.yaml", overrides=overrides)
