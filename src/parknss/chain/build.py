"""``parknss actuators build`` and ``ladder`` as one library call: the deployed chain.

:func:`run_build` loads the actuator config, the campaign and the NSS named by a
:class:`BuildInputs`, takes the Phase B winners from a ``selection.json`` (or runs the
two-phase selection first, :func:`parknss.chain.selection.run_selection`), fits and
co-tunes the deployment chain on every trial and scores the Table IV rows
(:func:`parknss.chain.ladder.build_deployment`; with ``monolithic`` also the monolithic
NSS row), and writes the chain artefact when ``out`` is given (atomically; a folder
holding another artefact is refused unless ``overwrite``). It returns one JSON document.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import torch

from parknss.actuators.config import ActuatorConfig, load_actuator_config
from parknss.actuators.phase_a import Fanout
from parknss.chain.deployed import save_chain
from parknss.chain.ladder import build_deployment, monolithic_score
from parknss.chain.selection import run_selection
from parknss.config import SHIPPED_NSS
from parknss.data.trial import Campaign
from parknss.errors import ConfigError
from parknss.nss.campaigns import load_campaign
from parknss.nss.checkpoint import LoadedModel, load_model
from parknss.outputs import artefact_folder, check_writable

Progress = Callable[[str], None]


def _quiet(msg: str) -> None:
    pass


@dataclass(frozen=True, kw_only=True)
class BuildInputs:
    """What a build reads and writes.

    Attributes:
        nss: NSS model folder (None: the shipped ``models/nss``).
        data: campaign folder (None: the default campaign).
        config: actuator YAML (None: the shipped ``configs/actuators.yaml``).
        selection: a study's ``selection.json`` (None: ``winners``, else run Phase A and
            B first).
        winners: channel -> candidate label, when no ``selection`` file is given (the
            Phase B winners a chain artefact records).
        out: chain artefact folder to write (None: score only).
        monolithic: also train and score the monolithic-NSS row of Table IV.
        overwrite: replace an artefact already at ``out``.
        command: "build" or "ladder", for messages (``parknss actuators <command>``).
        fanout: how the Phase A fits run when the selection is run here.
    """

    nss: Path | None = None
    data: Path | None = None
    config: Path | None = None
    selection: Path | None = None
    winners: dict[str, str] | None = None
    out: Path | None = None
    monolithic: bool = False
    overwrite: bool = False
    command: str = "build"
    fanout: Fanout = field(default_factory=Fanout)


def load_inputs(
    nss: Path | None, data: Path | None, config: Path | None, command: str
) -> tuple[ActuatorConfig, LoadedModel, Campaign]:
    """(actuator config, NSS, campaign) of ``parknss actuators <command>``, in that order of
    checking; a campaign without the channels the chain needs is refused in one line."""
    torch.set_num_threads(1)
    cfg = load_actuator_config(config)
    campaign = load_campaign(data, "actuators", f"parknss actuators {command}")
    loaded = load_model(nss or SHIPPED_NSS)
    return cfg, loaded, campaign


def selection_winners(path: Path) -> dict[str, str]:
    """channel -> candidate label from a study's ``selection.json`` (one-line ConfigError)."""
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


def nss_info(loaded: LoadedModel) -> dict:
    """The NSS a chain was built on, for the JSON documents: path, epoch, epochs."""
    t = loaded.training
    return {"path": str(loaded.path), "epoch": t.get("snapshot_of_epoch", t.get("best_epoch")),
            "epochs": t.get("epochs")}


def run_build(inputs: BuildInputs, progress: Progress = _quiet) -> dict:
    """Build the deployment (and optionally the monolithic row); write the artefact.

    Returns the JSON document: ``nss``, Table IV ``rows`` (vx MSE (km/h)², full and moving,
    yaw MSE (°/s)²), ``selection``, ``deployed``, ``cotune``, ``envelope``, ``wall_s``, and
    ``artefact`` when written (``selection_study`` when the selection was run here).
    """
    t0 = time.perf_counter()
    cfg, loaded, campaign = load_inputs(inputs.nss, inputs.data, inputs.config, inputs.command)
    if inputs.out is not None:
        check_writable(inputs.out, overwrite=inputs.overwrite, kind="chain")
    sel_doc = None
    if inputs.selection is not None:
        winners = selection_winners(inputs.selection)
    elif inputs.winners is not None:
        winners = dict(inputs.winners)
    else:
        progress("no --selection: running Phase A and Phase B first")
        data = str(inputs.data) if inputs.data is not None else None
        sel = run_selection(loaded.model, campaign, data, cfg, progress, inputs.fanout)
        winners, sel_doc = sel.winners(), sel.to_json()
    dep = build_deployment(loaded, list(campaign), cfg, winners, progress)
    doc = {"nss": nss_info(loaded), **dep.to_json()}
    if inputs.monolithic and cfg.ladder.monolithic_epochs > 0:
        score, info = monolithic_score(loaded, list(campaign), cfg, progress)
        doc["rows"]["monolithic"] = score.to_json()
        doc["monolithic"] = info
    if sel_doc is not None:
        doc["selection_study"] = sel_doc
    doc["wall_s"] = time.perf_counter() - t0
    if inputs.out is not None:
        meta = {k: v for k, v in doc.items() if k != "selection_study"}
        meta["data_hash"] = campaign.data_hash()
        with artefact_folder(inputs.out, overwrite=inputs.overwrite, kind="chain") as tmp:
            save_chain(tmp, dep.chain, meta)
        doc["artefact"] = str(inputs.out)
    return doc
