"""``parknss demo``: the main job on the bundled synthetic campaign and the shipped plant.

Five steps, each writing its artefacts to the run folder:

1. describe the campaign and draw one trial (commands vs actuals, states, reverse shaded);
2. the shipped NSS (models/nss) rolled out open loop over every trial from the logged
   actuals: errors against the logged and the noise-free truth channels, Fig. 5;
3. the shipped command-to-vehicle chain (models/chain) rolled out from the logged
   commands: the same errors, and its ISO/TS 18571 rating (raw and 5 Hz filtered, Fig. 7);
4. one parking cell planned and executed in closed loop under the ideal kinematic plant
   and the learned chain (Fig. 8, Fig. 9);
5. ``summary.json`` with every number printed.

The shipped artefacts are required: a missing one is an error that names it (there is no
stand-in).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import typer

from parknss.config import BUNDLED_CAMPAIGN, SHIPPED_CHAIN, SHIPPED_NSS
from parknss.errors import CheckpointError


def _log(msg: str) -> None:
    typer.echo(f"[demo] {msg}", err=True)


def _errors(predictions, trials, horizon) -> dict:
    from parknss.metrics.errors import logged_and_truth_errors

    logged, truth = logged_and_truth_errors(predictions, trials, horizon)
    return {"logged": logged} if truth is None else {"logged": logged, "truth": truth}


def _line(tag: str, e: dict) -> str:
    return (
        f"{tag:<34} vx {e['vx_mse_moving_kmh2']:.4f} (km/h)²  reverse "
        f"{e['vx_mse_reverse_kmh2']:.4f}  yaw {e['yaw_mse_moving_degs2']:.4f} (°/s)²"
    )


def _require(path: Path, what: str) -> None:
    if not path.exists():
        raise CheckpointError(
            f"{path}: the shipped {what} is missing (see README, 'Shipped plant')"
        )


def run_demo(out: Path, data: Path | None, cell: int, nss: Path, chain: Path) -> dict:
    """All five steps; returns the summary document."""
    from parknss.commands.rate import run_rate
    from parknss.commands.simulate import simulate_scene
    from parknss.data.describe import describe_campaign
    from parknss.data.io import read_campaign
    from parknss.nss.checkpoint import load_model
    from parknss.nss.predict import predict_trials
    from parknss.report.nss_figures import draw_rollouts, pick_maneuvers
    from parknss.report.trial_figure import draw_trial

    _require(nss, "NSS model")
    _require(chain, "command-to-vehicle chain")
    t0 = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    src = data or BUNDLED_CAMPAIGN
    _log(f"1/4 campaign {src} (synthetic reference vehicle unless you gave --data)")
    campaign = read_campaign(src)
    trials = list(campaign)
    summary = describe_campaign(campaign)
    typer.echo(summary.table())
    doc: dict = {"campaign": summary.to_json(), "figures": {}}
    doc["figures"]["trial"] = str(draw_trial(trials[0], out / "trial.png"))

    _log(f"2/4 shipped NSS {nss}: open-loop rollouts of {len(trials)} trials")
    loaded = load_model(nss)
    horizon = loaded.training.get("window_length")
    pred = predict_trials(loaded.model, trials)
    doc["nss"] = {"model": str(nss), **_errors(pred, trials, horizon)}
    doc["figures"]["nss_fig5"] = str(
        draw_rollouts(
            pick_maneuvers(trials),
            pred,
            out / "fig5_nss.png",
            horizon,
            title="Shipped NSS, open loop from the logged actuals",
        )
    )

    _log(f"3/4 shipped chain {chain}: rollouts from the logged commands, ISO/TS 18571 rating")
    from parknss.chain import load_chain

    cpred = load_chain(chain).predict_trials(trials)
    doc["chain"] = {"chain": str(chain), **_errors(cpred, trials, None)}
    doc["figures"]["chain_fig5"] = str(
        draw_rollouts(
            pick_maneuvers(trials),
            cpred,
            out / "fig5_chain.png",
            title="Shipped chain, open loop from the logged commands",
        )
    )
    rating = run_rate(src, None, False, out / "rate", chain=chain)
    table = rating.pop("_table")
    doc["rating"] = rating["summary"]
    doc["figures"]["fig7"] = rating["files"]["figure"]
    typer.echo(table.table())

    _log(f"4/4 closed loop: cell {cell} under the kinematic plant and the learned chain")
    sim = simulate_scene(str(cell), ["kinematic", "chain"], out)
    doc["closed_loop"] = {k: v for k, v in sim.items() if k != "figures"}
    doc["figures"].update(sim.get("figures", {}))
    doc["wall_s"] = round(time.perf_counter() - t0, 1)
    return doc


def _report(doc: dict) -> None:
    for name in ("nss", "chain"):
        for ref, e in doc[name].items():
            if isinstance(e, dict):
                typer.echo(_line(f"{name} vs {ref} channels", e))
    cl = doc["closed_loop"]
    typer.echo(f"closed loop, scene {cl['scene']} ({cl['cusps']} cusps):")
    for r in cl["runs"]:
        typer.echo(
            f"  {r['plant']:<10} completed {r['completed']!s:<5} goal error "
            f"{_num(r['goal_error_cm'], '.2f')} cm  heading "
            f"{_num(r['heading_error_deg'], '.2f')} deg  clearance "
            f"{_num(r['clearance_cm'], '.1f')} cm  duration {_num(r['duration_s'], '.1f')} s"
        )


def _num(v, spec: str) -> str:
    return "-" if v is None else format(v, spec)


def register(app: typer.Typer) -> None:
    @app.command("demo")
    def demo(
        out: Path = typer.Option(Path("runs/demo"), "--out", help="Run folder."),
        data: Path | None = typer.Option(
            None, "--data", help="Campaign folder (default: the bundled synthetic campaign)."
        ),
        cell: int = typer.Option(26, "--cell", help="Grid cell (0-35) to park in closed loop."),
        nss: Path = typer.Option(SHIPPED_NSS, "--nss", help="NSS model folder."),
        chain: Path = typer.Option(SHIPPED_CHAIN, "--chain", help="Chain artefact folder."),
    ) -> None:
        """Describe the campaign, evaluate and rate the shipped plant, park through it."""
        doc = run_demo(out, data, cell, nss, chain)
        (out / "summary.json").write_text(json.dumps(doc, indent=2, default=str))
        _report(doc)
        _log(f"done in {doc['wall_s']} s: artefacts in {out} (summary.json, PNG figures)")
