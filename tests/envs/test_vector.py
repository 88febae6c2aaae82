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


def test_the_chain_copies_are_stepped_in_one_c_call_a_sample(monkeypatch):
    # make_vec's batched path: every 10 ms sample of the moving copies is one call of the
    # native step_many over all of them, never a plant's own step
    import parknss.chain.native as native
    from parknss.chain.deployed import DeployedChain

    calls: list[int] = []
    many = native.step_many

    def counted(chains, cmds):
        calls.append(len(chains))
        return many(chains, cmds)

    def alone(*_a, **_k):
        raise AssertionError("a chain copy stepped on its own")

    monkeypatch.setattr(native, "step_many", counted)
    monkeypatch.setattr(DeployedChain, "step", alone)
    n = 4
    vec = make_vec(n, plant="chain", chain_engine="native")
    vec.reset(seed=1)
    steps = vec.envs[0].cfg.steps_per_action
    vec.step(np.zeros((n, 2), dtype=np.float32))
    assert calls == [n] * steps
    vec.close()
