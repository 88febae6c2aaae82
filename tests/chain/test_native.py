"""Several native chains stepped together (one C call, each NSS layer for all of them at
once) are exactly the chains stepped one by one; mixed or NumPy-engine plants fall back
to their own steps. The build for this machine is the FMU's portable build bit for bit.
The "wide" chain's NSS layers (75 and 40 units) take every kernel of the generated
matrix-vector product: whole blocks, single vectors and the scalar tail, for every
vector width (16, 32, 64 bytes)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from helpers.actuators import tiny_config, tiny_nss
from parknss.actuators.envelopes import identify_envelope
from parknss.actuators.fit import fit_candidate
from parknss.actuators.spec import CandidateSpec
from parknss.cbuild import CFLAGS
from parknss.chain import DeployedChain
from parknss.chain.deployed import step_many
from parknss.chain.native import NativeChain
from parknss.chain.native import step_many as native_step_many
from parknss.chain.score import make_chain
from parknss.errors import ConfigError, ParknssError
from parknss.plant import Commands

torch.set_num_threads(1)

K = 19  # more than one C batch (16)


@pytest.fixture(scope="module")
def parts(actuator_campaign):
    camp = list(actuator_campaign)
    cfg = tiny_config()
    env = identify_envelope(camp, cfg.envelope)
    names = {"drive": "drive/hammerstein/phys", "brake": "brake/narx1s/cmd",
             "steering": "steering/lag1/cmd"}
    models = {ch: fit_candidate(CandidateSpec.parse(n), camp[:3], cfg, env)[0]
              for ch, n in names.items()}
    return camp, models, env


@pytest.fixture(scope="module")
def chain(parts, actuator_nss):
    _, models, env = parts
    return make_chain(actuator_nss[0], models, env)


@pytest.fixture(scope="module")
def wide(parts):
    camp, models, env = parts
    nss, _ = tiny_nss(camp, seed=1, state_units=75, output_units=40)
    return make_chain(nss, models, env)


def _commands(rng, k: int) -> list[Commands]:
    return [Commands(int(rng.integers(-1, 2)), float(rng.uniform(0, 60)),
                     float(rng.uniform(-0.8, 0)), float(rng.uniform(-300, 300)))
            for _ in range(k)]


@pytest.mark.parametrize("which", ["chain", "wide"])
def test_step_many_is_stepping_one_by_one_exactly(which, request):
    chain = request.getfixturevalue(which)
    together = [DeployedChain(chain, engine="native") for _ in range(K)]
    alone = [DeployedChain(chain, engine="native") for _ in range(K)]
    for i, (a, b) in enumerate(zip(together, alone, strict=True)):
        a.reset(vx=0.1 * i, steer=10.0 * i, gear=1)
        b.reset(vx=0.1 * i, steer=10.0 * i, gear=1)
    rng = np.random.default_rng(4)
    for _ in range(60):
        cmds = _commands(rng, K)
        got = step_many(together, cmds)
        want = [p.step(c) for p, c in zip(alone, cmds, strict=True)]
        assert got == want  # every field of every plant, bit for bit
    assert [p.stepper.gear for p in together] == [p.stepper.gear for p in alone]


def test_numpy_and_mixed_engines_step_one_by_one(chain):
    plants = [DeployedChain(chain), DeployedChain(chain, engine="native")]
    twins = [DeployedChain(chain), DeployedChain(chain, engine="native")]
    rng = np.random.default_rng(5)
    for _ in range(20):
        cmds = _commands(rng, 2)
        assert step_many(plants, cmds) == [p.step(c) for p, c in zip(twins, cmds, strict=True)]
    assert step_many([], []) == []
    with pytest.raises(ConfigError, match="2 plants, 1 commands"):
        step_many(plants, cmds[:1])


def test_native_step_many_checks_its_input(chain):
    a, b = (DeployedChain(chain, engine="native") for _ in range(2))
    with pytest.raises(ParknssError, match=r"\(2, 4\)"):
        native_step_many([a.stepper, b.stepper], np.zeros((3, 4)))
    assert native_step_many([], np.zeros((0, 4))).shape == (0, 8)


def test_native_build_is_the_portable_build_bit_for_bit(wide):
    """-march=native (AVX-512 or AVX vectors here) against the FMU's portable -O3 build
    (SSE2): the same bits in every output, and both within 1e-9 of the NumPy twin."""
    dep = DeployedChain(wide)
    rng = np.random.default_rng(7)
    cm = np.column_stack([rng.integers(-1, 2, 400), rng.uniform(0, 60, 400),
                          rng.uniform(-0.8, 0, 400), rng.uniform(-300, 300, 400)])
    cm[:40, 0] = 1  # drive off first, so the NSS moves
    x0, y0 = [0.2, 0.01], [5.0, 0.0, 10.0]
    runs = []
    for nat in (NativeChain(dep.rt), NativeChain(dep.rt, flags=CFLAGS)):
        nat.start(x0, y0, cm[0])
        runs.append(nat.run(cm))
    assert runs[0].tobytes() == runs[1].tobytes()
    assert np.ptp(runs[0][:, 3]) > 0.01  # it drove
    dep.start(x0, y0, cm[0])
    twin = np.array([[*a, *s, dep.rt.gear] for a, s in (dep.rt.step(*c) for c in cm)])
    assert np.max(np.abs(twin - runs[0])) <= 1e-9
