"""``parknss export``: the learned plant outside parknss.

* ``fmu``: the chain as an FMI 2.0 co-simulation FMU, generated C from the artefact's
  weights built by the system C compiler (:func:`parknss.export.fmu.export_fmu`);
  ``--verify`` then drives it with FMPy under every trial's logged commands of ``--data``
  and prints the largest difference to the real-time chain
  (:func:`parknss.export.verify.fmu_trial_errors`).
* ``onnx``: one 10 ms step of the chain (``--chain``) or of the NSS (``--model``) as an
  ONNX graph checked by onnx.checker (:func:`parknss.export.onnx_step.export_onnx`).

Each prints one line, or one JSON document with ``--json``.
"""

from __future__ import annotations

import json
from pathlib import Path

import typer


def register(app: typer.Typer) -> None:
    sub = typer.Typer(help="The learned plant outside parknss: FMU and ONNX.",
                      short_help="The learned plant as an FMU or ONNX graph.",
                      no_args_is_help=True)
    app.add_typer(sub, name="export")
    json_opt = typer.Option(False, "--json", help="Print one JSON document.")
    over_opt = typer.Option(False, "--overwrite", help="Replace an existing file.")

    @sub.command("fmu", short_help="FMI 2.0 co-simulation FMU of the chain.")
    def fmu(
        out: Path = typer.Option(..., "--out", help="FMU file to write (.fmu)."),
        chain: Path | None = typer.Option(None, "--chain", help="Chain folder (models/plant)."),
        verify: bool = typer.Option(False, "--verify", help="Replay --data through FMPy."),
        data: Path | None = typer.Option(None, "--data", help="Campaign for --verify."),
        overwrite: bool = over_opt, as_json: bool = json_opt,
    ) -> None:
        """FMI 2.0 co-simulation FMU of the chain (C source + linux64 binary)."""
        from parknss.export.fmu import export_fmu

        doc = export_fmu(out, chain, overwrite).to_json()
        if verify:
            from parknss.chain.deployed import load_chain
            from parknss.config import SHIPPED_PLANT
            from parknss.export.verify import fmu_trial_errors
            from parknss.nss.campaigns import load_campaign

            trials = list(load_campaign(data, "actuators", "parknss export fmu --verify"))

            def show(i: int, n: int, e) -> None:
                typer.echo(f"[verify] {i}/{n} {e.trial}: largest difference {e.worst:.3g}",
                           err=True)

            errs = fmu_trial_errors(out, load_chain(chain or SHIPPED_PLANT), trials, show)
            doc["verify"] = {e.trial: e.max_abs for e in errs}
            doc["verify_worst"] = max(e.worst for e in errs)
        if as_json:
            typer.echo(json.dumps(doc, indent=2))
            return
        typer.echo(f"wrote {doc['fmu']} ({doc['bytes']} bytes, built in {doc['build_s']} s)")
        if verify:
            typer.echo(f"FMPy vs real-time chain over {len(doc['verify'])} trials: "
                       f"largest difference {doc['verify_worst']:.3g}")

    @sub.command("onnx", short_help="One 10 ms step as an ONNX graph.")
    def onnx(
        out: Path = typer.Option(..., "--out", help="ONNX file to write (.onnx)."),
        model: Path | None = typer.Option(None, "--model", help="NSS model folder."),
        chain: Path | None = typer.Option(None, "--chain", help="Chain folder (models/plant)."),
        overwrite: bool = over_opt, as_json: bool = json_opt,
    ) -> None:
        """One 10 ms step (state, command -> next state, outputs) as an ONNX graph."""
        from parknss.export.onnx_step import export_onnx

        doc = export_onnx(out, model, chain, overwrite).to_json()
        if as_json:
            typer.echo(json.dumps(doc, indent=2))
        else:
            typer.echo(f"wrote {doc['onnx']} ({doc['kind']} step, state of "
                       f"{doc['state_size']})")
