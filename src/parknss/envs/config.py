"""Typed configuration of the parking environment (configs/parking_env.yaml)."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field

from parknss.config import StrictModel, load_config


class EnvConfig(StrictModel):
    """What the environment drives, how actions map to requests, the reward (highway-env's
    parking-v0 convention) and the limits. Units in the names."""

    plant: str = Field("kinematic", pattern="^(kinematic|chain|reference)$")
    actions: str = Field("requests", pattern="^(requests|raw)$")
    scenes: str = "36"
    steps_per_action: int = Field(10, ge=1, description="10 ms plant steps per env step")
    time_limit_s: float = Field(60.0, gt=0)
    max_speed_ms: float = Field(1.5, gt=0)
    speed_deadband: float = Field(0.05, ge=0, lt=1)
    obs_scales: tuple[float, float, float, float, float, float] = (100, 100, 5, 5, 1, 1)
    reward_weights: tuple[float, float, float, float, float, float] = (1, 0.3, 0, 0, 0.02, 0.02)
    reward_p: float = Field(0.5, gt=0)
    success_goal_reward: float = Field(0.12, gt=0)
    collision_reward: float = -5.0
    chain_path: str | None = Field(None, description="chain artefact (None: the shipped one)")
    chain_engine: str = Field(
        "numpy", pattern="^(numpy|native)$",
        description="the chain plant's step: the NumPy twin or its generated C (native: "
        "make_vec steps the envs' chains one C call a sample)")
    vehicle_yaml: str | None = Field(
        None, description="vehicle YAML: the car planned, drawn and (reference) driven; "
        "None: the chain's own car (parknss.sim.vehicles.resolve_vehicle)")
    render_dpi: int = Field(60, ge=20, le=300)
    obs_speed_max_ms: float = Field(
        5.0, gt=0, description="bound of the observed speed, m/s: the observation space is "
        "finite, and a faster car (raw commands) is reported at this bound")


def load_env_config(path: str | Path | None = None, **overrides) -> EnvConfig:
    """``path`` (default: the shipped configs/parking_env.yaml) plus field overrides."""
    return load_config(EnvConfig, path, default="parking_env.yaml", overrides=overrides)
