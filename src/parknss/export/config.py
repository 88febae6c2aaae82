"""Typed configuration of the exports (configs/export.yaml)."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field

from parknss.config import StrictModel, load_config


class FmuConfig(StrictModel):
    """The FMU's default experiment and its identified-domain check (module doc of
    :mod:`parknss.export.fmi2_source`)."""

    stop_time_s: float = Field(60.0, gt=0, description="DefaultExperiment stop time, s")
    domain_margin: float = Field(
        0.1, ge=0, le=1, description="the vx / yaw-rate range of the data widened by this "
        "fraction of its span on each side before a state is reported outside the domain")


class ExportConfig(StrictModel):
    fmu: FmuConfig = FmuConfig()


def load_export_config(path: str | Path | None = None, **overrides) -> ExportConfig:
    """``path`` (default: the shipped configs/export.yaml) plus field overrides."""
    return load_config(ExportConfig, path, default="export.yaml", overrides=overrides)
