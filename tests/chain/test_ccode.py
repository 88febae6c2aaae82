"""The generated C step (through ctypes) equals the NumPy real-time twin for every
architecture and input variant, the gear rule included; the native engine of
DeployedChain is the same plant; the C's own tanh is within 1.4 ulp of the exact value."""

from __future__ import annotations

import ctypes

import numpy as np
import pytest
import torch

from helpers.actuators import tiny_config
from parknss.actuators.envelopes import identify_envelope
from parknss.actuators.fit import fit_candidate
from parknss.actuators.spec import CandidateSpec
from parknss.chain import DeployedChain
from parknss.chain.native import NativeChain
from parknss.chain.score import make_chain
from parknss.plant import Commands

torch.set_num_threads(1)

SETS = [
    {"drive": "drive/hammerstein/phys", "brake": "brake/gru/uniform",
     "steering": "steering/lag1/cmd"},
    {"drive": "drive/lag2/uniform", "brake": "brake/lstm/phys",
     "steering": "steering/narx/uniform"},
    {"drive": "drive/static/phys", "brake": "brake/narx1s/cmd", "steering": "steering/gru/cmd"},
    {"drive": "drive/hammerstein/uniform", "brake": "brake/monolag/phys",  # models/plant's
     "steering": "steering/lag1/uniform"},
    {"drive": "drive/lag1/uniform", "brake": "brake/monolag/cmd", "steering": "steering/lag2/cmd"},
]


@pytest.fixture(scope="module")
def chains(actuator_campaign, actuator_nss):
    camp = list(actuator_campaign)
    nss, _ = actuator_nss
    cfg = tiny_config()
    env = identify_envelope(camp, cfg.envelope)
    out = []
    for s in SETS:
        models = {ch: fit_candidate(CandidateSpec.parse(n), camp[:3], cfg, env)[0]
                  for ch, n in s.items()}
        out.append(DeployedChain(make_chain(nss, models, env)))
    return camp, out


def _replay(stepper, cm, x0, y0):
    stepper.start(x0, y0, cm[0])
    rows = []
    for c in cm:
        act, st = stepper.step(*c)
        rows.append([*act, *st, stepper.gear])
    return np.array(rows)


@pytest.mark.parametrize("which", range(len(SETS)))
def test_c_equals_numpy_twin(chains, which):
    camp, deps = chains
    dep = deps[which]
    nat = NativeChain(dep.rt)
    for tr in camp[:3]:
        cm = tr.array(("gear", "torque_cmd", "decel_cmd", "steer_cmd")).copy()
        cm[7, 1] = np.nan  # the NaN hold and the clamps are part of the step
        cm[9, 3] = np.inf
        x0 = [tr["vx"][0], tr["yaw_rate"][0]]
        y0 = [tr["torque"][0], tr["brake_pressure"][0], tr["steer"][0]]
        a, b = _replay(dep.rt, cm, x0, y0), _replay(nat, cm, x0, y0)
        assert np.max(np.abs(a - b)) <= 1e-9
        assert np.array_equal(a[:, 7], b[:, 7])  # the engaged gear, exactly
        nat.start(x0, y0, cm[0])
        assert np.max(np.abs(nat.run(cm) - a)) <= 1e-9


def test_native_engine_is_the_same_plant(chains):
    _, deps = chains
    dep = deps[0]
    nat = DeployedChain(dep.chain, engine="native")
    rng = np.random.default_rng(3)
    dep.reset(gear=1)
    nat.reset(gear=1)
    for _ in range(200):
        c = Commands(int(rng.integers(-1, 2)), float(rng.uniform(0, 60)),
                     float(rng.uniform(-0.8, 0)), float(rng.uniform(-300, 300)))
        a, b = dep.step(c), nat.step(c)
        assert a.gear == b.gear
        assert abs(a.vx - b.vx) <= 1e-9 and abs(a.steer - b.steer) <= 1e-9


def test_c_generation_and_onnx_refuse_the_brake_stop_latch():
    """Neither the generated C nor the ONNX step implements the brake-stop latch: a chain
    with it is refused in one line rather than stepped differently."""
    import dataclasses

    from parknss.chain import load_chain
    from parknss.chain.ccode import chain_c_source
    from parknss.config import SHIPPED_CHAIN
    from parknss.errors import CheckpointError
    from parknss.export.onnx_step import ChainStep

    shipped = load_chain(SHIPPED_CHAIN).chain
    env = dataclasses.replace(shipped.envelope, stop_latch_bar=1.0)
    rt = DeployedChain(make_chain(shipped.nss, shipped.models(), env)).rt
    with pytest.raises(CheckpointError, match="brake-stop latch"):
        chain_c_source(rt)
    with pytest.raises(CheckpointError, match="brake-stop latch"):
        ChainStep(rt)


