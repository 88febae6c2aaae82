"""``parknss demo``: the main job on the bundled synthetic campaign and the shipped plant.

Five steps, each writing its artefacts to the run folder:

1. describe the campaign and draw one trial (commands vs actuals, states, reverse shaded);
2. the shipped NSS (models/nss) rolled out open loop over every trial from the logged
   actuals: errors against the logged and the noise-free truth channels, Fig. 5;
3. the shipped command-to-vehicle chain (models/chain) rolled out from the logged
   commands: the same errors, and its ISO/TS 18571 rating (raw and 5 Hz filtered, Fig. 7);
4. one parking cell planned and executed in closed loop under the ideal kinematic plant
   and the deployed plant (models/plant, the closed-loop recipe's chain; Fig. 8, Fig. 9);
5. ``summary.json`` with every number printed (:func:`summary_text`).

``summary.json`` is tidy (:func:`tidy`): floats at 6 significant digits (no
3.1100000000000003), the within/beyond-horizon fields only where a training window exists
(the NSS; the chain has none, so its errors carry no such nulls), and the closed loop as
the scene and plan once with one entry per plant under ``closed_loop.runs``
(``{"kinematic": {...}, "chain": {...}}``): no plant's numbers at the top level.

The run folder is claimed through :func:`parknss.outputs.run_folder`: the same demo
(campaign, cell, NSS, chain) may run again into it, anything else there is refused unless
``overwrite``; every file is written atomically.

The shipped artefacts are required: a missing one is an error that names it (there is no
stand-in).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from parknss.chain.deployed import load_chain
from parknss.chain.rating import RateInputs
from parknss.config import BUNDLED_CAMPAIGN, SHIPPED_CHAIN, SHIPPED_NSS
from parknss.data.describe import describe_campaign
from parknss.data.io import read_campaign
from parknss.errors import CheckpointError
from parknss.experiments.rating import run_rate
from parknss.metrics.errors import logged_and_truth_errors
from parknss.nss.checkpoint import load_model
from parknss.nss.predict import predict_trials
from parknss.outputs import run_folder
from parknss.report.nss_figures import draw_rollouts, pick_maneuvers
from parknss.report.sim_figures import draw_scene_run
from parknss.report.trial_figure import draw_trial
from parknss.sim.session import simulate_scene

Say = Callable[[str], None]


def _quiet(msg: str) -> None:
    pass


@dataclass(frozen=True, kw_only=True)
class DemoInputs:
    """The run folder ``out``, the campaign folder ``data`` (None: the bundled one), the
    grid ``cell`` (0-35) parked in closed loop, the NSS and chain artefacts, and whether an
    ``out`` holding something else may be replaced (``overwrite``)."""

    out: Path
    data: Path | None = None
    cell: int = 26
    nss: Path = SHIPPED_NSS
    chain: Path = SHIPPED_CHAIN
    overwrite: bool = False


HORIZON_KEYS: tuple[str, ...] = ("vx_mse_within_kmh2", "vx_mse_beyond_kmh2",
                                  "yaw_mse_within_degs2", "yaw_mse_beyond_degs2", "horizon")


def _errors(predictions, trials, horizon) -> dict:
    """Errors against the logged (and truth) channels; without a training window (the
    chain) the within/beyond-horizon split does not exist and its keys are left out."""
    docs = dict(zip(("logged", "truth"),
                    logged_and_truth_errors(predictions, trials, horizon), strict=True))
    out = {}
    for ref, e in docs.items():
        if e is None:
            continue
        if horizon is None:
            e = {k: v for k, v in e.items() if k not in HORIZON_KEYS}
            e["counts"] = {k: n for k, n in e["counts"].items() if k not in ("within", "beyond")}
        out[ref] = e
    return out


def tidy(value, digits: int = 6):
    """``value`` with every float rounded to ``digits`` significant digits (nested dicts
    and lists), for a summary people read."""
    if isinstance(value, float):
        return float(f"{value:.{digits}g}")
    if isinstance(value, dict):
        return {k: tidy(v, digits) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [tidy(v, digits) for v in value]
    return value


def closed_loop_doc(run) -> dict:
    """The scene and plan once, then ``runs`` keyed by plant (:class:`SceneRun`'s JSON
    without the first plant's fields at the top level)."""
    full = run.to_json()
    scene_keys = ("scene", "cell", "plannable", "plan_reason", "refined", "plan_s", "cusps",
                  "planned_length_m")
    doc = {k: full[k] for k in scene_keys}
    doc["runs"] = {r["plant"]: {k: v for k, v in r.items() if k != "plant"}
                   for r in full["runs"]}
    doc["plan"] = full["plan"]
    return doc


def _require(path: Path, what: str) -> None:
    if not path.exists():
        raise CheckpointError(
            f"{path}: the shipped {what} is missing (see README, 'Shipped plant')"
        )


def run_demo(inputs: DemoInputs, log: Say = _quiet, show: Say = _quiet) -> dict:
    """All five steps; ``log`` gets progress, ``show`` the campaign and rating tables as
    they are made; returns the summary document (also written to ``summary.json``)."""
    out, nss, chain = inputs.out, inputs.nss, inputs.chain
    _require(nss, "NSS model")
    _require(chain, "command-to-vehicle chain")
    identity = {"data": inputs.data, "cell": inputs.cell, "nss": nss, "chain": chain}
    t0 = time.perf_counter()
    with run_folder(out, command="parknss demo", args=identity,
                    overwrite=inputs.overwrite) as folder:
        src = inputs.data or BUNDLED_CAMPAIGN
        log(f"1/4 campaign {src} (synthetic reference vehicle unless you gave --data)")
        campaign = read_campaign(src)
        trials = list(campaign)
        summary = describe_campaign(campaign)
        show(summary.table())
        doc: dict = {"campaign": summary.to_json(), "figures": {}}
        doc["figures"]["trial"] = str(draw_trial(trials[0], out / "trial.png"))

        log(f"2/4 shipped NSS {nss}: open-loop rollouts of {len(trials)} trials")
        loaded = load_model(nss)
        horizon = loaded.training.get("window_length")
        pred = predict_trials(loaded.model, trials)
        doc["nss"] = {"model": str(nss), **_errors(pred, trials, horizon)}
        doc["figures"]["nss_fig5"] = str(
            draw_rollouts(pick_maneuvers(trials), pred, out / "fig5_nss.png", horizon,
                          title="Shipped NSS, open loop from the logged actuals")
        )

        log(f"3/4 shipped chain {chain}: rollouts from the logged commands, ISO/TS 18571 rating")
        cpred = load_chain(chain).predict_trials(trials)
        doc["chain"] = {"chain": str(chain), **_errors(cpred, trials, None)}
        doc["figures"]["chain_fig5"] = str(
            draw_rollouts(pick_maneuvers(trials), cpred, out / "fig5_chain.png",
                          title="Shipped chain, open loop from the logged commands")
        )
        rating = run_rate(RateInputs(data=src, chain=chain), out / "rate", log)
        doc["rating"] = rating.doc["summary"]
        doc["figures"]["fig7"] = rating.doc["files"]["figure"]
        show(rating.table.table())

        log(f"4/4 closed loop: cell {inputs.cell} under the kinematic plant and the deployed "
            "plant (models/plant)")
        run = simulate_scene(str(inputs.cell), ["kinematic", "chain"])
        doc["closed_loop"] = closed_loop_doc(run)
        doc["figures"].update(draw_scene_run(run, out))
        doc["wall_s"] = round(time.perf_counter() - t0, 1)
        doc = tidy(doc)
        folder.write_json("summary.json", doc, default=str)
    return doc


def _num(v, spec: str) -> str:
    return "-" if v is None else format(v, spec)


def _line(tag: str, e: dict) -> str:
    return (
        f"{tag:<34} vx {e['vx_mse_moving_kmh2']:.4f} (km/h)²  reverse "
        f"{e['vx_mse_reverse_kmh2']:.4f}  yaw {e['yaw_mse_moving_degs2']:.4f} (°/s)²"
    )


def summary_text(doc: dict) -> str:
    """The demo's closing summary: errors of the NSS and the chain, the closed-loop runs."""
    lines = []
    for name in ("nss", "chain"):
        for ref, e in doc[name].items():
            if isinstance(e, dict):
                lines.append(_line(f"{name} vs {ref} channels", e))
    cl = doc["closed_loop"]
    lines.append(f"closed loop, scene {cl['scene']} ({cl['cusps']} cusps):")
    for plant, r in cl["runs"].items():
        lines.append(
            f"  {plant:<10} completed {r['completed']!s:<5} goal error "
            f"{_num(r['goal_error_cm'], '.2f')} cm  heading "
            f"{_num(r['heading_error_deg'], '.2f')} deg  clearance "
            f"{_num(r['clearance_cm'], '.1f')} cm  duration {_num(r['duration_s'], '.1f')} s"
        )
    return "\n".join(lines)
