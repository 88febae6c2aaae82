"""The report's results that are not NSS fits, stored like the fits: Table IV's ladder of
the shipped chain, the ISO/TS 18571 ratings of Fig. 7 and the closed-loop grid cells of
Table V (one store entry per cell).

Each is an executor job (:func:`ladder_job`, :func:`rating_job`,
:func:`parknss.sim.grid.cell_job`) that the result store (:mod:`parknss.experiments.store`)
keys like a fit, with two differences listed in its :data:`~parknss.experiments.store.DERIVED`
table: the key holds, besides the job's arguments, the **content of what the job reads**
(:func:`cell_inputs`, :func:`ladder_inputs`, :func:`rating_inputs`: the SHA-256 manifest
of a chain or NSS artefact, verified first, and the resolved configs), and its code
version hashes the code that job runs (not the training code of the fits). A retrained
chain, an edited config or an edited simulator therefore misses, and a
``--stored-only`` report says "not measured" instead of showing another chain's numbers.

:func:`ladder_job` is the ladder that built a chain artefact: ``parknss actuators ladder``
on the NSS with the Phase B winners the artefact records (``chain.json``,
``build.selection``), the monolithic row included; it rebuilds the artefact into a
temporary folder and records whether its actuator weights are the artefact's
(``rebuilds_artefact``) and how far its rows are from the rows the artefact recorded.
"""

from __future__ import annotations

import hashlib
import json
import sys
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from parknss.errors import ConfigError


def artefact_digest(folder: str | Path) -> str:
    """The content digest of an artefact folder (an NSS model, a chain): its manifest
    ``SHA256SUMS`` is verified against every file (a one-line CheckpointError otherwise),
    then hashed; it lists every file, a chain's ``nss/`` included."""
    from parknss import durable

    folder = Path(folder)
    durable.verify_manifest(folder)
    return "sha256:" + hashlib.sha256((folder / durable.MANIFEST).read_bytes()).hexdigest()


def config_digest(cfg: Any) -> str:
    """The digest of a resolved config model (its values, JSON)."""
    text = json.dumps(cfg.model_dump(mode="json"), sort_keys=True)
    return "sha256:" + hashlib.sha256(text.encode()).hexdigest()[:16]


def cell_inputs(kwargs: Mapping[str, Any]) -> dict[str, str]:
    """What a closed-loop grid cell (:func:`parknss.sim.grid.cell_job`) reads besides its
    arguments: the resolved closed-loop, interface (overrides applied), planning and
    scenario configs, the chain artefact (the chain plant and the default car) and the
    reference vehicle's parameters (the reference plant)."""
    from parknss.config import SHIPPED_PLANT, override
    from parknss.sim.closed_loop import SimConfigFiles

    files = SimConfigFiles(kwargs.get("closed_loop_config"), kwargs.get("interface_config"),
                           kwargs.get("planning_config"), kwargs.get("scenarios_config"),
                           kwargs.get("vehicle"))
    cfg = files.closed_loop_config()
    icfg = override(files.interface_config(), kwargs.get("interface_overrides"),
                    source="interface overrides")
    out = {"closed_loop": config_digest(cfg), "interface": config_digest(icfg),
           "planning": config_digest(files.planning_config()),
           "scenarios": config_digest(files.scenarios_config())}
    chain = Path(cfg.chain_path) if cfg.chain_path else SHIPPED_PLANT
    if (chain / "chain.json").is_file():
        out["chain"] = artefact_digest(chain)
    if files.vehicle is not None:
        out["vehicle"] = "sha256:" + hashlib.sha256(Path(files.vehicle).read_bytes()).hexdigest()
    if "reference" in (kwargs.get("plants") or ()):
        from parknss.reference.params import load_vehicle_params

        out["reference_vehicle"] = config_digest(load_vehicle_params(cfg.reference_vehicle))
    return out


def _chain_dir(chain: str | None) -> Path:
    from parknss.config import SHIPPED_CHAIN

    return Path(chain) if chain is not None else SHIPPED_CHAIN


def _nss_dir(nss: str | None) -> Path:
    from parknss.config import SHIPPED_NSS

    return Path(nss) if nss is not None else SHIPPED_NSS


