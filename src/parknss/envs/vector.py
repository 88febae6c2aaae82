"""The parking environment's vector version: :class:`ParkingVecEnv`, what
:func:`parknss.envs.make_vec` returns.

It is gymnasium's ``SyncVectorEnv`` (next-step autoreset, seeds s + i, the same batched
observations and infos) over :class:`~parknss.envs.parking.ParkingEnv` copies, except
that a step advances the copies' plants in lock-step, one 10 ms sample at a time for
all of them: with the chain plant on the native engine (``chain_engine="native"``) every
sample of every copy is one C call (:func:`parknss.sim.plants.step_plants`, each NSS
layer applied to all copies at once). Each copy's results are those it gives stepped
alone (tests/envs/test_vector.py).
"""

from __future__ import annotations

from copy import deepcopy
from typing import Any

import numpy as np
from gymnasium.vector import SyncVectorEnv
from gymnasium.vector.utils import concatenate, iterate

from parknss.envs.parking import ParkingEnv
from parknss.sim.plants import step_plants


class ParkingVecEnv(SyncVectorEnv):
    """``num_envs`` ParkingEnv copies (keyword overrides as for ParkingEnv) stepped
    together; see the module doc."""

    def __init__(self, num_envs: int, **kwargs: Any) -> None:
        super().__init__([lambda: ParkingEnv(**kwargs) for _ in range(num_envs)],
                         autoreset_mode="NextStep")

    def step(self, actions):
        """One env step of every copy (a reset for a copy that ended the step before)."""
        envs: list[ParkingEnv] = list(self.envs)
        acts = list(iterate(self.action_space, actions))
        infos: list = [None] * self.num_envs
        moving = []
        for i, env in enumerate(envs):
            if self._autoreset_envs[i]:
                self._env_obs[i], infos[i] = env.reset()
                self._rewards[i] = 0.0
                self._terminations[i] = self._truncations[i] = False
            else:
                moving.append((i, env, env.checked_action(acts[i]), []))
        for _ in range(envs[0].cfg.steps_per_action if moving else 0):
            outs = step_plants([env.plant for _, env, _, _ in moving],
                               [env.command(a) for _, env, a, _ in moving])
            for (_, env, _, poses), y in zip(moving, outs, strict=True):
                env.advance(y, poses)
        for i, env, _, poses in moving:
            (self._env_obs[i], self._rewards[i], self._terminations[i],
             self._truncations[i], infos[i]) = env.outcome(poses)
        vector_infos: dict = {}
        for i, info in enumerate(infos):
            vector_infos = self._add_info(vector_infos, info, i)
        self._observations = concatenate(self.single_observation_space, self._env_obs,
                                         self._observations)
        self._autoreset_envs = np.logical_or(self._terminations, self._truncations)
        return (deepcopy(self._observations) if self.copy else self._observations,
                np.copy(self._rewards), np.copy(self._terminations),
                np.copy(self._truncations), vector_infos)
