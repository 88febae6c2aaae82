"""Open-loop error metrics of paper §IV-B/§V-A in the paper's units.

Predictions are open-loop rollouts from the true initial state over whole trials
(``predictions[trial_id][channel]``, arrays of the trial's length, schema units). The
squared errors of all samples of all trials in a subset are pooled (a sample-weighted
mean, so long trials weigh more) and reported as MSE in (km/h)² for vx, (°/s)² for the
yaw rate and (m/s²)² for ax, ay, on these subsets:

* moving: measured |vx| >= 0.5 km/h (the blind zone masked; the headline numbers);
* reverse: moving and gear = -1;
* within / beyond: moving samples before / from the training-window horizon (the sample
  index counted from the trial start, the window length L);
* full: every sample.

With ``reference="truth"`` the errors are taken against the noise-free ``truth_*``
channels of a synthetic trial instead of the logged ones (ground-truth evaluation);
the masks still come from the logged vx and gear so both references score the same
samples. An empty subset gives NaN (``null`` in JSON).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass, field

import numpy as np

from parknss.data.trial import Trial
from parknss.errors import DataError
from parknss.signals import BLIND_ZONE_KMH, MSE_FACTOR_DEGS2, MSE_FACTOR_KMH2, kmh_to_ms

CHANNELS: tuple[str, ...] = ("vx", "yaw_rate", "ax", "ay")
FACTORS = {"vx": MSE_FACTOR_KMH2, "yaw_rate": MSE_FACTOR_DEGS2, "ax": 1.0, "ay": 1.0}


@dataclass
class OpenLoopErrors:
    """Pooled MSEs (NaN where the subset is empty) and the sample counts behind them."""

    vx_mse_moving_kmh2: float
    vx_mse_reverse_kmh2: float
    yaw_mse_moving_degs2: float
    yaw_mse_reverse_degs2: float
    vx_mse_full_kmh2: float
    yaw_mse_full_degs2: float
    ax_mse_moving_ms2: float
    ay_mse_moving_ms2: float
    ax_mse_full_ms2: float
    ay_mse_full_ms2: float
    vx_mse_within_kmh2: float
    vx_mse_beyond_kmh2: float
    yaw_mse_within_degs2: float
    yaw_mse_beyond_degs2: float
    horizon: int | None
    reference: str
    counts: dict[str, int] = field(default_factory=dict)
    trials: list[str] = field(default_factory=list)

    def to_json(self) -> dict:
        """Plain JSON (NaN -> null)."""
        d = asdict(self)
        return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in d.items()}


def _mse(sq: np.ndarray, mask: np.ndarray) -> float:
    n = int(mask.sum())
    return float(np.sum(sq[mask]) / n) if n else math.nan


def _reference(tr: Trial, ch: str, reference: str) -> np.ndarray:
    return tr.truth(ch) if reference == "truth" else tr[ch]


def _pooled(
    trials: list[Trial], predictions: Mapping, reference: str, bz: float
) -> dict[str, np.ndarray]:
    cols: dict[str, list[np.ndarray]] = {k: [] for k in (*CHANNELS, "moving", "rev", "idx")}
    for tr in trials:
        pred = predictions.get(tr.id)
        if pred is None:
            raise DataError(f"no prediction for trial {tr.id}")
        for ch in CHANNELS:
            if ch not in pred:
                raise DataError(f"trial {tr.id}: no prediction of {ch}")
            p = np.asarray(pred[ch], dtype=np.float64)
            if p.shape != (tr.n,):
                raise DataError(
                    f"trial {tr.id}: prediction of {ch} has shape {p.shape}, not ({tr.n},)"
                )
            cols[ch].append((p - _reference(tr, ch, reference)) ** 2 * FACTORS[ch])
        moving = np.abs(tr["vx"]) >= bz
        cols["moving"].append(moving)
        cols["rev"].append(moving & (tr["gear"] < -0.5))
        cols["idx"].append(np.arange(tr.n))
    return {k: np.concatenate(v) for k, v in cols.items()}


def open_loop_errors(
    predictions: Mapping[str, Mapping[str, np.ndarray]],
    trials: Iterable[Trial],
    horizon: int | None = None,
    reference: str = "logged",
    blind_zone_kmh: float = BLIND_ZONE_KMH,
) -> OpenLoopErrors:
    """Pooled open-loop errors of ``predictions`` on ``trials`` (see the module doc)."""
    if reference not in ("logged", "truth"):
        raise DataError(f"reference must be 'logged' or 'truth', got {reference!r}")
    trials = list(trials)
    if not trials:
        raise DataError("no trials to evaluate")
    p = _pooled(trials, predictions, reference, kmh_to_ms(blind_zone_kmh))
    mv, rev, full = p["moving"], p["rev"], np.ones_like(p["moving"])
    if horizon is not None:
        within, beyond = mv & (p["idx"] < horizon), mv & (p["idx"] >= horizon)
    else:
        within = beyond = np.zeros_like(mv)
    return OpenLoopErrors(
        vx_mse_moving_kmh2=_mse(p["vx"], mv),
        vx_mse_reverse_kmh2=_mse(p["vx"], rev),
        yaw_mse_moving_degs2=_mse(p["yaw_rate"], mv),
        yaw_mse_reverse_degs2=_mse(p["yaw_rate"], rev),
        vx_mse_full_kmh2=_mse(p["vx"], full),
        yaw_mse_full_degs2=_mse(p["yaw_rate"], full),
        ax_mse_moving_ms2=_mse(p["ax"], mv),
        ay_mse_moving_ms2=_mse(p["ay"], mv),
        ax_mse_full_ms2=_mse(p["ax"], full),
        ay_mse_full_ms2=_mse(p["ay"], full),
        vx_mse_within_kmh2=_mse(p["vx"], within),
        vx_mse_beyond_kmh2=_mse(p["vx"], beyond),
        yaw_mse_within_degs2=_mse(p["yaw_rate"], within),
        yaw_mse_beyond_degs2=_mse(p["yaw_rate"], beyond),
        horizon=horizon,
        reference=reference,
        counts={
            "full": int(full.sum()),
            "moving": int(mv.sum()),
            "reverse": int(rev.sum()),
            "within": int(within.sum()),
            "beyond": int(beyond.sum()),
        },
        trials=[tr.id for tr in trials],
    )


def per_trial_errors(
    predictions: Mapping[str, Mapping[str, np.ndarray]],
    trials: Iterable[Trial],
    horizon: int | None = None,
    reference: str = "logged",
) -> dict[str, OpenLoopErrors]:
    """The same metrics trial by trial."""
    return {tr.id: open_loop_errors(predictions, [tr], horizon, reference) for tr in trials}


def logged_and_truth_errors(
    predictions: Mapping[str, Mapping[str, np.ndarray]],
    trials: Iterable[Trial],
    horizon: int | None = None,
) -> tuple[dict, dict | None]:
    """JSON errors against the logged channels, and against the truth channels when every
    trial carries them (a synthetic campaign), else None."""
    trials = list(trials)
    logged = open_loop_errors(predictions, trials, horizon).to_json()
    if not all(tr.has_truth() for tr in trials):
        return logged, None
    return logged, open_loop_errors(predictions, trials, horizon, "truth").to_json()
