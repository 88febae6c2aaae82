"""``parknss cv``, ``parknss train`` and ``parknss evaluate``: the NSS model's jobs (§IV-B, §V-A).

* ``cv``: Table II, the stratified 4-fold cross-validation, with the linear and direct-yaw
  baselines on the same folds in the same run; Figs. 4 and 5
  (:func:`parknss.experiments.cv.table2`).
* ``train``: the all-trials deployment fit, resumable (``--resume``), with its loss history
  (:func:`parknss.experiments.training.train_deployment`).
* ``evaluate``: open-loop errors of any model (default: the shipped one) or chain on any
  campaign (default: the bundled one), against the logged channels and, for a synthetic
  campaign, the noise-free truth; Fig. 5
  (:func:`parknss.experiments.evaluate.evaluate_open_loop`).

Config: ``--config YAML`` (default: the shipped configs/nss.yaml, the paper's values) plus
``--epochs``, ``--seed`` and any ``--set section.field=value``. ``--out`` is a run folder:
the same command with the same arguments resumes it (``cv``: from its fold cache), one
holding anything else is refused unless ``--overwrite`` (:func:`parknss.outputs.run_folder`).
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

DATA_HELP = "Campaign folder (default: bundled)."


def _log(msg: str) -> None:
    typer.echo(f"[nss] {msg}", err=True)


def _emit(doc: dict, as_json: bool, text: str) -> None:
    typer.echo(json.dumps(doc, indent=2) if as_json else text)


def register(app: typer.Typer) -> None:
    data_opt = typer.Option(None, "--data", help=DATA_HELP)
    config_opt = typer.Option(None, "--config", help="NSS config YAML.")
    epochs_opt = typer.Option(None, "--epochs", help="Override train.epochs.")
    seed_opt = typer.Option(None, "--seed", help="Override train.seed.")
    set_opt = typer.Option(None, "--set", help="section.field=value (repeatable).")
    json_opt = typer.Option(False, "--json", help="Print one JSON document.")
    over_opt = typer.Option(
        False, "--overwrite", help="Replace what --out holds (another run, an artefact)."
    )

    @app.command("cv", short_help="Table II: 4-fold CV of the NSS and two baselines.")
    def cv(
        data: Path | None = data_opt, config: Path | None = config_opt,
        epochs: int | None = epochs_opt, seed: int | None = seed_opt,
        set_: list[str] = set_opt,
        variants: str = typer.Option(
            "nss,nss_direct_yaw,linear", "--variants", help="Comma-separated models to run."
        ),
        executor: str = typer.Option("local", "--executor", help="local | ray"),
        workers: int | None = typer.Option(None, "--workers", help="Parallel workers."),
        address: str | None = typer.Option(None, "--address", help="Ray cluster address."),
        out: Path = typer.Option(Path("runs/cv"), "--out", help="Run folder."),
        overwrite: bool = over_opt, as_json: bool = json_opt,
    ) -> None:
        """Table II: stratified 4-fold CV of the NSS and two baselines on the same folds
        (plain 4-fold, with a note, when the campaign is not stratifiable)."""
        from parknss.experiments.cv import CVInputs, table2
        from parknss.nss.config import cli_overrides

        names = tuple(v.strip() for v in variants.split(",") if v.strip())
        inputs = CVInputs(out=out, data=data, config=config,
                          overrides=cli_overrides(set_, epochs, seed), variants=names,
                          executor=executor, workers=workers, address=address,
                          overwrite=overwrite)
        res, doc = table2(inputs, _log)
        _emit(doc, as_json, res.table())

    @app.command("train", short_help="The deployment fit of the NSS on every trial.")
    def train(
        data: Path | None = data_opt, config: Path | None = config_opt,
        epochs: int | None = epochs_opt, seed: int | None = seed_opt,
        set_: list[str] = set_opt,
        processes: int | None = typer.Option(
            None, "--processes", help="Share each step's windows over N processes "
            "(train.processes; data-parallel, another rounding: a fit of its own)."),
        out: Path = typer.Option(Path("runs/train"), "--out", help="Run folder."),
        resume: bool = typer.Option(False, "--resume", help="Continue from out/state."),
        overwrite: bool = typer.Option(
            False, "--overwrite", help="Train afresh into an --out that holds an earlier run."
        ),
        as_json: bool = json_opt,
    ) -> None:
        """The deployment fit on every trial (paper config); writes out/model (atomically;
        a fresh fit refuses an --out holding an earlier run unless --overwrite)."""
        from parknss.experiments.training import TrainInputs, train_deployment
        from parknss.nss.config import cli_overrides

        over = cli_overrides(set_, epochs, seed)
        if processes is not None:
            over.setdefault("train", {})["processes"] = processes
        inputs = TrainInputs(out=out, data=data, config=config, overrides=over, resume=resume,
                             overwrite=overwrite)
        doc, text = train_deployment(inputs)
        _emit(doc, as_json, text)

    @app.command("evaluate", short_help="Open-loop errors over whole trials (Fig. 5).")
    def evaluate(
        model: Path | None = typer.Option(
            None, "--model", help="NSS model folder (default: shipped)."
        ),
        chain: Path | None = typer.Option(
            None, "--chain", help="Evaluate a command-to-vehicle chain folder instead."
        ),
        data: Path | None = data_opt,
        limiter: bool = typer.Option(False, "--limiter", help="Apply the inference limiter."),
        out: Path = typer.Option(Path("runs/evaluate"), "--out", help="Run folder."),
        overwrite: bool = over_opt, as_json: bool = json_opt,
    ) -> None:
        """Open-loop errors of a model over whole trials (Fig. 5 for two maneuvers)."""
        from parknss.experiments.evaluate import EvaluateInputs, evaluate_open_loop

        doc, text = evaluate_open_loop(EvaluateInputs(out=out, model=model, chain=chain, data=data,
                                                      limiter=limiter, overwrite=overwrite))
        _emit(doc, as_json, text)
