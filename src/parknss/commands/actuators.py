"""``parknss actuators``: study, ladder, build, stress (paper §III, §V-E, Table IV).

* ``study``: Phase A and Phase B tables, co-tuning on the split, Fig. 6 and Fig. 3;
  writes study.json, selection.json and the figures to --out.
* ``ladder``: Table IV on every trial (all measured; the assembly with the signal-fitted
  and with the co-tuned 1 s NARX brake; a monolithic NSS on commands; static affine maps).
* ``build``: selects (or reads --selection), fits, co-tunes and writes the deployed chain
  artefact (what ships in models/chain).
* ``stress``: the envelope stress study on a chain artefact.

Every command prints a table, or one JSON document with --json (progress on stderr).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import typer

from parknss.errors import ConfigError, ParknssError

DEFAULT_OUT = Path("runs/actuators")


def _log(msg: str) -> None:
    typer.echo(f"[actuators] {msg}", err=True)


def _campaign(data: Path | None, command: str):
    """The campaign of ``parknss actuators <command>``, refused (one line) if it lacks a
    channel the actuator chain needs (parknss.data.workflows)."""
    from parknss.nss.campaigns import load_campaign

    return load_campaign(data, "actuators", f"parknss actuators {command}")


def _setup(nss: Path | None, data: Path | None, config: Path | None, command: str):
    import torch

    from parknss.actuators.config import load_actuator_config
    from parknss.config import SHIPPED_NSS
    from parknss.nss.checkpoint import load_model

    torch.set_num_threads(1)
    cfg = load_actuator_config(config)
    campaign = _campaign(data, command)
    loaded = load_model(nss or SHIPPED_NSS)
    return cfg, loaded, campaign


def _selection_winners(path: Path) -> dict[str, str]:
    if not path.is_file():
        raise ConfigError(f"{path}: selection file not found")
    try:
        doc = json.loads(path.read_text())
        winners = doc["winners"]
    except (json.JSONDecodeError, KeyError, TypeError) as exc:
        raise ConfigError(f"{path}: not a selection.json (no winners)") from exc
    if not isinstance(winners, dict):
        raise ConfigError(f"{path}: winners must be a mapping channel -> candidate")
    return {str(k): str(v) for k, v in winners.items()}


def _nss_info(loaded) -> dict:
    t = loaded.training
    return {"path": str(loaded.path), "epoch": t.get("snapshot_of_epoch", t.get("best_epoch")),
            "epochs": t.get("epochs")}


# ------------------------------------------------------------------------ study


def run_study_command(nss, data, out: Path, config) -> dict:
    """The study: selection, co-tuning, figures; returns the JSON document."""
    import numpy as np

    from parknss.actuators.data import channel_data
    from parknss.actuators.fit import replay
    from parknss.actuators.spec import ACTUAL_OF, CHANNELS, COMMAND_OF
    from parknss.actuators.study import (
        correlations,
        fidelity_points,
        run_cotune_study,
        run_selection,
        selected_variants,
    )
    from parknss.report.actuator_figures import autohold_mask, draw_fidelity, draw_replay

    t0 = time.perf_counter()
    cfg, loaded, campaign = _setup(nss, data, config, "study")
    sel = run_selection(loaded.model, campaign, cfg, _log)
    co = run_cotune_study(loaded.model, sel, cfg, _log)
    pts = fidelity_points(sel)
    corr = correlations(pts)
    out.mkdir(parents=True, exist_ok=True)
    stars = {
        f"{co.target} before co-tuning": (co.signal_before["nmse"], co.single_before["vx_full"]),
        f"{co.target} after co-tuning": (co.signal_after["nmse"], co.single_after["vx_full"]),
    }
    files = {"fig6": str(draw_fidelity(pts, stars, sel.phase_b.reference.vx_full, corr,
                                       out / "fig6_fidelity.png"))}
    park_out = next((t for t in sel.val if t.maneuver.startswith("park_out")), sel.val[0])
    rows = []
    for ch in CHANNELS:
        m = sel.pool[sel.winners()[ch]].model
        d = channel_data(m.spec, [park_out], sel.env)
        rows.append({"name": ACTUAL_OF[ch], "unit": {"drive": "N·m", "brake": "bar",
                                                     "steering": "deg"}[ch],
                     "cmd": park_out[COMMAND_OF[ch]],
                     "cmd_unit": {"drive": "N·m", "brake": "m/s²", "steering": "deg"}[ch],
                     "actual": park_out[ACTUAL_OF[ch]], "replay": replay(m, d, sel.env)[0]})
    hold = autohold_mask(park_out["decel_cmd"], park_out["brake_pressure"])
    files["fig3"] = str(draw_replay(np.arange(park_out.n) * 0.01, rows, hold,
                                    f"held-out {park_out.id}", out / "fig3_replay.png"))
    doc = {
        "nss": _nss_info(loaded),
        **sel.to_json(),
        "cotune": co.to_json(),
        "fig6": {"points": pts, **corr},
        "selected_variants": selected_variants(sel),
        "wall_s": time.perf_counter() - t0,
        "files": files,
    }
    (out / "study.json").write_text(json.dumps(doc, indent=2, default=float))
    (out / "selection.json").write_text(json.dumps(
        {"winners": sel.winners(), "nss": _nss_info(loaded)}, indent=2))
    files["json"] = str(out / "study.json")
    files["selection"] = str(out / "selection.json")
    return doc


def _fmt(v) -> str:
    return "-" if v is None else (f"{v:.4g}" if isinstance(v, float) else str(v))


def print_study(doc: dict) -> None:
    typer.echo("Phase A (held-out signal fidelity)")
    typer.echo(f"{'candidate':28s} {'MSE':>10s} {'MAE':>9s} {'NMSE':>8s} {'delay':>6s} "
               f"{'rise':>6s} {'ovs%':>6s} {'params':>6s}")
    for r in doc["phase_a"]:
        typer.echo(f"{r['candidate']:28s} {_fmt(r['mse']):>10s} {_fmt(r['mae']):>9s} "
                   f"{_fmt(r['nmse']):>8s} {_fmt(r['delay_s']):>6s} {_fmt(r['rise_s']):>6s} "
                   f"{_fmt(r['overshoot_pct']):>6s} {r['n_params']:>6d}")
    pb = doc["phase_b"]
    typer.echo("\nPhase B (held-out chained vx MSE, (km/h)^2)")
    typer.echo(f"{'all measured (reference)':36s} {pb['reference']['vx_full']:8.4f} "
               f"{pb['reference']['vx_moving']:8.4f}")
    for lb, s in pb["single"].items():
        typer.echo(f"{lb:36s} {s['vx_full']:8.4f} {s['vx_moving']:8.4f}")
    for a in pb["assemblies"]:
        lab = " + ".join(a["labels"].values())
        typer.echo(f"assembly {lab}: {a['vx_full']:.4f} / {a['vx_moving']:.4f}")
    typer.echo(f"\nwinners: {doc['winners']}")
    typer.echo(f"Fig. 6 Pearson r = {doc['fig6']['pearson']:+.3f} "
               f"(log10: {doc['fig6']['pearson_log10']:+.3f}) over {doc['fig6']['n']} pairs")
    co = doc["cotune"]
    typer.echo(f"co-tuning {co['target']}: assembled vx full "
               f"{co['assembled_before']['vx_full']:.4f} -> {co['assembled_after']['vx_full']:.4f}")
    typer.echo(f"wrote {doc['files']}")


# ------------------------------------------------------------------------ ladder / build


def _winners(nss_model, campaign, cfg, selection: Path | None) -> tuple[dict, dict | None]:
    if selection is not None:
        return _selection_winners(selection), None
    from parknss.actuators.study import run_selection

    _log("no --selection: running Phase A and Phase B first")
    sel = run_selection(nss_model, campaign, cfg, _log)
    return sel.winners(), sel.to_json()


def run_build(nss, data, out: Path | None, config, selection, monolithic: bool,
              command: str = "build") -> dict:
    """Build the deployment (and optionally the monolithic row); write the artefact.
    ``command`` ("build" or "ladder") names the command in error messages."""
    from parknss.actuators.deploy import build_deployment, monolithic_score
    from parknss.chain import save_chain

    t0 = time.perf_counter()
    cfg, loaded, campaign = _setup(nss, data, config, command)
    winners, sel_doc = _winners(loaded.model, campaign, cfg, selection)
    dep = build_deployment(loaded.model, list(campaign), cfg, winners, _log)
    doc = {"nss": _nss_info(loaded), **dep.to_json()}
    if monolithic and cfg.ladder.monolithic_epochs > 0:
        score, info = monolithic_score(loaded, list(campaign), cfg, _log)
        doc["rows"]["monolithic"] = score.to_json()
        doc["monolithic"] = info
    if sel_doc is not None:
        doc["selection_study"] = sel_doc
    doc["wall_s"] = time.perf_counter() - t0
    if out is not None:
        chain = dep.chain
        chain.nss_config = loaded.config
        chain.nss_training = loaded.training
        meta = {k: v for k, v in doc.items() if k != "selection_study"}
        meta["data_hash"] = campaign.data_hash()
        save_chain(out, chain, meta)
        doc["artefact"] = str(out)
    return doc


LADDER_ROWS = (
    ("all_measured", "All channels measured (reference)"),
    ("signal_target", "Assembled chain, signal-fitted 1 s NARX brake"),
    ("cotuned_target", "Assembled chain, consequence-tuned 1 s NARX brake"),
    ("selected_assembly", "Assembled chain, Phase B winners (no co-tuning)"),
    ("monolithic", "Monolithic NSS on commands, no submodels"),
    ("static_affine", "Static affine actuator maps, no dynamics"),
)


def print_ladder(doc: dict) -> None:
    typer.echo(f"{'Configuration':52s} {'vx full':>9s} {'vx moving':>10s}  [(km/h)^2]")
    for key, name in LADDER_ROWS:
        r = doc["rows"].get(key)
        if r is not None:
            typer.echo(f"{name:52s} {r['vx_full']:9.4f} {r['vx_moving']:10.4f}")
    typer.echo(f"deployed: {doc['deployed']}")
    if "artefact" in doc:
        typer.echo(f"wrote {doc['artefact']}")


# ------------------------------------------------------------------------ stress


def run_stress_command(chain: Path | None, data: Path | None, config) -> dict:
    import torch

    from parknss.actuators.config import load_actuator_config
    from parknss.actuators.stress import run_stress
    from parknss.chain import load_chain
    from parknss.config import SHIPPED_CHAIN

    torch.set_num_threads(1)
    cfg = load_actuator_config(config)
    campaign = _campaign(data, "stress")
    dep = load_chain(chain or SHIPPED_CHAIN)
    tr = next((t for t in campaign if t.maneuver.startswith("park_in")), campaign[0])
    rows = run_stress(dep, tr, cfg.stress)
    return {"chain": str(chain or SHIPPED_CHAIN), "trial": tr.id,
            "envelope": dep.chain.envelope.to_json(), "rows": [r.to_json() for r in rows],
            "ok": all(r.violations == 0 and r.nonfinite_states == 0 for r in rows)}


def print_stress(doc: dict) -> None:
    typer.echo(f"{'scenario':14s} {'viol':>5s} {'NaN st':>6s} {'torque':>16s} {'pressure':>14s} "
               f"{'steer':>18s} {'rate°/s':>8s}  active envelopes")
    for r in doc["rows"]:
        typer.echo(
            f"{r['scenario']:14s} {r['violations']:5d} {r['nonfinite_states']:6d} "
            f"{r['torque_range'][0]:7.1f}..{r['torque_range'][1]:<7.1f} "
            f"{r['pressure_range'][0]:5.1f}..{r['pressure_range'][1]:<7.1f} "
            f"{r['steer_range'][0]:8.1f}..{r['steer_range'][1]:<8.1f} "
            f"{r['max_steer_rate_dps']:8.1f}  {', '.join(sorted(set(r['active']))) or '-'}")
    typer.echo("all within envelopes, no NaN states" if doc["ok"] else "ENVELOPE VIOLATED")


# ------------------------------------------------------------------------ register


def register(app: typer.Typer) -> None:
    sub = typer.Typer(help="Actuator submodels, selection, co-tuning, the chain (§III, §V-E).",
                      no_args_is_help=True)
    app.add_typer(sub, name="actuators")
    nss_opt = typer.Option(None, "--nss", help="NSS model folder (default models/nss).")
    data_opt = typer.Option(None, "--data", help="Campaign folder (default campaign).")
    cfg_opt = typer.Option(None, "--config", help="Actuator YAML (configs/actuators.yaml).")
    json_opt = typer.Option(False, "--json", help="Print one JSON document.")
    sel_opt = typer.Option(None, "--selection", help="selection.json of a study (skips A/B).")

    def emit(doc: dict, as_json: bool, printer) -> None:
        if as_json:
            typer.echo(json.dumps(doc, indent=2, default=float))
        else:
            printer(doc)

    @sub.command("study")
    def study(
        nss: Path | None = nss_opt, data: Path | None = data_opt,
        out: Path = typer.Option(DEFAULT_OUT / "study", "--out", help="Output folder."),
        config: Path | None = cfg_opt, as_json: bool = json_opt,
    ) -> None:
        """Phase A/B tables, co-tuning on the split, Fig. 6 and Fig. 3."""
        emit(run_study_command(nss, data, out, config), as_json, print_study)

    @sub.command("ladder")
    def ladder(
        nss: Path | None = nss_opt, data: Path | None = data_opt,
        selection: Path | None = sel_opt, config: Path | None = cfg_opt,
        save: Path | None = typer.Option(None, "--save", help="Also write the chain here."),
        as_json: bool = json_opt,
    ) -> None:
        """Table IV: every row measured on every trial."""
        emit(run_build(nss, data, save, config, selection, True, "ladder"), as_json,
             print_ladder)

    @sub.command("build")
    def build(
        nss: Path = typer.Option(..., "--nss", help="NSS model folder."),
        out: Path = typer.Option(..., "--out", help="Chain artefact folder to write."),
        data: Path | None = data_opt, selection: Path | None = sel_opt,
        config: Path | None = cfg_opt, as_json: bool = json_opt,
    ) -> None:
        """Select, fit, co-tune and write the deployed chain artefact."""
        emit(run_build(nss, data, out, config, selection, False), as_json, print_ladder)

    @sub.command("stress")
    def stress(
        chain: Path | None = typer.Option(None, "--chain", help="Chain folder (models/chain)."),
        data: Path | None = data_opt, config: Path | None = cfg_opt, as_json: bool = json_opt,
    ) -> None:
        """Envelope stress study: out-of-domain, NaN and inf command streams."""
        doc = run_stress_command(chain, data, config)
        emit(doc, as_json, print_stress)
        if not doc["ok"]:
            raise ParknssError("the chain left its envelopes under stress (see the table)")
