"""``parknss actuators``: study, ladder, build, stress (paper §III, §V-E, Table IV).

* ``study``: Phase A and Phase B tables, co-tuning on the split, Fig. 6 and Fig. 3;
  writes study.json, selection.json and the figures to the run folder --out (refused if
  it holds anything but the same study unless --overwrite)
  (:func:`parknss.experiments.actuator_study.run_actuator_study`). The Phase A fits run
  through the one executor: ``--executor local|ray``, ``--workers``, ``--address``.
* ``ladder``: Table IV on every trial (all measured; the assembly with the signal-fitted
  and with the co-tuned 1 s NARX brake; a monolithic NSS on commands; static affine maps).
* ``build``: selects (or reads --selection), fits, co-tunes and writes the deployed chain
  artefact (what ships in models/chain); ladder and build are
  :func:`parknss.chain.build.run_build`.
* ``stress``: the envelope stress study on a chain artefact
  (:func:`parknss.chain.stress.stress_study`).

Every command prints a table, or one JSON document with --json (progress on stderr).
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

from parknss.errors import ParknssError

DEFAULT_OUT = Path("runs/actuators")


def _log(msg: str) -> None:
    typer.echo(f"[actuators] {msg}", err=True)


def _emit(doc: dict, as_json: bool, text) -> None:
    typer.echo(json.dumps(doc, indent=2, default=float) if as_json else text(doc))


def register(app: typer.Typer) -> None:
    sub = typer.Typer(help="Actuator submodels, selection, co-tuning, the chain (§III, §V-E).",
                      short_help="Actuator submodels, selection, the chain.",
                      no_args_is_help=True)
    app.add_typer(sub, name="actuators")
    nss_opt = typer.Option(None, "--nss", help="NSS model folder (default models/nss).")
    data_opt = typer.Option(None, "--data", help="Campaign folder (default campaign).")
    cfg_opt = typer.Option(None, "--config", help="Actuator YAML (configs/actuators.yaml).")
    json_opt = typer.Option(False, "--json", help="Print one JSON document.")
    sel_opt = typer.Option(None, "--selection", help="selection.json of a study (skips A/B).")
    over_opt = typer.Option(False, "--overwrite", help="Replace a chain already in the folder.")

    @sub.command("study", short_help="Phase A/B selection and co-tuning (Figs. 3, 6).")
    def study(
        nss: Path | None = nss_opt, data: Path | None = data_opt,
        out: Path = typer.Option(DEFAULT_OUT / "study", "--out", help="Output folder."),
        config: Path | None = cfg_opt,
        executor: str = typer.Option("local", "--executor", help="local | ray"),
        workers: int = typer.Option(1, "--workers", help="Parallel Phase A fits."),
        address: str | None = typer.Option(None, "--address", help="Ray cluster address."),
        overwrite: bool = typer.Option(False, "--overwrite", help="Replace what --out holds."),
        as_json: bool = json_opt,
    ) -> None:
        """Phase A/B tables, co-tuning on the split, Fig. 6 and Fig. 3."""
        from parknss.actuators.phase_a import Fanout
        from parknss.experiments.actuator_study import (
            StudyInputs,
            run_actuator_study,
            study_text,
        )

        inputs = StudyInputs(out=out, nss=nss, data=data, config=config,
                             fanout=Fanout(executor, workers, address), overwrite=overwrite)
        _emit(run_actuator_study(inputs, _log), as_json, study_text)

    @sub.command("ladder", short_help="Table IV: every row measured on every trial.")
    def ladder(
        nss: Path | None = nss_opt, data: Path | None = data_opt,
        selection: Path | None = sel_opt, config: Path | None = cfg_opt,
        save: Path | None = typer.Option(None, "--save", help="Also write the chain here."),
        overwrite: bool = over_opt, as_json: bool = json_opt,
    ) -> None:
        """Table IV: every row measured on every trial."""
        from parknss.chain.build import BuildInputs, run_build
        from parknss.chain.ladder import ladder_text

        inputs = BuildInputs(nss=nss, data=data, config=config, selection=selection,
                             out=save, monolithic=True, overwrite=overwrite, command="ladder")
        _emit(run_build(inputs, _log), as_json, ladder_text)

    @sub.command("build", short_help="Select, fit, co-tune and write the chain.")
    def build(
        nss: Path = typer.Option(..., "--nss", help="NSS model folder."),
        out: Path = typer.Option(..., "--out", help="Chain artefact folder to write."),
        data: Path | None = data_opt, selection: Path | None = sel_opt,
        config: Path | None = cfg_opt, overwrite: bool = over_opt, as_json: bool = json_opt,
    ) -> None:
        """Select, fit, co-tune and write the deployed chain artefact."""
        from parknss.chain.build import BuildInputs, run_build
        from parknss.chain.ladder import ladder_text

        inputs = BuildInputs(nss=nss, data=data, config=config, selection=selection, out=out,
                             overwrite=overwrite)
        _emit(run_build(inputs, _log), as_json, ladder_text)

    @sub.command("stress", short_help="Envelope stress study of the chain.")
    def stress(
        chain: Path | None = typer.Option(None, "--chain", help="Chain folder (models/chain)."),
        data: Path | None = data_opt, config: Path | None = cfg_opt, as_json: bool = json_opt,
    ) -> None:
        """Envelope stress study: out-of-domain, NaN and inf command streams."""
        from parknss.chain.stress import stress_study, stress_text

        doc = stress_study(chain, data, config)
        _emit(doc, as_json, stress_text)
        if not doc["ok"]:
            raise ParknssError("the chain left its envelopes under stress (see the table)")
