"""``parknss study``: the evaluation studies one by one, each drawing its table and figure.

``parknss study learning-curve|seed-noise|ablations|limiter|convergence`` runs one study
(``--quick``: the smoke-test budget of configs/experiments.yaml) through the executor
(``--executor local|ray``, ``--workers``, ``--address``) with a result cache in
``<out>/cache`` that every study run into the same ``--out`` with the same budget,
campaign, configs and floor shares and resumes; an ``--out`` holding anything else is
refused unless ``--overwrite`` (:func:`parknss.experiments.studies.run_study`);
``--floor`` names the seed-noise floor that judges the learning curve, the ablations and
the limiter (``measure``, ``paper`` or a seed-noise JSON);
fits are read from the result store (``--store DIR|off``; ``--refit``: fit them all).
``parknss study estimate`` lists each study's fits, those the result store holds, and the
CPU hours of the rest (:mod:`parknss.experiments.plan`); ``parknss study progress OUT``
how far each fit of a run folder has got (:mod:`parknss.experiments.progress`).
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

from parknss.experiments.studies import STUDIES


def _log(msg: str) -> None:
    typer.echo(f"[study] {msg}", err=True)


def register(app: typer.Typer) -> None:
    study_app = typer.Typer(
        help="Evaluation studies: learning curve, seed noise, ablations, limiter, convergence.",
        short_help="The paper's evaluation studies, resumable.",
        no_args_is_help=True,
    )
    app.add_typer(study_app, name="study")
    quick_opt = typer.Option(False, "--quick", help="Smoke-test budget.")
    config_opt = typer.Option(None, "--config", help="Experiments YAML.")
    data_opt = typer.Option(None, "--data", help="Campaign folder.")
    json_opt = typer.Option(False, "--json", help="Print one JSON document.")
    store_opt = typer.Option(
        None, "--store", help="Result store folder or 'off' (default: results/)."
    )
    refit_opt = typer.Option(False, "--refit", help="Refit what the store holds.")

    def _make(name: str):
        def command(
            quick: bool = quick_opt,
            executor: str = typer.Option("local", "--executor", help="local | ray"),
            address: str | None = typer.Option(None, "--address", help="Ray cluster address."),
            workers: int | None = typer.Option(None, "--workers", help="Parallel workers."),
            data: Path | None = data_opt,
            out: Path | None = typer.Option(None, "--out", help="Output folder (and cache)."),
            config: Path | None = config_opt,
            floor: str = typer.Option(
                "measure", "--floor", help="Noise floor: measure | paper | seed-noise JSON."
            ),
            overwrite: bool = typer.Option(
                False, "--overwrite", help="Replace what --out holds (another run, an artefact)."
            ),
            as_json: bool = json_opt,
            store: str | None = store_opt,
            refit: bool = refit_opt,
            axes: str | None = typer.Option(
                None, "--axes", hidden=name != "ablations",
                help="Only these Table III axes, comma-separated, e.g. 'lr schedule,yaw "
                "readout' (default: every axis of the config).",
            ),
        ) -> None:
            from parknss.experiments.studies import StudyInputs, run_study, study_text

            picked = tuple(a.strip() for a in (axes or "").split(",") if a.strip())
            if axes is not None and not picked:
                raise typer.BadParameter("name at least one axis", param_hint="--axes")
            folder = out or Path("runs") / f"study-{name}{'-quick' if quick else ''}"
            inputs = StudyInputs(name=name, out=folder, quick=quick, executor=executor,
                                 workers=workers, address=address, data=data, config=config,
                                 floor=floor, overwrite=overwrite, store=store, refit=refit,
                                 axes=picked)
            run = run_study(inputs, _log)
            if as_json:
                typer.echo(json.dumps(run.doc, indent=2, default=str))
            else:
                typer.echo(study_text(run))

        command.__doc__ = f"Run the {name} study; print its table, write its figure and JSON."
        return command

    for name in STUDIES:
        study_app.command(name, short_help=f"Run the {name} study.")(_make(name))

    @study_app.command("progress", short_help="How far each fit of a run folder has got.")
    def progress_cmd(
        out: Path = typer.Argument(..., help="Run folder of parknss reproduce or study."),
        as_json: bool = json_opt,
    ) -> None:
        """How far each fit of a run folder has got (its training state), named by the plan."""
        from parknss.experiments.progress import HEADER
        from parknss.experiments.studies import run_progress_of

        rows = run_progress_of(out)
        if as_json:
            typer.echo(json.dumps([r.to_json() for r in rows], indent=2))
            return
        typer.echo(HEADER)
        for r in rows:
            typer.echo(r.line())
        done = sum(r.done for r in rows)
        queued = sum(r.queued for r in rows)
        typer.echo(f"{len(rows) - queued} fits with a training state, {done} done"
                   + (f", {queued} queued" if queued else ""))

    @study_app.command("estimate", short_help="Fits per study: stored, parked, CPU hours left.")
    def estimate_cmd(
        quick: bool = quick_opt, config: Path | None = config_opt, data: Path | None = data_opt,
        sec_per_epoch: float | None = typer.Option(
            None, "--sec-per-epoch",
            help="The fused Euler engine's s/epoch (not timed); other engine classes keep "
            "their timed ratio to it.",
        ),
        sec_per_update: float | None = typer.Option(
            None, "--sec-per-update",
            help="The fused Euler engine's s per fast-recipe update (not timed); the "
            "engines of fast eager fits keep their timed ratio to it.",
        ),
        store: str | None = store_opt,
        as_json: bool = json_opt,
    ) -> None:
        """Each study's fits, those in the result store, and CPU hours of the rest."""
        from parknss.experiments.studies import estimate

        est = estimate(quick, config, data, store, sec_per_epoch, sec_per_update, _log)
        typer.echo(json.dumps(est.to_json(), indent=2) if as_json else est.text())
