"""``parknss train`` as one library call: the all-trials deployment fit (paper §IV-B).

:func:`train_deployment` fits the NSS on every trial of a campaign (no validation set: the
best checkpoint is chosen on the smoothed training loss), resumable from ``out/state``,
and writes ``out/config.json``, the model artefact ``out/model`` (atomically), the loss
history ``out/history.json`` and its figure. A fresh fit refuses an ``out`` holding an
earlier run unless ``overwrite`` (``--resume`` continues that run on purpose).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from parknss.experiments.folds import fold_config
from parknss.nss import train_state
from parknss.nss.campaigns import load_campaign
from parknss.nss.checkpoint import save_model
from parknss.nss.train import fit, geometry_of
from parknss.outputs import artefact_folder, check_writable, keep_on_interrupt
from parknss.report.nss_figures import draw_history


@dataclass(frozen=True, kw_only=True)
class TrainInputs:
    """The run folder ``out``, campaign ``data`` (None: default), NSS YAML ``config`` (None:
    shipped), ``overrides`` {section: {field: value}}, ``resume``, ``overwrite``."""

    out: Path
    data: Path | None = None
    config: Path | None = None
    overrides: dict = field(default_factory=dict)
    resume: bool = False
    overwrite: bool = False


def _kept(out: Path) -> str:
    """What an interrupted ``parknss train`` keeps and how to resume it, for one line."""
    state = out / "state"
    if train_state.exists(state):
        return (f"training state kept in {state}; resume with "
                f"`parknss train --out {out} --resume` (and the same --data/--config/--set)")
    return (f"no training state saved yet in {state}; start again with "
            f"`parknss train --out {out} --overwrite`")


def train_deployment(inputs: TrainInputs) -> tuple[dict, str]:
    """Fit and write (see the module doc); (the JSON document, a one-line summary)."""
    out = inputs.out
    cfg = fold_config(str(inputs.config) if inputs.config else None, inputs.overrides)
    campaign = load_campaign(inputs.data, "nss", "parknss train")
    if not inputs.resume:  # --resume continues the run in --out on purpose
        check_writable(out, overwrite=inputs.overwrite, kind="model")
    out.mkdir(parents=True, exist_ok=True)
    (out / "config.json").write_text(json.dumps(cfg.model_dump(mode="json"), indent=2))
    with keep_on_interrupt(lambda: _kept(out)):
        res = fit(
            list(campaign), [], cfg, geometry_of(campaign), out_dir=out / "state",
            resume=inputs.resume,
        )
    model_dir = out / "model"
    with artefact_folder(model_dir, overwrite=True, kind="model") as tmp:
        save_model(tmp, res.model, cfg, res.training_meta())
    h = res.history
    (out / "history.json").write_text(json.dumps(h.to_json()))
    fig = draw_history(
        h.crit_epochs,
        h.crit_raw,
        h.crit_smooth,
        out / "fig4_training.png",
        best_epoch=res.best_epoch,
        criterion="training loss",
    )
    doc = {"model": str(model_dir), "figure": str(fig), **res.training_meta()}
    steps = "epochs" if res.recipe == "paper" else f"steps of the {res.recipe} recipe"
    p = res.config.train.processes
    on = f" on {p} processes ({res.cpu_s or 0.0:.0f} CPU s)" if p > 1 else ""
    text = (
        f"trained {res.epochs_run} {steps} on {len(campaign)} trials "
        f"({res.n_windows} windows of {res.window_length}) in {res.wall_s:.0f} s{on}; "
        f"best step {res.best_epoch} (smoothed {h.criterion} {res.best_value:.5f}); "
        f"model in {model_dir}"
    )
    return doc, text
