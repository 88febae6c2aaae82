"""The command-to-vehicle chain: batched rollout = real-time step to 1e-10 in float64, the
NumPy NSS twin = the NSS's own step, the artefact round trip, refusal of corrupt
artefacts, and the Plant protocol."""

from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pytest
import torch

from helpers.actuators import tiny_config
from parknss.actuators.envelopes import identify_envelope
from parknss.actuators.fit import fit_candidate
from parknss.actuators.spec import CandidateSpec
from parknss.chain import (
    DeployedChain,
    NSSProvenance,
    chain_predictions,
    load_chain,
    predict_chain_campaign,
    realtime_predictions,
    rollout_trials,
    save_chain,
)
from parknss.chain.realtime import NumpyNSS, RealtimeChain
from parknss.chain.score import make_chain
from parknss.durable import write_manifest
from parknss.errors import CheckpointError
from parknss.plant import Commands, Plant

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def setup(actuator_campaign, actuator_nss):
    camp = actuator_campaign
    nss, ncfg = actuator_nss
    cfg = tiny_config()
    env = identify_envelope(list(camp), cfg.envelope)

    def fit(name):
        return fit_candidate(CandidateSpec.parse(name), list(camp)[:4], cfg, env)[0]

    cmd_models = {"drive": fit("drive/gru/cmd"), "brake": fit("brake/narx1s/cmd"),
                  "steering": fit("steering/lag1/cmd")}
    aware = {"drive": fit("drive/lag1/uniform"), "brake": fit("brake/lstm/phys"),
             "steering": fit("steering/narx/uniform")}
    return camp, nss, ncfg, env, cmd_models, aware


def _step_all(rt: RealtimeChain, tr):
    cm = tr.array(("gear", "torque_cmd", "decel_cmd", "steer_cmd"))
    rt.start([tr["vx"][0], tr["yaw_rate"][0]],
             [tr["torque"][0], tr["brake_pressure"][0], tr["steer"][0]], cm[0])
    outs = [rt.step(*cm[k]) for k in range(tr.n)]
    st = np.array([o[1] for o in outs])
    act = np.array([o[0] for o in outs])
    return st, act


@pytest.mark.parametrize("gear_rule", [False, True], ids=["replay", "gear_rule"])
@pytest.mark.parametrize("kind", ["command_only", "state_aware"])
def test_batched_rollout_equals_real_time_step(setup, kind, gear_rule):
    """The torch rollout (fused/decoupled, its gear-rule fixed point, or the interleaved
    loop) equals the NumPy real-time step, replaying the logged gear as engaged or gating
    it as a request; the Plant (DeployedChain) gates it."""
    camp, nss, _, env, cmd_models, aware = setup
    chain = make_chain(nss, cmd_models if kind == "command_only" else aware, env)
    assert chain.state_aware == (kind == "state_aware")
    trials = list(camp)[:3]
    r = rollout_trials(chain, trials, gear_rule=gear_rule)
    dep = DeployedChain(chain)
    assert dep.rt.shift is not None
    rt = dep.rt if gear_rule else RealtimeChain(chain.nss, chain.models(), chain.envelope,
                                                gear_rule=False)
    for i, tr in enumerate(trials):
        st, act = _step_all(rt, tr)
        n = tr.n
        for j, key in enumerate(("vx", "yaw_rate", "ax", "ay")):
            ref = getattr(r.nss, key)[i, :n].numpy()
            assert np.max(np.abs(st[:, j] - ref)) < 1e-10, key
        assert np.max(np.abs(act - r.actuals[i, :n].numpy())) < 1e-10


@pytest.mark.parametrize("residual_yaw", [True, False])
def test_numpy_nss_twin_equals_the_nss_step(setup, residual_yaw):
    """The real-time twin of the NSS against its one source, NSSModel.step: the same
    Euler step and yaw readout sample by sample over a whole trial (float64)."""
    from parknss.nss.config import with_overrides
    from parknss.nss.train import build_model

    camp, nss, ncfg, *_ = setup
    cfg = with_overrides(ncfg, model={"residual_yaw": residual_yaw})
    model = build_model(cfg, nss.normalizer, nss.geometry).double().eval()
    twin = NumpyNSS(model)
    tr = camp[0]
    u = tr.array(("gear", "torque", "brake_pressure", "steer"))
    x0 = np.array([tr["vx"][0], tr["yaw_rate"][0]])
    with torch.no_grad():
        state = model.initial_state(torch.as_tensor(x0)[None], torch.as_tensor(u[:1]))
    x = twin.initial_state(x0, u[0])
    assert np.max(np.abs(x - state[0].numpy())) < 1e-12
    for k in range(tr.n):
        with torch.no_grad():
            out, state = model.step(state, torch.as_tensor(u[k : k + 1]))
        us = twin.scale_u(u[k])
        got = twin.readout(x, us)
        want = [float(getattr(out, n)[0, 0]) for n in ("vx", "yaw_rate", "ax", "ay")]
        assert np.max(np.abs(np.subtract(got, want))) < 1e-10, k
        x = twin.advance(x, us)
        assert np.max(np.abs(x - state[0].numpy())) < 1e-10, k


