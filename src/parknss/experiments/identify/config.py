"""Typed configuration of ``parknss identify`` (configs/identify.yaml) and its inputs."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from pydantic import Field

from parknss.config import StrictModel, load_config
from parknss.nss.config import FusedKernels

STAGES: tuple[str, ...] = (
    "data", "nss", "selection", "chain", "rating", "tune", "grid", "fidelity", "export", "card",
)
"""The stages of the pipeline, in order (docs/identify.md)."""

RECIPES: tuple[str, ...] = ("paper", "fast", "coarse")


class StageEstimates(StrictModel):
    """Nominal wall seconds of each stage (the progress display's time estimate)."""

    data: float = Field(10.0, ge=0)
    nss_paper_epoch: float = Field(2.2, ge=0, description="s per paper-recipe epoch")
    nss_fast: float = Field(950.0, ge=0, description="s for the whole fast recipe")
    nss_coarse: float = Field(550.0, ge=0, description="s for the whole coarse recipe")
    selection: float = Field(1200.0, ge=0)
    chain: float = Field(300.0, ge=0)
    rating: float = Field(60.0, ge=0)
    tune: float = Field(700.0, ge=0)
    grid: float = Field(200.0, ge=0)
    fidelity: float = Field(200.0, ge=0)
    export: float = Field(60.0, ge=0)
    card: float = Field(10.0, ge=0)


class IdentifyConfig(StrictModel):
    """What ``parknss identify`` runs when no option says otherwise."""

    recipe: Literal["paper", "fast", "coarse"] = "coarse"
    kernels: FusedKernels = "native"
    grid: Literal["36", "12", "252"] = "36"
    grid_cells: str | None = None
    tune_rounds: int = Field(1, ge=1)
    fidelity_grid: Literal["36", "12", "252"] = "12"
    fidelity_cells: str | None = "2,8,14,20"
    phase_a_ahead: bool = True
    estimate_s: StageEstimates = StageEstimates()


def load_identify_config(path: str | Path | None = None, **overrides) -> IdentifyConfig:
    """``path`` (default: the shipped configs/identify.yaml) plus field overrides."""
    return load_config(IdentifyConfig, path, default="identify.yaml", overrides=overrides)


@dataclass(frozen=True, kw_only=True)
class IdentifyInputs:
    """What one ``parknss identify`` run reads.

    Attributes:
        out: the car folder CAR (every stage writes under it).
        logs: a folder of logs to import (with ``mapping``), or None with ``data``.
        mapping: the channel-mapping YAML of the import.
        data: an already-imported campaign folder (instead of ``logs``).
        recipe: "paper", "fast" or "coarse" (None: the config's).
        nss_overrides: NSS config overrides {section: {field: value}} (``--set``).
        nss: a fitted NSS folder to start from (reused only when its data hash and
            training config equal this run's; see :mod:`.reuse`).
        allow_code_change: reuse ``nss`` even when its training-code version is not
            shown equal to the current one by the canary lineage (the card says so).
        selection: a ``selection.json`` or a chain folder whose winners to reuse.
        actuator_config: actuator YAML (None: shipped).
        interface: interface-gains YAML to use instead of tuning them (the ``tune``
            stage then records it as given, not tuned here).
        stages: the stages to run (None: all); the others are skipped and say so.
        skip_export: leave the FMU/ONNX exports out.
        executor, workers, address: how the stages that fan out run.
        config: the identify YAML (None: shipped); ``overrides`` field overrides.
        overwrite: replace what CAR holds when it is not an identify run of this source.
    """

    out: Path
    logs: Path | None = None
    mapping: Path | None = None
    data: Path | None = None
    recipe: str | None = None
    nss_overrides: dict = field(default_factory=dict)
    nss: Path | None = None
    allow_code_change: bool = False
    selection: Path | None = None
    actuator_config: Path | None = None
    interface: Path | None = None
    stages: tuple[str, ...] | None = None
    skip_export: bool = False
    executor: str = "local"
    workers: int = 1
    address: str | None = None
    config: Path | None = None
    overrides: dict = field(default_factory=dict)
    overwrite: bool = False
