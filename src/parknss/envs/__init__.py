"""The parking task as a gymnasium environment (layer L10): :class:`~parknss.envs.parking.
ParkingEnv`, registered as ``parknss/Parking-v0`` when this package is imported, and
:func:`make_vec`, its synchronous vector version (``gymnasium.vector.SyncVectorEnv``)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from parknss.envs.parking import ENV_ID, ParkingEnv

if ENV_ID not in gym.registry:
    gym.register(id=ENV_ID, entry_point="parknss.envs.parking:ParkingEnv",
                 max_episode_steps=None)


def make_vec(num_envs: int, **kwargs: Any) -> gym.vector.SyncVectorEnv:
    """``num_envs`` copies of the environment (keyword overrides as for ParkingEnv) stepped
    together; ``reset(seed=s)`` seeds copy i with s + i."""
    return gym.make_vec(ENV_ID, num_envs=num_envs, vectorization_mode="sync", **kwargs)


__all__ = ["ENV_ID", "ParkingEnv", "make_vec"]