def test_partial_chain_real_time_equals_torch(setup):
    camp, nss, _, env, _, aware = setup
    chain = make_chain(nss, {"drive": aware["drive"]}, env)  # brake, steering measured
    trials = list(camp)[:2]
    a = realtime_predictions(chain, trials)
    r = rollout_trials(chain, trials)
    for i, tr in enumerate(trials):
        assert np.max(np.abs(a[tr.id]["vx"] - r.nss.vx[i, : tr.n].numpy())) < 1e-10


def test_all_measured_chain_is_the_nss(setup):
    from parknss.nss.predict import predict_trials

    camp, nss, _, env, _, _ = setup
    chain = make_chain(nss, {}, env)
    p = chain_predictions(chain, list(camp))
    q = predict_trials(chain.nss, list(camp))
    for tid in p:
        assert np.allclose(p[tid]["vx"], q[tid]["vx"], atol=1e-12)


def test_artefact_round_trip_and_plant(setup, tmp_path):
    camp, nss, ncfg, env, cmd_models, _ = setup
    chain = make_chain(nss, cmd_models, env, NSSProvenance(ncfg, {"epochs": 7}))
    folder = save_chain(tmp_path / "chain", chain, {"note": "test"})
    dep = load_chain(folder)
    assert isinstance(dep, Plant)
    assert dep.meta["note"] == "test"
    assert dep.chain.provenance.config == ncfg
    assert dep.chain.provenance.training["epochs"] == 7
    p0 = chain_predictions(chain, list(camp)[:2])
    p1 = predict_chain_campaign(folder, list(camp)[:2])
    for tid in p0:
        for k in ("vx", "yaw_rate", "ax", "ay"):
            assert np.max(np.abs(p0[tid][k] - p1[tid][k])) < 1e-12
    out = dep.reset(steer=30.0)
    assert out.vx == 0.0 and out.steer == 30.0
    for _ in range(50):
        out = dep.step(Commands(1, 40.0, 0.0, 30.0))
    assert np.isfinite([out.vx, out.yaw_rate, out.ax, out.ay]).all()
    from parknss.sim.plants import ChainPlant

    assert ChainPlant(folder).reset() is not None


def _corrupt(tmp_path, folder, how):
    bad = tmp_path / f"bad_{how}"
    shutil.copytree(folder, bad)
    if how == "missing_json":
        (bad / "chain.json").unlink()
    elif how == "malformed":
        (bad / "chain.json").write_text("{not json")
    elif how == "hash":
        data = bytearray((bad / "actuators.safetensors").read_bytes())
        data[-3] ^= 0xFF
        (bad / "actuators.safetensors").write_bytes(bytes(data))
    elif how == "shapes":
        doc = json.loads((bad / "chain.json").read_text())
        doc["channels"]["brake"]["arch"]["narx_hidden"] = [4]
        (bad / "chain.json").write_text(json.dumps(doc))
    elif how == "nss_swapped":
        data = bytearray((bad / "nss" / "model.safetensors").read_bytes())
        data[-3] ^= 0xFF
        (bad / "nss" / "model.safetensors").write_bytes(bytes(data))
    elif how == "missing_channel":
        doc = json.loads((bad / "chain.json").read_text())
        del doc["channels"]["steering"]
        (bad / "chain.json").write_text(json.dumps(doc))
    elif how == "no_folder":
        shutil.rmtree(bad)
    if how not in ("missing_json", "no_folder"):  # reach the checks behind the manifests
        write_manifest(bad / "nss")
        write_manifest(bad)
    return bad


