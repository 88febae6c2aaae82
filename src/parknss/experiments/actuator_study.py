"""``parknss actuators study`` as one library call: selection, co-tuning, Figs. 6 and 3.

On the stratified selection split of a campaign (fold ``select.val_fold``),
:func:`run_actuator_study` runs Phase A (as executor jobs, :class:`StudyInputs.fanout`)
and Phase B (:func:`parknss.chain.selection.run_selection`), co-tunes the co-tuning
target inside the selected assembly (:func:`parknss.chain.study.run_cotune_study`), draws
Fig. 6 (signal fidelity vs closed-loop value) and Fig. 3 (the winners replayed on a
held-out park-out) and writes ``study.json`` and ``selection.json`` (the winners, what
``parknss actuators build --selection`` reads) to the run folder ``out``
(:func:`parknss.outputs.run_folder`: refused if it holds anything but the same study,
unless ``overwrite``). :func:`study_text` prints it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from parknss.actuators.data import channel_data
from parknss.actuators.fit import replay
from parknss.actuators.phase_a import Fanout
from parknss.actuators.spec import ACTUAL_OF, CHANNELS, COMMAND_OF
from parknss.chain.build import load_inputs, nss_info
from parknss.chain.selection import Selection, run_selection
from parknss.chain.study import (
    correlations,
    fidelity_points,
    run_cotune_study,
    selected_variants,
)
from parknss.outputs import run_folder
from parknss.report.actuator_figures import autohold_mask, draw_fidelity, draw_replay
from parknss.signals import DT

UNITS = {"drive": ("N·m", "N·m"), "brake": ("bar", "m/s²"), "steering": ("deg", "deg")}
"""channel -> (unit of the actual, unit of the command), for Fig. 3."""


def _quiet(msg: str) -> None:
    pass


@dataclass(frozen=True, kw_only=True)
class StudyInputs:
    """What the study reads: NSS folder (None: shipped), campaign folder (None: default),
    actuator YAML (None: shipped); ``out`` the folder it writes; ``fanout`` how the Phase
    A fits run; ``overwrite`` whether an ``out`` holding something else may be replaced."""

    out: Path
    nss: Path | None = None
    data: Path | None = None
    config: Path | None = None
    fanout: Fanout = field(default_factory=Fanout)
    overwrite: bool = False


def _fig3(sel: Selection, path: Path) -> Path:
    """Fig. 3: each winner replayed open loop on a held-out park-out trial."""
    park_out = next((t for t in sel.val if t.maneuver.startswith("park_out")), sel.val[0])
    rows = []
    for ch in CHANNELS:
        m = sel.pool[sel.winners()[ch]].model
        d = channel_data(m.spec, [park_out], sel.env)
        rows.append({"name": ACTUAL_OF[ch], "unit": UNITS[ch][0],
                     "cmd": park_out[COMMAND_OF[ch]], "cmd_unit": UNITS[ch][1],
                     "actual": park_out[ACTUAL_OF[ch]], "replay": replay(m, d, sel.env)[0]})
    hold = autohold_mask(park_out["decel_cmd"], park_out["brake_pressure"])
    return draw_replay(np.arange(park_out.n) * DT, rows, hold, f"held-out {park_out.id}", path)


def run_actuator_study(inputs: StudyInputs, progress: Callable[[str], None] = _quiet) -> dict:
    """The study: selection, co-tuning, figures and files; returns the JSON document."""
    t0 = time.perf_counter()
    cfg, loaded, campaign = load_inputs(inputs.nss, inputs.data, inputs.config, "study")
    identity = {"nss": inputs.nss, "data": inputs.data, "config": inputs.config}
    with run_folder(inputs.out, command="parknss actuators study", args=identity,
                    overwrite=inputs.overwrite) as run:
        data = str(inputs.data) if inputs.data is not None else None
        sel = run_selection(loaded.model, campaign, data, cfg, progress, inputs.fanout)
        co = run_cotune_study(loaded.model, sel, cfg, progress)
        pts = fidelity_points(sel)
        corr = correlations(pts)
        out = inputs.out
        before = (co.signal_before["nmse"], co.single_before["vx_full"])
        after = (co.signal_after["nmse"], co.single_after["vx_full"])
        stars = {f"{co.target} before co-tuning": before, f"{co.target} after co-tuning": after}
        files = {"fig6": str(draw_fidelity(pts, stars, sel.phase_b.reference.vx_full, corr,
                                           out / "fig6_fidelity.png"))}
        files["fig3"] = str(_fig3(sel, out / "fig3_replay.png"))
        doc = {
            "nss": nss_info(loaded),
            **sel.to_json(),
            "cotune": co.to_json(),
            "fig6": {"points": pts, **corr},
            "selected_variants": selected_variants(sel),
            "wall_s": time.perf_counter() - t0,
            "files": files,
        }
        run.write_json("study.json", doc, default=float)
        run.write_json("selection.json", {"winners": sel.winners(), "nss": nss_info(loaded)})
        files["json"] = str(out / "study.json")
        files["selection"] = str(out / "selection.json")
    return doc


def _fmt(v) -> str:
    return "-" if v is None else (f"{v:.4g}" if isinstance(v, float) else str(v))


def study_text(doc: dict) -> str:
    """The Phase A and Phase B tables, the winners, Fig. 6's correlation and co-tuning."""
    lines = ["Phase A (held-out signal fidelity)",
             f"{'candidate':28s} {'MSE':>10s} {'MAE':>9s} {'NMSE':>8s} {'delay':>6s} "
             f"{'rise':>6s} {'ovs%':>6s} {'params':>6s}"]
    for r in doc["phase_a"]:
        lines.append(f"{r['candidate']:28s} {_fmt(r['mse']):>10s} {_fmt(r['mae']):>9s} "
                     f"{_fmt(r['nmse']):>8s} {_fmt(r['delay_s']):>6s} {_fmt(r['rise_s']):>6s} "
                     f"{_fmt(r['overshoot_pct']):>6s} {r['n_params']:>6d}")
    pb = doc["phase_b"]
    lines += ["", "Phase B (held-out chained vx MSE, (km/h)^2)",
              f"{'all measured (reference)':36s} {pb['reference']['vx_full']:8.4f} "
              f"{pb['reference']['vx_moving']:8.4f}"]
    for lb, s in pb["single"].items():
        lines.append(f"{lb:36s} {s['vx_full']:8.4f} {s['vx_moving']:8.4f}")
    for a in pb["assemblies"]:
        lab = " + ".join(a["labels"].values())
        lines.append(f"assembly {lab}: {a['vx_full']:.4f} / {a['vx_moving']:.4f}")
    co = doc["cotune"]
    lines += ["", f"winners: {doc['winners']}",
              f"Fig. 6 Pearson r = {doc['fig6']['pearson']:+.3f} "
              f"(log10: {doc['fig6']['pearson_log10']:+.3f}) over {doc['fig6']['n']} pairs",
              f"co-tuning {co['target']}: assembled vx full "
              f"{co['assembled_before']['vx_full']:.4f} -> {co['assembled_after']['vx_full']:.4f}",
              f"wrote {doc['files']}"]
    return "\n".join(lines)
