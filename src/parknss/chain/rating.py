"""What ``parknss rate`` rates: a model, a chain, or a campaign's truth channels (§V-F).

:func:`rate_source` predicts vx, yaw rate, ax and ay of every trial of a campaign folder
and rates each against the logged channel, raw and 5 Hz filtered
(:func:`parknss.metrics.rating_report.rate_campaign`). The source is one of

* ``model``: an NSS artefact, rolled out open loop from the logged actuals
  (:func:`parknss.nss.predict.predict_campaign`);
* ``chain``: a chain artefact (e.g. the shipped ``models/chain``), rolled out from the
  logged commands (:func:`parknss.chain.deployed.predict_chain_campaign`), the paper's
  Fig. 7 setting;
* ``replay_truth``: a synthetic campaign's noise-free ``truth_*`` channels, the rating a
  perfect model would get (the ceiling set by sensor noise, offsets and the blind zone).

The files and the Fig. 7 box plot are written by :func:`parknss.experiments.rating.run_rate`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from parknss.chain.deployed import predict_chain_campaign
from parknss.config import load_config
from parknss.data.trial import Campaign
from parknss.data.workflows import require, require_channels
from parknss.errors import CheckpointError, ParknssError
from parknss.metrics.rating_report import (
    RateConfig,
    RatingTable,
    model_pairs,
    rate_campaign,
    truth_pairs,
)
from parknss.nss.campaigns import load_campaign
from parknss.nss.predict import predict_campaign

Progress = Callable[[str], None]


def _quiet(msg: str) -> None:
    pass


@dataclass(frozen=True, kw_only=True)
class RateInputs:
    """A rating job: the campaign folder ``data`` and exactly one source (``model`` NSS
    folder, ``chain`` artefact folder, or ``replay_truth``); ``config`` a RateConfig YAML
    (None: the code defaults, the paper's)."""

    data: Path
    model: Path | None = None
    chain: Path | None = None
    replay_truth: bool = False
    config: Path | None = None

    def check(self) -> None:
        """One-line ParknssError unless exactly one source is given."""
        if int(self.replay_truth) + (self.model is not None) + (self.chain is not None) != 1:
            raise ParknssError("give exactly one of --model M, --chain C or --replay-truth")


def check_channels(campaign: Campaign, rated: Sequence[str], inputs: RateInputs) -> None:
    """Refuse (one DataError line) a campaign that lacks what the source reads: a chain the
    ``rate`` workflow's channels, a model the ``nss`` ones, the truth replay the rated
    channels (parknss.data.workflows)."""
    where = f"parknss rate --data {inputs.data}"
    if inputs.replay_truth:
        require_channels(campaign, tuple(rated), "rating the truth replay", where)
    else:
        require(campaign, "rate" if inputs.chain is not None else "nss", where)


def rate_source(inputs: RateInputs, progress: Progress = _quiet) -> tuple[RatingTable, dict]:
    """(the rating table, the source's description for the JSON document)."""
    inputs.check()
    cfg = load_config(RateConfig, inputs.config)
    campaign = load_campaign(inputs.data)  # the folder (a path is required here)
    check_channels(campaign, cfg.channels, inputs)
    data = str(inputs.data)
    if inputs.replay_truth:
        pairs = truth_pairs(campaign, cfg.channels)
        source = {"mode": "replay-truth", "data": data}
    elif inputs.chain is not None:
        progress(f"predicting {len(campaign)} trials with the chain {inputs.chain}")
        predictions = predict_chain_campaign(inputs.chain, campaign)
        pairs = model_pairs(campaign, predictions, cfg.channels, inputs.chain)
        source = {"mode": "chain", "chain": str(inputs.chain), "data": data}
    else:
        if not Path(inputs.model).exists():
            raise CheckpointError(f"{inputs.model}: model not found")
        progress(f"predicting {len(campaign)} trials with {inputs.model}")
        predictions = predict_campaign(inputs.model, campaign)
        pairs = model_pairs(campaign, predictions, cfg.channels, inputs.model)
        source = {"mode": "model", "model": str(inputs.model), "data": data}
    dts = {tr.id: 1.0 / tr.sample_rate_hz for tr in campaign}
    return rate_campaign(pairs, dts, cfg, progress=progress), source