@pytest.mark.parametrize("how,msg", [
    ("missing_json", "chain.json: listed in SHA256SUMS but missing"),
    ("malformed", "malformed JSON"),
    ("hash", "SHA-256 mismatch"),
    ("shapes", "has shape"),
    ("nss_swapped", "NSS weights do not match"),
    ("missing_channel", "channel 'steering' missing"),
    ("no_folder", "chain folder not found"),
])
def test_corrupt_artefacts_are_refused_in_one_line(setup, tmp_path, how, msg):
    _camp, nss, ncfg, env, cmd_models, _ = setup
    chain = make_chain(nss, cmd_models, env, NSSProvenance(ncfg))
    folder = save_chain(tmp_path / "chain", chain, {})
    bad = _corrupt(tmp_path, folder, how)
    with pytest.raises(CheckpointError, match=msg) as ei:
        load_chain(bad)
    assert "\n" not in str(ei.value)


def test_real_time_step_is_fast_enough_to_be_measured(setup):
    _camp, nss, _, env, cmd_models, _ = setup
    dep = DeployedChain(make_chain(nss, cmd_models, env))
    dep.reset()
    for _ in range(200):
        out = dep.step(Commands(1, 30.0, -0.1, 10.0))
    assert np.isfinite(out.vx)


def test_brake_hold_latch_holds_a_car_at_rest_in_closed_loop_only(setup):
    """Under a full brake-hold inside the blind zone the Plant (gear rule, closed loop) is
    set to rest exactly and stays there until the brake is released; a replay
    (gear_rule=False) leaves the NSS as it is (actuators/envelopes.py, the latch)."""
    _, nss, _, env, cmd_models, _ = setup
    assert math.isfinite(env.hold_latch_bar) and env.hold_latch_bar > 0
    chain = make_chain(nss, cmd_models, env)
    plant = DeployedChain(chain)
    replay = RealtimeChain(chain.nss, chain.models(), chain.envelope, gear_rule=False)
    v_plant, v_replay = [], []
    for rt, out in ((plant.rt, v_plant), (replay, v_replay)):
        rt.start([0.1, 0.0], [0.0, 0.0, 0.0], [1, 0.0, 0.0, 0.0])
        for _ in range(300):  # 3 s of the strongest decel request
            act, st = rt.step(1, 0.0, env.cmd_lo[1], 0.0)
            out.append((act[1], st[0]))
    p = np.array([a for a, _ in v_plant])
    vx = np.array([v for _, v in v_plant])
    assert p.max() >= env.hold_latch_bar  # the brake reaches the latch pressure
    k = int(np.argmax((p >= env.hold_latch_bar) & (np.abs(vx) < 0.5 / 3.6)))
    assert np.all(np.abs(vx[k + 2:]) < 1e-12)  # held at rest from the next sample on
    assert np.max(np.abs([v for _, v in v_replay][k + 2:])) > 1e-6  # the replay is not
    for _ in range(200):  # release the brake and drive: the latch lets go
        _, st = plant.rt.step(1, float(env.cmd_hi[0]), 0.0, 0.0)
    assert abs(st[0]) > 0.05


def test_brake_stop_latch_keeps_the_shipped_chain_from_rolling_through_zero():
    """The shipped chain, reversing at 5.4 cm/s into a full brake, passes through zero and
    rolls forward (issue 44, grid cell 30); with the brake-stop latch it never moves against
    its gear and comes to rest, and the batched closed-loop rollout agrees with the
    real-time step."""
    import dataclasses

    from parknss.config import SHIPPED_CHAIN

    cmds = np.tile([-1.0, 0.0, -0.8, 0.0], (150, 1))
    cmds[0, 2] = 0.0  # the histories start released (the brake has not acted yet)

    def run(chain):
        rt = DeployedChain(chain).rt
        rt.start([-0.054, 0.0], [0.0, 0.0, 0.0], cmds[0])
        return np.array([rt.step(*row)[1][0] for row in cmds.tolist()])

    shipped = load_chain(SHIPPED_CHAIN).chain
    v = run(shipped)
    assert np.any(v > 0.0)  # rolls the wrong way under the brake
    latched = make_chain(shipped.nss, shipped.models(),
                         dataclasses.replace(shipped.envelope, stop_latch_bar=1.0))
    vl = run(latched)
    assert np.all(vl <= 0.0) and np.all(np.abs(vl[-50:]) < 1e-12)
    r = latched.double().rollout(cmds[None], torch.tensor([[-0.054, 0.0]]), torch.zeros(1, 3),
                                 gear_rule=True)
    assert np.allclose(r.nss.vx[0].detach().numpy(), vl, atol=1e-9)
