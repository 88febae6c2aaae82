"""``parknss campaign``: generate, describe and import field-test campaigns.

``generate`` and ``import`` write the campaign folder atomically and refuse a folder that
holds anything already unless ``--overwrite`` (:mod:`parknss.outputs`).
"""

from __future__ import annotations

import json
from enum import StrEnum
from pathlib import Path

import typer

OVERWRITE_HELP = "Replace an existing campaign (or other content) at --out."


class Condition(StrEnum):
    """Per-trial conditions profiles of the reference vehicle (docs/reference.md)."""

    none = "none"
    typical = "typical"
    harsh = "harsh"


def register(app: typer.Typer) -> None:
    sub = typer.Typer(
        help="Generate, describe and import field-test campaigns.", no_args_is_help=True,
        short_help="Generate, describe and import campaigns."
    )

    @sub.command("generate", short_help="Generate the synthetic 16-trial campaign.")
    def generate(
        out: Path = typer.Option(..., "--out", help="Folder to write the campaign to."),
        seed: int = typer.Option(0, "--seed", help="Seed of the repetition perturbations."),
        vehicle: Path | None = typer.Option(None, "--vehicle", help="Reference-vehicle YAML."),
        conditions: Condition | None = typer.Option(
            None, "--conditions", help="Per-trial conditions profile (default: the YAML's)."
        ),
        overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
    ) -> None:
        """Drive the synthetic reference vehicle through the paper's 16-trial campaign."""
        from parknss.data.io import write_campaign
        from parknss.outputs import check_writable
        from parknss.reference.campaign import generate_campaign

        check_writable(out, overwrite=overwrite, kind="campaign")
        extra = {} if conditions is None else {"conditions": conditions.value}
        campaign = generate_campaign(seed=seed, vehicle_yaml=vehicle, progress=True, **extra)
        write_campaign(campaign, out, overwrite=overwrite)
        typer.echo(f"wrote {len(campaign)} trials to {out}", err=True)

    @sub.command("stack", short_help="Trials of the reference car parked by parknss's stack.")
    def stack(
        out: Path = typer.Option(..., "--out", help="Folder to write the campaign to."),
        base: Path | None = typer.Option(None, "--base", help="Campaign the trials are added to "
                                         "(default: the bundled one)."),
        no_base: bool = typer.Option(False, "--no-base", help="Write the stack trials alone."),
        seed: int = typer.Option(0, "--seed", help="Seed of the scene draws and conditions."),
        repetitions: int | None = typer.Option(None, "--repetitions", help="Trials per class."),
        vehicle: Path | None = typer.Option(None, "--vehicle", help="Reference-vehicle YAML."),
        config: Path | None = typer.Option(None, "--config", help="stack_trials YAML."),
        overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
    ) -> None:
        """Park the reference vehicle with parknss's planner, tracker and interface on scenes
        held out from the fidelity grids; write them as campaign trials (docs/reference.md)."""
        from parknss.config import BUNDLED_CAMPAIGN
        from parknss.data.io import read_campaign, write_campaign
        from parknss.errors import ConfigError
        from parknss.outputs import check_writable
        from parknss.reference.params import load_vehicle_params
        from parknss.sim import stack_trials as st

        if no_base and base is not None:
            raise ConfigError("--base and --no-base: give one")
        check_writable(out, overwrite=overwrite, kind="campaign")
        cfg = st.load_stack_config(config, repetitions)
        camp = None if no_base else read_campaign(base or BUNDLED_CAMPAIGN)
        params = load_vehicle_params(vehicle)
        st.check_base(camp, params)
        profile = None if camp is None else camp.meta.get("conditions_profile", "none")
        trials = st.generate_stack_trials(seed, vehicle, cfg, conditions=profile, progress=True)
        campaign = st.stack_campaign(trials, params, camp, seed, cfg)
        write_campaign(campaign, out, overwrite=overwrite)
        typer.echo(f"wrote {len(campaign)} trials ({len(trials)} stack trials) to {out}", err=True)

    @sub.command("describe", short_help="Per-trial summary and physics checks.")
    def describe(
        path: Path = typer.Argument(..., help="Campaign folder."),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
    ) -> None:
        """Per-trial summary and campaign-level physics checks."""
        from parknss.data.describe import describe_campaign
        from parknss.data.io import read_campaign
        from parknss.reference.conditions import conditions_rows, conditions_summary

        campaign = read_campaign(path)
        summary, conds = describe_campaign(campaign), conditions_summary(campaign)
        if as_json:
            typer.echo(json.dumps({**summary.to_json(), "conditions": conds}, indent=2))
        else:
            typer.echo("\n".join([summary.table(), *conditions_rows(conds)]))

    @sub.command("import", short_help="Turn a folder of real logs into a campaign.")
    def import_(
        src: Path = typer.Argument(..., help="Folder of logs, one file per trial."),
        out: Path = typer.Option(..., "--out", help="Campaign folder to write."),
        mapping: Path | None = typer.Option(None, "--mapping", help="Channel-mapping YAML."),
        overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
    ) -> None:
        """Turn a folder of real logs (.csv, .parquet, .mat, .mf4, CAN traces) into a campaign."""
        from parknss.data.io import import_folder, skipped_summary, write_campaign
        from parknss.errors import DataError
        from parknss.outputs import check_writable

        target, logs = out.resolve(), src.resolve()
        if target == logs or target in logs.parents:
            raise DataError(f"{out}: holds the logs being imported ({src}); choose another --out")
        check_writable(out, overwrite=overwrite, kind="campaign")
        campaign = import_folder(src, mapping=mapping)
        write_campaign(campaign, out, overwrite=overwrite)
        typer.echo(f"imported {len(campaign)} trials to {out}", err=True)
        if (skipped := skipped_summary(campaign)) is not None:
            typer.echo(skipped, err=True)

    app.add_typer(sub, name="campaign")
