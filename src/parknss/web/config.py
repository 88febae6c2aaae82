"""Settings of the interactive simulator (configs/web.yaml).

Budgets are wall-clock seconds of the server; the simulated-time limit of a run stays the
closed-loop config's ``timeout_s`` so the browser and ``parknss simulate`` drive the same
loop. Paths of the other configs default (null) to the files ``parknss simulate`` reads.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field

from parknss.config import StrictModel, load_config


class WebConfig(StrictModel):
    """Server, budgets, payload sizes and colours of the browser view."""

    host: str = Field("127.0.0.1", description="address the server binds to")
    port: int = Field(8000, ge=1, le=65535, description="TCP port")
    workers: int = Field(1, ge=1, description="concurrent plan/simulate computations")
    max_pending: int = Field(4, ge=1, description="computations queued or running before 503")
    plan_budget_s: float = Field(120.0, gt=0, description="wall-clock budget of a plan, s")
    simulate_budget_s: float = Field(300.0, gt=0, description="wall-clock budget of a run, s")
    max_body_bytes: int = Field(
        8 * 1024 * 1024, ge=1024, description="largest request body, bytes (413 beyond)"
    )
    max_coordinate_m: float = Field(
        1000.0, gt=0, description="coordinates of bounds, obstacles and poses within ±this, m"
    )
    max_heading_rad: float = Field(100.0, gt=0, description="headings within ±this, rad")
    token: str | None = Field(
        None,
        min_length=8,
        pattern=r"^[A-Za-z0-9._~-]+$",
        description="access token, 8+ URL-safe characters (required off loopback)",
    )
    allowed_hosts: list[str] = Field(
        default_factory=list, description="Host header names accepted besides the bound ones"
    )
    plan_cache_size: int = Field(32, ge=1, description="plans kept, keyed by scene")
    series_rate_hz: float = Field(25.0, gt=0, le=100, description="series rate sent, Hz")
    max_series_points: int = Field(4000, ge=10, description="max samples sent per run")
    path_step_m: float = Field(0.05, gt=0, description="planned-path pose spacing sent, m")
    footprint_step_m: float = Field(1.0, gt=0, description="planned footprints every, m")
    accel_smoothing_s: float = Field(
        0.2, ge=0, description="moving-average window of the smoothed ax/ay view, s"
    )
    closed_loop_config: str | None = Field(None, description="closed-loop YAML")
    interface_config: str | None = Field(None, description="interface gains YAML")
    planning_config: str | None = Field(None, description="planning YAML")
    scenarios_config: str | None = Field(None, description="scenarios YAML")
    vehicle: str | None = Field(None, description="vehicle YAML (None: the chain's car)")
    fidelity_config: str | None = Field(
        None, description="fidelity YAML: noise seeds, targets, ISO settings (parknss fidelity)"
    )
    plant_colours: dict[str, str] = Field(
        default_factory=lambda: {
            "kinematic": "#00bcd4",
            "chain": "#e67e22",
            "reference": "#8e44ad",
        },
        description="driven path and car colour per plant",
    )
    planned_colour: str = Field("#27ae60", description="planned path colour")


def load_web_config(path: str | Path | None = None, **overrides) -> WebConfig:
    """Read ``path`` (default: the shipped configs/web.yaml) plus ``overrides``."""
    return load_config(WebConfig, path, default="web.yaml", overrides=overrides)
