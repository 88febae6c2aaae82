"""Envelopes: identified numbers, the NaN/inf rule, the real-time twin against the batched
rules, and no violation under stress."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from helpers.actuators import tiny_config
from parknss.actuators.envelopes import (
    EnvelopeState,
    clean_commands,
    identify_envelope,
    limit_outputs_torch,
)
from parknss.actuators.fit import fit_candidate
from parknss.actuators.spec import CandidateSpec
from parknss.chain import DeployedChain
from parknss.chain.score import make_chain
from parknss.chain.stress import run_stress
from parknss.plant import Commands
from parknss.signals import DT

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def deployed(actuator_campaign, actuator_nss):
    camp = actuator_campaign
    nss, _ = actuator_nss
    cfg = tiny_config()
    env = identify_envelope(list(camp), cfg.envelope)
    models = {c: fit_candidate(CandidateSpec.parse(n), list(camp)[:3], cfg, env)[0]
              for c, n in (("drive", "drive/narx/uniform"), ("brake", "brake/narx1s/cmd"),
                           ("steering", "steering/lag1/cmd"))}
    return camp, DeployedChain(make_chain(nss, models, env)), cfg


def test_identified_envelope(actuator_campaign, actuator_config):
    camp = actuator_campaign
    env = identify_envelope(list(camp), actuator_config.envelope)
    assert env.cmd_lo[1] == -0.8 and env.cmd_hi[1] == 0.0
    assert env.cmd_hi[0] == max(tr["torque_cmd"].max() for tr in camp)
    slew = max(np.abs(np.diff(tr["steer"])).max() for tr in camp) / DT
    assert env.steer_rate_dps == pytest.approx(1.05 * slew)
    assert env.steer_lock == 400.0 and env.torque_floor == 0.0


def test_nan_holds_and_inf_clamps_in_both_paths(actuator_campaign, actuator_config):
    env = identify_envelope(list(actuator_campaign), actuator_config.envelope)
    cmds = np.array([[1, 10.0, -0.2, 50.0], [1, np.nan, np.nan, np.nan],
                     [1, np.inf, -np.inf, -np.inf], [np.nan, np.nan, 3.0, 1e9]])
    batched = clean_commands(env, cmds[None], np.array([5.0]))[0]
    st = EnvelopeState(env)
    st.reset(steer=5.0, gear=0)
    for k, row in enumerate(cmds):
        g, c = st.command(row[0], list(row[1:]))
        assert [g, *c] == pytest.approx(list(batched[k]))
    assert list(batched[1, 1:]) == [10.0, -0.2, 50.0]  # held
    assert list(batched[2, 1:]) == [env.cmd_hi[0], env.cmd_lo[1], env.cmd_lo[2]]  # clamped
    assert batched[3, 0] == 1 and batched[3, 2] == 0.0 and batched[3, 3] == env.cmd_hi[2]
    assert st.activity.nonfinite["torque_cmd"] == 3


def test_output_envelope_twin_equals_the_batched_rule(actuator_campaign, actuator_config):
    """EnvelopeState.output (real time, floats) against limit_outputs_torch over a whole
    history and sample by sample: floors, rate limit, lock; and measured channels pass."""
    env = identify_envelope(list(actuator_campaign), actuator_config.envelope)
    rng = np.random.default_rng(5)
    T = 400
    y = rng.uniform([-80, -30, -900], [300, 60, 900], (T, 3))
    y[::7, 2] = rng.uniform(-50, 50, len(y[::7]))  # small moves the rate limit lets pass
    st = EnvelopeState(env)
    st.reset(steer=12.0)
    twin = np.array([st.output(*row) for row in y])
    t = torch.as_tensor(y.T[:, None, :])  # (3, B=1, T)
    steer0 = torch.tensor([12.0], dtype=torch.float64)
    batched = np.stack([v[0].numpy() for v in limit_outputs_torch(env, *t, steer0)], axis=1)
    assert np.max(np.abs(batched - twin)) == 0.0
    prev, rows = steer0, []
    for k in range(T):
        s = [torch.tensor([v], dtype=torch.float64) for v in y[k]]
        out = limit_outputs_torch(env, *s, prev)
        prev = out[2]
        rows.append([float(v[0]) for v in out])
    assert np.max(np.abs(np.array(rows) - twin)) == 0.0
    assert st.activity.steer_rate > 0 and st.activity.output_floor["torque"] > 0
    kept = limit_outputs_torch(env, *t, steer0, modelled=(False, True, False))
    assert torch.equal(kept[0], t[0]) and torch.equal(kept[2], t[2])


def test_random_extreme_and_nan_commands_stay_in_the_envelope(deployed):
    _, dep, _ = deployed
    env = dep.chain.envelope
    rng = np.random.default_rng(3)
    dep.reset()
    prev = 0.0
    for k in range(600):
        c = [rng.uniform(-1e4, 1e4) for _ in range(3)]
        if k % 7 == 0:
            c[k % 3] = [np.nan, np.inf, -np.inf][k % 3]
        out = dep.step(Commands(int(rng.integers(-1, 2)), *c))
        assert out.torque >= env.torque_floor and out.brake_pressure >= env.pressure_floor
        assert abs(out.steer) <= env.steer_lock
        assert abs(out.steer - prev) <= env.steer_rate_dps * DT * (1 + 1e-12)
        assert np.isfinite([out.vx, out.yaw_rate, out.ax, out.ay]).all()
        prev = out.steer


def test_stress_study_reports_the_active_envelopes(deployed):
    camp, dep, cfg = deployed
    rows = {r.scenario: r for r in run_stress(dep, camp[0], cfg.stress)}
    assert set(rows) >= {"torque_x3", "decel_-5", "steer_1000dps", "nan", "inf", "random"}
    for r in rows.values():
        assert r.violations == 0 and r.nonfinite_states == 0
        assert r.max_path_diff < 1e-9  # real time = batched, even with NaN/inf inputs
    assert "input_clamp:decel_cmd" in rows["decel_-5"].active
    assert "input_clamp:torque_cmd" in rows["torque_x3"].active
    assert any(a.startswith("nonfinite") for a in rows["nan"].active)


def test_brake_stop_latch_is_off_by_default_and_round_trips():
    """Off (inf): the artefact's envelope JSON has no key for it (artefacts written before
    the option stay byte-identical); on: it round-trips; negative is refused."""
    import dataclasses
    import math

    from parknss.actuators.envelopes import Envelope
    from parknss.errors import CheckpointError

    env = Envelope((0.0, -0.8, -400.0), (80.0, 0.0, 400.0), hold_latch_bar=8.0)
    assert math.isinf(env.stop_latch_bar) and "stop_latch_bar" not in env.to_json()
    assert not env.stops(1e9, -1, 0.1)
    on = dataclasses.replace(env, stop_latch_bar=1.0)
    assert Envelope.from_json(on.to_json()) == on
    assert on.stops(1.0, -1, 0.01) and on.stops(2.0, 1, -0.01)  # against the gear
    assert not on.stops(0.9, -1, 0.01)  # a weak brake: no latch
    assert not on.stops(5.0, 1, 0.01) and not on.stops(5.0, 0, 0.01)  # along it, or park
    with pytest.raises(CheckpointError, match="brake-stop latch"):
        Envelope.from_json({**on.to_json(), "stop_latch_bar": -1.0})
