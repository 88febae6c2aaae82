"""The parking task as a gymnasium environment (layer L10): :class:`~parknss.envs.parking.
ParkingEnv`, registered as ``parknss/Parking-v0`` when this package is imported, and
:func:`make_vec`, its synchronous vector version (:class:`~parknss.envs.vector.
ParkingVecEnv`, a ``gymnasium.vector.SyncVectorEnv`` that steps the copies' plants
together)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from parknss.envs.parking import ENV_ID, ParkingEnv
from parknss.envs.vector import ParkingVecEnv

if ENV_ID not in gym.registry:
    gym.register(id=ENV_ID, entry_point="parknss.envs.parking:ParkingEnv",
                 max_episode_steps=None)


def make_vec(num_envs: int, **kwargs: Any) -> ParkingVecEnv:
    """``num_envs`` copies of the environment (keyword overrides as for ParkingEnv) stepped
    together, their plants one sample at a time for all (``chain_engine="native"``: one
    C call a sample); ``reset(seed=s)`` seeds copy i with s + i."""
    return ParkingVecEnv(num_envs, **kwargs)


__all__ = ["ENV_ID", "ParkingEnv", "ParkingVecEnv", "make_vec"]