def ladder_inputs(kwargs: Mapping[str, Any]) -> dict[str, str]:
    """What :func:`ladder_job` reads besides the campaign (the data hash): the chain
    artefact whose selection it rebuilds, the NSS and the actuator config."""
    from parknss.actuators.config import load_actuator_config

    return {"chain": artefact_digest(_chain_dir(kwargs.get("chain"))),
            "nss": artefact_digest(_nss_dir(kwargs.get("nss"))),
            "actuators": config_digest(load_actuator_config(kwargs.get("config")))}


def rating_inputs(kwargs: Mapping[str, Any]) -> dict[str, str]:
    """What :func:`rating_job` reads besides the campaign: the rated model or chain and
    the rating config."""
    from parknss.config import load_config
    from parknss.metrics.rating_report import RateConfig

    out = {"rate": config_digest(load_config(RateConfig, kwargs.get("config")))}
    for name in ("model", "chain"):
        if kwargs.get(name) is not None:
            out[name] = artefact_digest(kwargs[name])
    return out


def recorded_selection(chain: Path) -> dict[str, str]:
    """The Phase B winners a chain artefact was built with (``chain.json``,
    ``build.selection``); a one-line ConfigError when it records none."""
    artefact_digest(chain)  # refuse an edited artefact before reading it
    try:
        build = json.loads((chain / "chain.json").read_text()).get("build") or {}
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{chain}: cannot read chain.json ({exc})") from exc
    winners = build.get("selection")
    if not isinstance(winners, dict) or not winners:
        raise ConfigError(f"{chain}: chain.json records no Phase B selection (build.selection)"
                          "; its ladder cannot be rebuilt")
    return {str(k): str(v) for k, v in winners.items()}


def _say_ladder(msg: str) -> None:
    """Print one step of the Table IV ladder on stderr (it runs for minutes)."""
    print(f"[reproduce] table4: {msg}", file=sys.stderr, flush=True)


def ladder_job(nss: str | None = None, chain: str | None = None, data: str | None = None,
               config: str | None = None) -> dict:
    """Executor job: the Table IV ladder that built the chain artefact ``chain`` (None:
    the shipped ``models/chain``) on the NSS ``nss`` (None: ``models/nss``) and campaign
    ``data``, with the Phase B winners it records and the monolithic row: the
    :func:`parknss.chain.build.run_build` document (rows, selection, deployed, co-tuning
    report, envelope, monolithic) plus ``recorded_rows`` (the rows in the artefact),
    ``max_abs_diff`` (largest difference to them) and ``rebuilds_artefact`` (the rebuilt
    actuator weights are byte-identical to the artefact's)."""
    from parknss import durable
    from parknss.chain.build import BuildInputs, run_build

    chain_dir = _chain_dir(chain)
    winners = recorded_selection(chain_dir)
    recorded = json.loads((chain_dir / "chain.json").read_text())["build"].get("rows", {})
    with tempfile.TemporaryDirectory(prefix="parknss-ladder-") as tmp:
        out = Path(tmp) / "chain"
        doc = run_build(BuildInputs(nss=_nss_dir(nss), data=Path(data) if data else None,
                                    config=Path(config) if config else None, winners=winners,
                                    out=out, monolithic=True, command="ladder"),
                        _say_ladder)  # minutes at full budget: each step on stderr
        same = (durable.sha256_file(out / "actuators.safetensors")
                == durable.sha256_file(chain_dir / "actuators.safetensors"))
    doc.pop("artefact", None)
    diffs = [abs(float(v) - float(recorded[row][k]))
             for row, vals in doc["rows"].items() if row in recorded
             for k, v in vals.items() if k in recorded[row]]
    doc.update(recorded_rows=recorded, rebuilds_artefact=same,
               max_abs_diff=max(diffs) if diffs else None)
    return doc


def rating_job(data: str, model: str | None = None, chain: str | None = None,
               replay_truth: bool = False, config: str | None = None) -> dict:
    """Executor job: the ISO/TS 18571 rating of one source on the campaign ``data``
    (:func:`parknss.chain.rating.rate_source`): ``{"source", **RatingTable.to_json()}``,
    per-trial rows and the summary (small: one row per trial, channel and conditioning)."""
    from parknss.chain.rating import RateInputs, rate_source

    table, source = rate_source(RateInputs(
        data=Path(data), model=Path(model) if model else None,
        chain=Path(chain) if chain else None, replay_truth=replay_truth,
        config=Path(config) if config else None))
    return {"source": source, **table.to_json()}
