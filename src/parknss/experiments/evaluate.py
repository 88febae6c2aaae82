"""``parknss evaluate`` as one library call: open-loop errors of a model or a chain.

:func:`evaluate_open_loop` rolls out an NSS (default: the shipped one) from the logged
actuals, or a chain artefact from the logged commands, over every trial of a campaign
(default: the bundled one) and gives its errors (:mod:`parknss.metrics.errors`) against
the logged channels and, for a synthetic campaign, against the noise-free truth; it draws
Fig. 5 for a park-in and a park-out and writes ``evaluate.json``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from parknss.chain.deployed import load_chain
from parknss.config import SHIPPED_NSS
from parknss.errors import ConfigError
from parknss.metrics.errors import logged_and_truth_errors
from parknss.nss.campaigns import load_campaign
from parknss.nss.checkpoint import load_model
from parknss.nss.config import LimiterConfig
from parknss.nss.predict import predict_trials
from parknss.report.nss_figures import draw_rollouts, pick_maneuvers


@dataclass(frozen=True, kw_only=True)
class EvaluateInputs:
    """An NSS folder ``model`` (None: shipped) or a ``chain`` artefact, the campaign
    ``data`` (None: default), whether the inference ``limiter`` runs (NSS only), and the
    run folder ``out``."""

    out: Path
    model: Path | None = None
    chain: Path | None = None
    data: Path | None = None
    limiter: bool = False


def errors_text(title: str, e: dict) -> str:
    """An errors document of :func:`parknss.metrics.errors.logged_and_truth_errors` as text
    (MSE in (km/h)², (°/s)², (m/s²)²; n/a where a subset is empty)."""

    def f(key: str) -> str:
        v = e.get(key)
        return "   n/a" if v is None else f"{v:8.4f}"

    return (
        f"{title}\n"
        f"  vx moving {f('vx_mse_moving_kmh2')} (km/h)²   reverse {f('vx_mse_reverse_kmh2')}"
        f"   full {f('vx_mse_full_kmh2')}\n"
        f"  yaw moving {f('yaw_mse_moving_degs2')} (°/s)²   full {f('yaw_mse_full_degs2')}\n"
        f"  vx within horizon {f('vx_mse_within_kmh2')}   beyond {f('vx_mse_beyond_kmh2')}\n"
        f"  ax moving {f('ax_mse_moving_ms2')} (m/s²)²   ay moving {f('ay_mse_moving_ms2')}"
    )


def evaluate_open_loop(inputs: EvaluateInputs) -> tuple[dict, str]:
    """(the JSON document: the errors vs logged, ``truth``, ``source``, ``figure``; text)."""
    chain = inputs.chain
    if chain is not None and (inputs.model is not None or inputs.limiter):
        raise ConfigError("--chain cannot be combined with --model or --limiter")
    # a chain rolls out from the logged commands; a model from the logged actuals
    campaign = load_campaign(inputs.data, "rate" if chain is not None else "nss",
                             "parknss evaluate")
    trials = list(campaign)
    if chain is not None:
        source = str(chain)
        predictions = load_chain(chain).predict_trials(trials)
        horizon = None
    else:
        loaded = load_model(inputs.model or SHIPPED_NSS)
        source = str(loaded.path)
        lim = LimiterConfig(enabled=True) if inputs.limiter else None
        predictions = predict_trials(loaded.model, trials, lim)
        horizon = loaded.training.get("window_length")
    logged, truth = logged_and_truth_errors(predictions, trials, horizon)
    out = inputs.out
    out.mkdir(parents=True, exist_ok=True)
    fig = draw_rollouts(
        pick_maneuvers(trials),
        predictions,
        out / "fig5_rollouts.png",
        horizon,
        title=f"Open-loop rollout of {Path(source).name}",
    )
    doc = {**logged, "source": source, "truth": truth, "figure": str(fig)}
    (out / "evaluate.json").write_text(json.dumps(doc, indent=2))
    text = errors_text(f"{source} on {len(trials)} trials vs logged channels", logged)
    if truth is not None:
        text += "\n" + errors_text("vs noise-free truth channels (synthetic campaign)", truth)
    return doc, text