@pytest.mark.skipif(np.finfo(np.longdouble).nmant < 63, reason="needs 80-bit long double")
def test_c_tanh_is_within_1_4_ulp_and_odd(chains):
    """pk_tanh_v (basic IEEE operations, no libm) against tanh in 80-bit long double, on
    both branches (|x| < 0.625 and above), the cap at 20 and the special values."""
    lib = NativeChain(chains[1][0].rt)._lib
    lib.pk_tanh_array.argtypes = [ctypes.c_long, ctypes.c_void_p, ctypes.c_void_p]
    rng = np.random.default_rng(11)
    x = np.concatenate([rng.uniform(-25, 25, 200_000), rng.uniform(-1.5, 1.5, 200_000),
                        rng.normal(0, 1e-3, 10_000), np.linspace(0.62, 0.63, 10_001),
                        [0.0, -0.0, 1e-300, 5e-324, 0.625, 19.0, 20.0, 700.0, 1e300,
                         np.inf, -np.inf, np.nan]])
    x = np.concatenate([x, -x])
    y = np.empty_like(x)
    lib.pk_tanh_array(len(x), x.ctypes.data, y.ctypes.data)
    fin = np.isfinite(x)
    exact = np.tanh(x[fin].astype(np.longdouble))
    ulp = np.abs(y[fin] - exact) / np.spacing(np.abs(exact).astype(np.float64))
    assert float(np.max(ulp)) <= 1.4  # 1.34 measured, just above 0.625
    n = len(x) // 2
    assert y[:n][fin[:n]].tobytes() == (-y[n:][fin[n:]]).tobytes()  # odd, bit for bit
    assert np.array_equal(np.signbit(y[fin]), np.signbit(x[fin]))  # -0.0 stays -0.0
    assert list(y[np.isinf(x)]) == [1.0, -1.0, -1.0, 1.0]
    assert np.all(np.abs(y[np.abs(x) >= 19.1]) == 1.0)
    assert np.isnan(y[np.isnan(x)]).all()


@pytest.mark.parametrize("release", ["exp", "ramp"])
def test_a_monolag_brake_chain_round_trips_and_c_and_onnx_step_it(
        actuator_campaign, actuator_nss, tmp_path, release):
    """The monotone brake (models/plant's) travels in the artefact (its structure config
    with it, the hold's release shape included) and steps identically after loading; the
    generated C steps it as the NumPy twin does (1e-9) and the ONNX step as well (float32,
    1e-5), the hold gate's state included."""
    import onnxruntime as ort

    from parknss.chain import load_chain
    from parknss.chain.deployed import save_chain
    from parknss.chain.model import NSSProvenance
    from parknss.export.onnx_step import chain_state, export_onnx

    camp = list(actuator_campaign)
    nss, ncfg = actuator_nss
    cfg = tiny_config(arch={"monolag_release": release})
    env = identify_envelope(camp, cfg.envelope)
    names = {"drive": "drive/lag1/cmd", "brake": "brake/monolag/phys",
             "steering": "steering/lag1/cmd"}
    models = {ch: fit_candidate(CandidateSpec.parse(n), camp[:3], cfg, env)[0]
              for ch, n in names.items()}
    with torch.no_grad():  # the tiny random NSS never stands still: arm the gate at any speed
        models["brake"].log_v_hold.fill_(np.log(50.0))
    chain = make_chain(nss, models, env, NSSProvenance(ncfg, {}))
    folder = save_chain(tmp_path / "chain", chain, {})
    dep = load_chain(folder)
    assert dep.chain.model("brake").spec.name == "brake/monolag/phys"
    assert dep.rt.steppers["brake"].hold  # the speed feature arms the hold
    assert dep.rt.steppers["brake"].ramp == (release == "ramp")
    tr = camp[0]
    cm = tr.array(("gear", "torque_cmd", "decel_cmd", "steer_cmd")).copy()
    hold = np.tile([cm[-1, 0], 0.0, -0.8, 0.0], (300, 1))  # a held stop, then a release
    cm = np.vstack([cm, hold, np.tile([cm[-1, 0], 0.0, 0.0, 0.0], (200, 1))])
    x0 = [tr["vx"][0], tr["yaw_rate"][0]]
    y0 = [tr["torque"][0], tr["brake_pressure"][0], tr["steer"][0]]
    a = _replay(DeployedChain(chain).rt, cm, x0, y0)
    b = _replay(dep.rt, cm, x0, y0)
    assert np.max(np.abs(a - b)) < 1e-12
    assert np.max(np.abs(_replay(NativeChain(dep.rt), cm, x0, y0) - a)) <= 1e-9
    so = ort.SessionOptions()
    so.intra_op_num_threads = so.inter_op_num_threads = 1
    sess = ort.InferenceSession(str(export_onnx(tmp_path / "c.onnx", chain_dir=folder).path),
                                so, providers=["CPUExecutionProvider"])
    rt = dep.rt
    rt.start(x0, y0, cm[0])
    worst, gfs = 0.0, []
    for k in range(len(cm)):
        nxt, out = sess.run(None, {"state": chain_state(rt).astype(np.float32),
                                   "command": cm[k].astype(np.float32)})
        act, st = rt.step(*cm[k])
        gfs.append(rt.steppers["brake"].gf)
        for got, ref in ((out, np.array([*act, *st, rt.gear])), (nxt, chain_state(rt))):
            worst = max(worst, float(np.max(np.abs(got - ref) / np.maximum(1.0, np.abs(ref)))))
    assert worst <= 1e-5
    gf = np.array(gfs)  # the trial engages the hold and releases it: both branches ran
    assert gf.max() > 0.5 and np.sum(np.diff(gf) < -1e-3) > 10
