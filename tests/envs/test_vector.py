"""make_vec's ParkingVecEnv steps its copies' plants together (the native chains in one C
call a sample) and gives exactly what gymnasium's SyncVectorEnv over the same copies
gives: observations, rewards, ends, infos, next-step autoresets."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium.vector import SyncVectorEnv

from parknss.envs import ParkingEnv, ParkingVecEnv, make_vec


def _same(a, b) -> None:
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for k in a:
            _same(a[k], b[k])
    elif isinstance(a, tuple):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            _same(x, y)
    else:
        assert np.array_equal(np.asarray(a), np.asarray(b)), (a, b)


@pytest.mark.parametrize("plant", ["chain", "kinematic"])
def test_stepping_together_is_stepping_each_copy(plant):
    # a short time limit makes copies truncate, so the next-step autoreset is exercised
    kw = {"plant": plant, "chain_engine": "native", "time_limit_s": 0.6}
    n = 3
    together = make_vec(n, **kw)
    assert isinstance(together, ParkingVecEnv)
    if plant == "chain":  # the batched path: native chains of one artefact
        assert {e.plant.plant.engine for e in together.envs} == {"native"}
    apart = SyncVectorEnv([lambda: ParkingEnv(**kw) for _ in range(n)])
    _same(together.reset(seed=5), apart.reset(seed=5))
    rng = np.random.default_rng(6)
    ends = 0
    for _ in range(14):
        act = rng.uniform(-1, 1, (n, 2)).astype(np.float32)
        got, want = together.step(act), apart.step(act)
        _same(got, want)
        ends += int(np.sum(got[3]))
    assert ends >= n  # every copy was truncated (and reset) at least once
    together.close()
    apart.close()
