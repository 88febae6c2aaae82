"""``parknss evaluate`` as one library call: open-loop errors of a model or a chain.

:func:`evaluate_open_loop` rolls out an NSS (default: the shipped one) from the logged
actuals, or a chain artefact from the logged commands, over every trial of a campaign
(default: the bundled one) and gives its errors (:mod:`parknss.metrics.errors`) against
the logged channels and, for a synthetic campaign, against the noise-free truth; it draws
Fig. 5 for a park-in and a park-out and writes ``evaluate.json`` to the run folder
(:func:`parknss.outputs.run_folder`: an ``out`` holding anything but an evaluation of the
same source on the same campaign is refused unless ``overwrite``).
"""

from __future__ import annotations

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
from parknss.outputs import run_folder
from parknss.report.nss_figures import draw_rollouts, pick_maneuvers


@dataclass(frozen=True, kw_only=True)
class EvaluateInputs:
    """An NSS folder ``model`` (None: shipped) or a ``chain`` artefact, the campaign
    ``data`` (None: default), whether the inference ``limiter`` runs (NSS only), the run
    folder ``out`` and whether an ``out`` holding something else may be replaced
    (``overwrite``)."""

    out: Path
    model: Path | None = None
    chain: Path | None = None
    data: Path | None = None
    limiter: bool = False
    overwrite: bool = False


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
        source, predictor, horizon = str(chain), load_chain(chain).predict_trials, None
    else:
        loaded = load_model(inputs.model or SHIPPED_NSS)
        source, horizon = str(loaded.path), loaded.training.get("window_length")
        lim = LimiterConfig(enabled=True) if inputs.limiter else None

        def predictor(trials):
            return predict_trials(loaded.model, trials, lim)

    identity = {"model": None if chain is not None else (inputs.model or SHIPPED_NSS),
                "chain": chain, "data": inputs.data, "limiter": inputs.limiter}
    with run_folder(inputs.out, command="parknss evaluate", args=identity,
                    overwrite=inputs.overwrite) as run:
        predictions = predictor(trials)
        logged, truth = logged_and_truth_errors(predictions, trials, horizon)
        fig = draw_rollouts(
            pick_maneuvers(trials),
            predictions,
            run.path / "fig5_rollouts.png",
            horizon,
            title=f"Open-loop rollout of {Path(source).name}",
        )
        doc = {**logged, "source": source, "truth": truth, "figure": str(fig)}
        run.write_json("evaluate.json", doc)
    text = errors_text(f"{source} on {len(trials)} trials vs logged channels", logged)
    if truth is not None:
        text += "\n" + errors_text("vs noise-free truth channels (synthetic campaign)", truth)
    return doc, text
