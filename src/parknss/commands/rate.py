"""``parknss rate``: ISO/TS 18571 rating of a model's predictions against a campaign.

``parknss rate --model M --data D`` predicts vx, yaw rate, ax and ay of every trial of
the campaign folder D with the model M (through ``parknss.nss.predict``) and rates each
against the logged channel, raw and after the identical 5 Hz zero-phase low-pass.
``parknss rate --chain C --data D`` rates the command-to-vehicle chain artefact C (e.g.
the shipped ``models/chain``) instead, rolled out from the logged commands
(``parknss.chain.predict_chain_campaign``), the paper's Fig. 7 setting.
``parknss rate --replay-truth --data D`` instead rates a synthetic campaign's noise-free
``truth_*`` channels against the logged ones: the rating a perfect model would get, the
ceiling set by sensor noise, offsets and the wheel-speed blind zone.

Writes ``ratings.csv``, ``ratings.json`` and the box plot ``iso_rating.png`` (Fig. 7) to
``--out`` (default ``runs/rate``) and prints the summary table, or with ``--json`` one
JSON document (the rating table plus the written files) on stdout.
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

from parknss.errors import CheckpointError, DataError, ParknssError

PREDICTOR = "parknss.nss.predict"


def _log(msg: str) -> None:
    typer.echo(f"[rate] {msg}", err=True)


def load_predictor():
    """``predict_campaign`` from parknss.nss.predict, or a ParknssError if not there."""
    try:
        from parknss.nss.predict import predict_campaign
    except ModuleNotFoundError as exc:
        if exc.name and PREDICTOR.startswith(exc.name):
            raise ParknssError(
                f"no model predictor is available yet ({PREDICTOR} is missing); "
                "use --replay-truth to rate the campaign's truth channels"
            ) from exc
        raise
    except ImportError as exc:
        raise ParknssError(f"{PREDICTOR} has no predict_campaign: {exc}") from exc
    return predict_campaign


def truth_pairs(campaign, channels) -> dict:
    """trial id -> channel -> (logged, truth_<channel>) for a synthetic campaign."""
    return {tr.id: {ch: (tr[ch], tr.truth(ch)) for ch in channels} for tr in campaign}


def model_pairs(campaign, predictions, channels, model) -> dict:
    """trial id -> channel -> (logged, predicted); DataError for anything missing."""
    pairs = {}
    for tr in campaign:
        pred = predictions.get(tr.id)
        if pred is None:
            raise DataError(f"{model}: no prediction for trial {tr.id}")
        missing = [ch for ch in channels if ch not in pred]
        if missing:
            raise DataError(f"{model}: trial {tr.id}: no prediction of {', '.join(missing)}")
        pairs[tr.id] = {ch: (tr[ch], pred[ch]) for ch in channels}
    return pairs


def check_channels(campaign, rated, replay_truth: bool, chain: bool, data: Path) -> None:
    """Refuse (one DataError line) a campaign that lacks what the mode reads: a chain the
    ``rate`` workflow's channels, a model the ``nss`` ones, the truth replay the rated
    channels (parknss.data.workflows)."""
    from parknss.data.workflows import require, require_channels

    where = f"parknss rate --data {data}"
    if replay_truth:
        require_channels(campaign, tuple(rated), "rating the truth replay", where)
    else:
        require(campaign, "rate" if chain else "nss", where)


def run_rate(
    data: Path,
    model: Path | None,
    replay_truth: bool,
    out: Path,
    config: Path | None = None,
    chain: Path | None = None,
) -> dict:
    """Rate, write the CSV, JSON and figure; return the JSON document."""
    from parknss.config import load_config
    from parknss.data.io import read_campaign
    from parknss.metrics.rating_report import RateConfig, rate_campaign
    from parknss.report.iso_figure import draw_iso_boxplot

    if int(replay_truth) + (model is not None) + (chain is not None) != 1:
        raise ParknssError("give exactly one of --model M, --chain C or --replay-truth")
    cfg = load_config(RateConfig, config)
    campaign = read_campaign(data)
    check_channels(campaign, cfg.channels, replay_truth, chain is not None, data)
    if replay_truth:
        pairs = truth_pairs(campaign, cfg.channels)
        source = {"mode": "replay-truth", "data": str(data)}
    elif chain is not None:
        from parknss.chain import predict_chain_campaign

        _log(f"predicting {len(campaign)} trials with the chain {chain}")
        predictions = predict_chain_campaign(chain, campaign)
        pairs = model_pairs(campaign, predictions, cfg.channels, chain)
        source = {"mode": "chain", "chain": str(chain), "data": str(data)}
    else:
        predict_campaign = load_predictor()
        if not Path(model).exists():
            raise CheckpointError(f"{model}: model not found")
        _log(f"predicting {len(campaign)} trials with {model}")
        predictions = predict_campaign(model, campaign)
        pairs = model_pairs(campaign, predictions, cfg.channels, model)
        source = {"mode": "model", "model": str(model), "data": str(data)}
    dts = {tr.id: 1.0 / tr.sample_rate_hz for tr in campaign}
    table = rate_campaign(pairs, dts, cfg, progress=_log)
    out.mkdir(parents=True, exist_ok=True)
    doc = {"source": source, **table.to_json()}
    files = {
        "csv": str(table.to_csv(out / "ratings.csv")),
        "json": str(out / "ratings.json"),
        "figure": str(draw_iso_boxplot(table, out / "iso_rating.png")),
    }
    doc["files"] = files
    (out / "ratings.json").write_text(json.dumps(doc, indent=2))
    doc["_table"] = table
    return doc


def register(app: typer.Typer) -> None:
    @app.command("rate")
    def rate(
        data: Path = typer.Option(..., "--data", help="Campaign folder (campaign.json)."),
        model: Path | None = typer.Option(None, "--model", help="Model checkpoint to rate."),
        chain: Path | None = typer.Option(
            None, "--chain", help="Chain artefact to rate from the commands (models/chain)."
        ),
        replay_truth: bool = typer.Option(
            False, "--replay-truth", help="Rate the truth_* channels (sensor-noise ceiling)."
        ),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON document."),
        out: Path = typer.Option(Path("runs/rate"), "--out", help="Folder for CSV/JSON/PNG."),
        config: Path | None = typer.Option(None, "--config", help="Rating YAML (RateConfig)."),
    ) -> None:
        """ISO/TS 18571 rating of vx, yaw rate, ax, ay per trial, raw and 5 Hz filtered."""
        doc = run_rate(data, model, replay_truth, out, config, chain)
        table = doc.pop("_table")
        if as_json:
            typer.echo(json.dumps(doc, indent=2))
        else:
            typer.echo(table.table())
            typer.echo(f"wrote {doc['files']['csv']}, {doc['files']['figure']}")
