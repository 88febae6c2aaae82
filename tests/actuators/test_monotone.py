"""The monotone structured brake (``monolag``): no pulse when a pulse leaves any window,
a steady state monotone in the request, order preservation, a step response of the
reference brake's order of magnitude when fitted to it, and artefacts of the other
architectures written as before."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from helpers.actuators import lagged_trial, tiny_config
from parknss.actuators.candidates import build_candidate
from parknss.actuators.config import ArchConfig
from parknss.actuators.envelopes import identify_envelope
from parknss.actuators.fit import fit_candidate, step_metrics
from parknss.actuators.models import Scaling
from parknss.actuators.spec import CandidateSpec
from parknss.data.trial import Trial
from parknss.reference.actuators import BrakeActuator
from parknss.reference.params import BrakeParams
from parknss.signals import DT

torch.set_num_threads(1)
# decel command [-0.8, 0] -> scaled [-1, 1]; pressure [0, 16] bar -> [-1, 1]; |vx| feature
SCALING = Scaling(-0.4, 0.4, (0.5,), (0.5,), 8.0, 8.0)


def _random_brake(variant: str, seed: int, release: str = "exp"):
    """A monolag brake with its parameters scattered at random (the properties hold for
    every parameter value, not only for a good fit), its hold released by ``release``."""
    spec = CandidateSpec("brake", "monolag", variant)
    sc = SCALING if spec.features else Scaling(-0.4, 0.4, (), (), 8.0, 8.0)
    m = build_candidate(spec, sc, ArchConfig(monolag_release=release))
    m.init_affine(-1.0, 0.0, np.zeros(len(spec.features)))
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in m.parameters():
            p.add_(0.8 * torch.randn(p.shape, generator=g, dtype=p.dtype))
    return m


def _run(m, cmd: np.ndarray, speed: float = 0.0, settle: int = 0) -> np.ndarray:
    """Output (T,) of the NumPy twin (the chain's real-time path) under cmd (T,), after
    ``settle`` samples of cmd[0] (so that the test starts from the model's rest)."""
    st = m.stepper()
    st.reset(float(cmd[0]), 0.0)
    f = np.array([speed]) if m.spec.features else None
    for _ in range(settle):
        st.step(float(cmd[0]), f)
    return np.array([st.step(float(c), f) for c in cmd])


@pytest.mark.parametrize("variant,speed", [("cmd", 0.0), ("phys", 0.0), ("phys", 0.5)])
@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("release", ["exp", "ramp"])
def test_no_pulse_after_a_pulse_leaves_the_window(variant, speed, seed, release):
    """A 0.5 s brake pulse, then no request for 4 s: once the pulse has passed the dead
    time, the output only falls (the 1 s NARX brake put out a phantom 7.8 bar pulse when
    the pulse left its 100-sample window); in particular nothing rises 1 s later."""
    m = _random_brake(variant, seed, release)
    k0, k1, T = 100, 150, 550
    cmd = np.zeros(T)
    cmd[k0:k1] = -0.6
    y = _run(m, cmd, speed, settle=3000)
    tail = y[k1 + m.max_delay + 1 :]
    i = int(np.argmax(tail))
    assert np.all(np.diff(tail[i:]) <= 1e-9)
    one_s = k1 + round(1.0 / DT)
    assert np.max(y[one_s : one_s + 50]) <= y[one_s - 10] + 1e-9
    assert np.max(y[:k0]) == pytest.approx(y[0], abs=1e-9)  # nothing before the pulse


@pytest.mark.parametrize("variant,speed", [("cmd", 0.0), ("phys", 0.0), ("phys", 0.5)])
@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("release", ["exp", "ramp"])
def test_steady_state_is_monotone_in_the_request(variant, speed, seed, release):
    """A constant request held 6 s: the final pressure never falls as the request deepens,
    and under a constant request the pressure settles without a dip (the NARX brake fell
    from 5.8 to 1.6 bar under a constant -0.8 m/s²)."""
    m = _random_brake(variant, seed, release)
    levels = np.linspace(0.0, -0.8, 17)
    finals = []
    for a in levels:
        y = _run(m, np.r_[np.zeros(50), np.full(600, a)], speed, settle=3000)
        finals.append(y[-1])
        if a < 0:  # from rest into a constant request: no fall back once it has risen
            rise = y[50:]
            i = int(np.argmax(rise))
            assert np.all(np.diff(rise[: i + 1]) >= -1e-9)
    assert np.all(np.diff(finals) >= -1e-9)


@pytest.mark.parametrize("variant", ["cmd", "phys"])
@pytest.mark.parametrize("release", ["exp", "ramp"])
def test_a_deeper_request_anywhere_never_lowers_the_output(variant, release):
    """Order preservation (ζ >= 1: the lag's impulse response is non-negative): command
    histories c1 <= c2 sample by sample give outputs y1 >= y2 at every sample."""
    rng = np.random.default_rng(3)
    for seed in range(3):
        m = _random_brake(variant, seed, release)
        c2 = np.repeat(rng.uniform(-0.8, 0.0, 40), 15)
        c1 = c2 - rng.uniform(0.0, 0.3, c2.size) * (rng.uniform(size=c2.size) < 0.3)
        for speed in (0.0, 0.2, 0.6):
            y1, y2 = _run(m, c1, speed, 3000), _run(m, c2, speed, 3000)
            assert np.all(y1 >= y2 - 1e-9)


def _truth_trial(seed: int, n: int = 600) -> Trial:
    """A trial whose brake pressure is the reference vehicle's brake hydraulics (dead zone,
    gain 10 bar/(m/s²), 50 ms dead time, 3 Hz second-order lag; no auto-hold) under
    piecewise-constant decel requests."""
    tr = lagged_trial(n, seed=seed)
    rng = np.random.default_rng(seed)
    cmd = -np.repeat(rng.uniform(0, 0.8, n // 60 + 1) * (rng.uniform(size=n // 60 + 1) < 0.7),
                     60)[:n]
    brake = BrakeActuator(BrakeParams(), DT)
    ch = dict(tr.channels)
    ch["decel_cmd"] = cmd
    ch["brake_pressure"] = np.array([brake.step(float(c), 0.0) for c in cmd])
    return Trial(tr.id, tr.maneuver, tr.repetition, ch)


def test_fitted_to_the_reference_brake_its_step_has_the_truths_size_and_speed():
    trials = [_truth_trial(s) for s in range(3)]
    cfg = tiny_config(fit={"iters_linear": 150, "window": 200, "burn_in": 40,
                           "max_windows": 24})
    env = identify_envelope(trials, cfg.envelope)
    model, _ = fit_candidate(CandidateSpec("brake", "monolag", "cmd"), trials, cfg, env)
    truth = BrakeActuator(BrakeParams(), DT)
    for level in (-0.3, -0.6):
        cmd = np.r_[np.zeros(100), np.full(300, level)]
        y = _run(model, cmd)
        truth.reset()
        ref = np.array([truth.step(float(c), 0.0) for c in cmd])
        assert y[-1] == pytest.approx(ref[-1], rel=0.15)  # -0.3: 2.5 bar, -0.6: 5.5 bar
        s, r = step_metrics(y, 100, level), step_metrics(ref, 100, level)
        assert s.delay_s + s.rise_s == pytest.approx(r.delay_s + r.rise_s, abs=0.1)
    assert 0.0 <= model.delay_s <= 0.15


def test_default_dumps_and_other_artefacts_omit_the_monolag_fields():
    """The config digests (run folders, the derived store) and the artefacts of the other
    architectures read as before monolag existed; a changed monolag value is dumped."""
    cfg = ArchConfig()
    assert not any(k.startswith("monolag_") for k in cfg.model_dump(mode="json"))
    assert not any(k.startswith("monolag_") for k in cfg.artefact_json("narx1s"))
    assert cfg.artefact_json("monolag")["monolag_knots"] == cfg.monolag_knots
    assert ArchConfig.model_validate(cfg.artefact_json("lag2")) == cfg
    changed = ArchConfig(monolag_knots=4)
    assert changed.model_dump()["monolag_knots"] == 4
    assert changed.digest() != cfg.digest()
    assert ArchConfig.model_validate(changed.model_dump()) == changed


@pytest.mark.parametrize("seed", range(4))
def test_a_hold_speed_ceiling_keeps_the_hold_off_a_moving_car(seed):
    """With ``monolag_hold_speed_max_ms`` the gate's threshold stays below the ceiling for
    every parameter value (even one pushed far up), so a deep request on a car moving
    clearly above the ceiling never raises the hold floor: torch rollout and NumPy twin
    alike; the unbounded default keeps its parameter (artefacts read as before)."""
    v_max = 0.139
    arch = ArchConfig(monolag_hold_speed_max_ms=v_max)
    assert ArchConfig.model_validate(arch.artefact_json("monolag")) == arch
    m = build_candidate(CandidateSpec("brake", "monolag", "phys"), SCALING, arch)
    m.init_affine(-1.0, 0.0, np.zeros(1))
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in m.parameters():
            p.add_(0.8 * torch.randn(p.shape, generator=g, dtype=p.dtype))
        m.logit_v_hold.add_(40.0)  # a fit that pushes the threshold up
        m.rho_hold.fill_(5.0)      # a large floor, so that an armed hold would show
    assert 0.0 < float(m.hold_speed()) <= v_max
    cmd = np.r_[np.zeros(50), np.full(350, -0.8)]
    moving = v_max + 6 * m.v_width
    with torch.no_grad():
        H = m.rho_hold.clone()
        roll = m.rollout(torch.as_tensor(cmd)[None], torch.full((1, len(cmd), 1), moving),
                         torch.zeros(1))[0].numpy()
        m.rho_hold.fill_(-40.0)  # no floor at all
        bare = m.rollout(torch.as_tensor(cmd)[None], torch.full((1, len(cmd), 1), moving),
                         torch.zeros(1))[0].numpy()
        m.rho_hold.copy_(H)
    assert np.abs(roll - bare).max() < 0.05  # bar: the hold does not arm while moving
    twin = _run(m, cmd, speed=moving)
    assert np.abs(twin - roll).max() < 1e-6
    at_rest = _run(m, cmd, speed=0.0)
    assert at_rest[-1] > twin[-1] + 1.0  # and it does arm at rest
    default = build_candidate(CandidateSpec("brake", "monolag", "phys"), SCALING, ArchConfig())
    assert "log_v_hold" in default.state_dict() and "logit_v_hold" not in default.state_dict()


def _held_then_released(m, T_hold: int = 200, T_free: int = 300):
    """(cmd (1, T), feat (1, T, 1)): a full request at standstill, then no request."""
    cmd = torch.cat([torch.full((1, T_hold), -0.8), torch.zeros(1, T_free)], 1).double()
    return cmd, torch.zeros(1, T_hold + T_free, 1, dtype=torch.float64)


def test_a_ramp_release_falls_linearly_to_none_in_tau_off():
    """``monolag_release: ramp``: a full hold (g_f -> 1) released by a zero gate falls by
    dt/τ_off per sample and is gone after τ_off (the chassis auto-hold's ramp-out); the
    exponential release is still at e^-1 after τ_off."""
    tau = 0.5
    for release in ("ramp", "exp"):
        m = build_candidate(CandidateSpec("brake", "monolag", "phys"), SCALING,
                            ArchConfig(monolag_release=release, monolag_release_tau_s=tau))
        a_on, off = m.hold_rates()
        gf, g = torch.ones(1, dtype=torch.float64), torch.zeros(1, dtype=torch.float64)
        trace = [1.0]
        for _ in range(round(tau / DT) + 5):
            gf = m.hold_filter(gf, g, a_on, off)
            trace.append(float(gf))
        n = round(tau / DT)
        if release == "ramp":
            assert np.allclose(np.diff(trace[: n + 1]), -DT / tau, atol=1e-12)
            assert trace[n] == pytest.approx(0.0, abs=1e-12) and max(trace[n:]) == 0.0
        else:
            assert trace[n] == pytest.approx(np.exp(-1.0), rel=1e-9)


@pytest.mark.parametrize("release", ["exp", "ramp"])
def test_rollout_step_and_twin_agree_through_a_hold_and_its_release(release):
    """The training rollout, the torch step and the NumPy twin give the same pressure
    through a hold that engages at standstill and is released (1e-10)."""
    m = _random_brake("phys", 0, release)
    with torch.no_grad():
        m.r_hold.fill_(-0.5)
        m.log_v_hold.fill_(np.log(0.07))
        m.rho_hold.fill_(2.0)
    cmd, feat = _held_then_released(m)
    y0 = torch.tensor([0.5], dtype=torch.float64)
    with torch.no_grad():
        Y = m.rollout(cmd, feat, y0)[0]
        st = m.init_state(cmd[:, 0], y0)
        ys = []
        for k in range(cmd.shape[1]):
            y, st = m.step(st, cmd[:, k], feat[:, k])
            ys.append(float(y[0]))
    tw = m.stepper()
    tw.reset(float(cmd[0, 0]), 0.5)
    yn, gfs = [], []
    for k in range(cmd.shape[1]):
        yn.append(tw.step(float(cmd[0, k]), feat[0, k].numpy()))
        gfs.append(tw.gf)
    assert np.max(np.abs(np.array(ys) - Y.numpy())) < 1e-10
    assert np.max(np.abs(np.array(yn) - Y.numpy())) < 1e-10
    assert max(gfs) > 0.9 and gfs[-1] < 1e-3  # the hold engaged, then released
    assert float(st[1][0]) == pytest.approx(tw.gf, abs=1e-12)
