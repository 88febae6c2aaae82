"""Per-trial conditions of the reference vehicle (issue 14): the default profile (typical)
reproduces the bundled campaign bit for bit, profile ``none`` is the nominal car, every
condition shows where its physics says it should, the draw is deterministic and
documented, the ground truth round-trips through the campaign files and identification
code never reads it."""

from __future__ import annotations

import ast
import json
import math
from pathlib import Path

import numpy as np
import pytest

from parknss.cli import main
from parknss.config import BUNDLED_CAMPAIGN, CONFIG_DIR, PACKAGE_DIR
from parknss.data.describe import describe_campaign
from parknss.data.io import read_campaign, write_campaign
from parknss.errors import ConfigError
from parknss.reference.campaign import generate_campaign, generate_trial
from parknss.reference.conditions import (
    CONDITIONS_KEY,
    ConditionRanges,
    ConditionsConfig,
    TrialConditions,
    draw_conditions,
    trial_conditions,
)
from parknss.reference.environment import trial_environment, walther_viscosity
from parknss.reference.params import ReferenceVehicleParams, load_vehicle_params
from parknss.reference.vehicle import ReferenceVehicle
from parknss.signals import DT, G, kmh_to_ms

P0 = ReferenceVehicleParams()
NOM = TrialConditions.nominal()
QUIET = P0.replace(
    imu={"ax_noise": 0.0, "ay_noise": 0.0, "yaw_rate_noise": 0.0},
    wheel_speed={"noise_ms": 0.0, "resolution_kmh": 0.0},
)


def cond(**kw) -> TrialConditions:
    """The nominal conditions with some fields changed."""
    return NOM.model_copy(update=kw)


def cmds(T: int, gear=0, torque=0.0, decel=0.0) -> np.ndarray:
    c = np.zeros((T, 4))
    c[:, 0], c[:, 1], c[:, 2] = gear, torque, decel
    return c


def run(c: np.ndarray, conditions=None, params=P0) -> dict[str, np.ndarray]:
    return ReferenceVehicle(params, seed=7, conditions=conditions).simulate(c)


# ------------------------------------------------- the bundled campaign is the default draw
@pytest.fixture(scope="module")
def none_campaign(tmp_path_factory):
    out = tmp_path_factory.mktemp("none") / "c"
    assert main(["campaign", "generate", "--out", str(out), "--seed", "0",
                 "--conditions", "none"]) == 0  # fmt: skip
    return read_campaign(out)


def test_the_default_profile_reproduces_the_bundled_campaign_bit_for_bit(tmp_path):
    """`parknss campaign generate --seed 0` (profile from the YAML: typical) is the bundled
    campaign, so the shipped models are reproducible from the shipped configuration."""
    out = tmp_path / "c"
    assert main(["campaign", "generate", "--out", str(out), "--seed", "0"]) == 0
    new_c, bundled = read_campaign(out), read_campaign(BUNDLED_CAMPAIGN)
    assert new_c.ids == bundled.ids and new_c.meta == bundled.meta
    for new, old in zip(new_c, bundled, strict=True):
        assert set(new.channels) == set(old.channels)
        for name in old.channels:
            np.testing.assert_array_equal(new[name], old[name], err_msg=f"{old.id} {name}")
        assert new.provenance == old.provenance
        assert trial_conditions(new.provenance) is not None


def test_profile_none_is_the_nominal_car_and_shares_the_maneuver_plan(none_campaign):
    """Profile none draws no conditions (no ground-truth key); the maneuver plans and the
    noise come from the same streams as under a profile, so a trial drawn at the same
    attempt has the same plan and noise seeds under both."""
    bundled = read_campaign(BUNDLED_CAMPAIGN)
    assert none_campaign.ids == bundled.ids
    for new, old in zip(none_campaign, bundled, strict=True):
        assert trial_conditions(new.provenance) is None
        assert trial_conditions(old.provenance) is not None
        pn, po = json.loads(new.provenance), json.loads(old.provenance)
        if pn["attempt"] == po["attempt"]:  # a trial whose length left 21-64 s is redrawn
            for key in ("plan_seed", "noise_seed", "planned_reversals"):
                assert pn[key] == po[key], key


def test_physics_checks_hold_on_the_flat_unloaded_campaign(none_campaign):
    s = describe_campaign(none_campaign)
    assert s.yaw_r2 > 0.995
    assert 12.0 <= s.steer_ratio_fit <= 12.4
    assert s.reversals_while_moving == 0


def test_nominal_conditions_are_the_car_without_conditions():
    c = cmds(500, gear=1)
    c[300:, 2] = -0.6
    a, b = run(c), run(c, NOM)
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


# ----------------------------------------------------------------- each effect where it belongs
@pytest.mark.parametrize(("uphill", "sign"), [(0.0, 1.0), (180.0, -1.0)])
def test_grade_reads_as_g_sin_theta_in_ax_at_standstill(uphill, sign):
    out = run(cmds(300), cond(lot_slope_pct=5.0, uphill_heading_deg=uphill), QUIET)
    expect = sign * G * math.sin(math.atan(0.05))  # 0.49 m/s² on a 5 % grade
    assert np.all(out["truth_vx"] == 0.0)  # held by the parking lock
    assert out["truth_ax"][-1] == 0.0  # no kinematic acceleration: the specific force
    assert np.mean(out["ax"] - P0.imu.ax_bias) == pytest.approx(expect, abs=0.01)


def test_crossfall_reads_in_ay_and_gravity_moves_a_released_car():
    bank = run(cmds(200), cond(lot_slope_pct=2.0, uphill_heading_deg=90.0), QUIET)
    assert np.mean(bank["ay"] - P0.imu.ay_bias) == pytest.approx(
        G * math.sin(math.atan(0.02)), abs=0.01
    )
    # in D with creep and no brake: downhill it runs away faster than on the flat
    flat = run(cmds(400, gear=1))["truth_vx"][-1]
    down = run(cmds(400, gear=1), cond(lot_slope_pct=5.0, uphill_heading_deg=180.0))
    up = run(cmds(400, gear=1), cond(lot_slope_pct=5.0, uphill_heading_deg=0.0))
    assert down["truth_vx"][-1] > flat + 0.3
    assert up["truth_vx"][-1] < -0.3  # creep cannot hold 5 %: it rolls back, against D


def test_payload_slows_the_launch():
    c = cmds(300, gear=1, torque=60.0)
    v = [run(c, cond(payload_kg=kg))["truth_vx"] for kg in (0.0, 250.0, 500.0)]
    accel = [(x[200] - x[100]) / 1.0 for x in v]  # m/s² between 1 and 2 s
    assert accel[0] > accel[1] > accel[2]
    assert accel[2] / accel[0] == pytest.approx(2100.0 / 2600.0, rel=0.06)


@pytest.mark.parametrize("factor", [0.75, 1.1])
def test_tyre_pressure_scales_the_wheel_speed_against_true_speed(factor):
    out = run(cmds(800, gear=1, torque=40.0), cond(tyre_pressure_factor=factor), QUIET)
    env = trial_environment(P0, cond(tyre_pressure_factor=factor))
    m = np.abs(out["truth_vx"]) > 0.3
    ratio = np.median(out["vx"][m] / out["truth_vx"][m])
    assert ratio == pytest.approx(env.speed_scale, abs=1e-9)
    assert (ratio > 1.0) == (factor < 1.0)  # a soft tyre rolls smaller: the ECU over-reads
    assert abs(ratio - 1.0) > 1e-3


def test_brake_temperature_changes_the_hydraulic_lag_and_the_pad_gain():
    no_hold = P0.replace(autohold={"enabled": False})
    c = cmds(300)
    c[50:, 2] = -1.0

    def t63(temp: float) -> float:
        p = run(c, cond(brake_temp_c=temp), no_hold)["truth_brake_pressure"]
        return (int(np.argmax(p > 0.632 * p[-1])) - 50) * DT

    assert t63(-20.0) > t63(20.0) + 0.03  # cold fluid: viscous, slower
    assert t63(150.0) <= t63(20.0)
    hot = trial_environment(P0, cond(brake_temp_c=150.0)).params.brake.force_per_bar
    assert hot > P0.brake.force_per_bar  # warm pads grip more per bar
    assert walther_viscosity(-40.0, (-40.0, 700.0), (100.0, 2.0)) == pytest.approx(700.0)


def test_powertrain_temperature_changes_the_creep_speed_and_soc_does_not():
    def creep_kmh(**kw) -> float:
        return run(cmds(1500, gear=1), cond(**kw))["truth_vx"][-1] / kmh_to_ms(1.0)

    warm, cold = creep_kmh(powertrain_temp_c=20.0), creep_kmh(powertrain_temp_c=-20.0)
    assert cold < warm - 0.2  # cold drive-unit oil drags
    # the battery's power limit does not bind at parking speed (docs/reference.md)
    assert creep_kmh(battery_soc_pct=5.0, powertrain_temp_c=20.0) == warm
    env = trial_environment(P0, cond(battery_soc_pct=5.0, powertrain_temp_c=-20.0))
    assert env.torque_available(kmh_to_ms(5.0)) == P0.drive.torque_max_nm
    assert env.torque_available(kmh_to_ms(60.0)) < P0.drive.torque_max_nm


def test_imu_bias_misalignment_and_yaw_rate_drift_at_rest():
    c = cond(ax_bias_ms2=0.05, ay_bias_ms2=-0.04, gyro_bias_dps=0.1, gyro_drift_dps_per_min=0.05)
    out = run(cmds(6000), c)  # one minute at rest, with the sensor noise
    assert np.mean(out["ax"]) == pytest.approx(P0.imu.ax_bias + 0.05, abs=0.005)
    assert np.mean(out["ay"]) == pytest.approx(P0.imu.ay_bias - 0.04, abs=0.005)
    w = np.degrees(out["yaw_rate"])
    bias0 = np.degrees(P0.imu.yaw_rate_bias) + 0.1
    assert np.mean(w[:500]) == pytest.approx(bias0, abs=0.01)  # first 5 s
    assert np.mean(w[-500:]) - np.mean(w[:500]) == pytest.approx(0.05 * 55 / 60, abs=0.01)
    tilt = run(cmds(200), cond(imu_pitch_deg=0.5, imu_roll_deg=-0.5), QUIET)
    g05 = G * math.sin(math.radians(0.5))
    assert np.mean(tilt["ax"] - P0.imu.ax_bias) == pytest.approx(g05, abs=0.005)
    assert np.mean(tilt["ay"] - P0.imu.ay_bias) == pytest.approx(-g05, abs=0.005)


# ----------------------------------------------------------------- the draw
def test_draw_is_deterministic_in_range_and_harsh_stretches_typical():
    cfg = ConditionsConfig()
    assert draw_conditions(cfg, 0, 0, 1, "none") is None  # profile none: nothing drawn
    assert draw_conditions(cfg, 0, 0, 1) == draw_conditions(cfg, 0, 0, 1, "typical")  # default
    a = draw_conditions(cfg, 5, 2, 3, "typical")
    assert a == draw_conditions(cfg, 5, 2, 3, "typical")
    assert a != draw_conditions(cfg, 6, 2, 3, "typical")
    assert a != draw_conditions(cfg, 5, 2, 4, "typical")
    h = draw_conditions(cfg, 5, 2, 3, "harsh")
    assert a.profile == "typical" and h.profile == "harsh"
    for name in ConditionRanges.model_fields:
        st, sh = getattr(cfg.typical, name), getattr(cfg.harsh, name)
        va, vh = getattr(a, name), getattr(h, name)
        assert st.lo <= va <= st.hi and sh.lo <= vh <= sh.hi, name
        assert sh.lo <= st.lo and st.hi <= sh.hi, name  # harsh spans typical
        if st.hi > st.lo and sh.hi > sh.lo:  # same uniform number, wider range
            u_t, u_h = (va - st.lo) / (st.hi - st.lo), (vh - sh.lo) / (sh.hi - sh.lo)
            assert u_t == pytest.approx(u_h, abs=1e-12), name
    assert 0.0 <= a.uphill_heading_deg < 360.0 and a.uphill_heading_deg == h.uphill_heading_deg


def test_ranges_and_profile_are_validated(tmp_path):
    bad = tmp_path / "v.yaml"
    bad.write_text("conditions:\n  typical:\n    payload_kg: {lo: 300, hi: 100}\n")
    with pytest.raises(ConfigError, match="payload_kg"):
        load_vehicle_params(bad)
    bad.write_text("conditions:\n  profile: stormy\n")
    with pytest.raises(ConfigError, match="profile"):
        load_vehicle_params(bad)
    ok = tmp_path / "ok.yaml"
    ok.write_text("conditions:\n  profile: typical\n  typical:\n    payload_kg: {lo: 80, hi: 80}\n")
    p = load_vehicle_params(ok)
    assert p.conditions.profile == "typical" and p.digest() == P0.digest()
    tr = generate_trial("park_out_left", 1, seed=4, params=p)
    assert trial_conditions(tr.provenance).payload_kg == 80.0  # every range is the YAML's
    shipped = (CONFIG_DIR / "reference_vehicle.yaml").read_text()
    for name in ConditionRanges.model_fields:
        assert shipped.count(f"{name}:") == 2, name  # typical and harsh, both editable


# ----------------------------------------------------------------- a conditions campaign
@pytest.fixture(scope="module")
def typical_campaign():
    return generate_campaign(seed=3, conditions="typical")


def test_typical_campaign_is_deterministic_and_records_its_conditions(typical_campaign):
    c = typical_campaign
    assert c.meta["conditions_profile"] == "typical"
    assert (
        c.meta["conditions_digest"]
        == P0.replace(conditions={"profile": "typical"}).conditions.digest()
    )
    again = generate_trial("park_in_right", 2, seed=3, params=P0, conditions="typical")
    first = c["park_in_right_r2"]
    assert again.provenance == first.provenance
    for name in first.channels:
        np.testing.assert_array_equal(again[name], first[name], err_msg=name)
    conds = [trial_conditions(tr.provenance) for tr in c]
    assert all(x is not None and x.profile == "typical" for x in conds)
    assert len({x.lot_slope_pct for x in conds}) == len(c)  # each trial its own draw


def test_conditions_round_trip_through_the_campaign_files(typical_campaign, tmp_path):
    back = read_campaign(write_campaign(typical_campaign, tmp_path / "c"))
    assert back.meta == typical_campaign.meta
    for a, b in zip(typical_campaign, back, strict=True):
        assert trial_conditions(b.provenance) == trial_conditions(a.provenance)
        assert json.loads(b.provenance)[CONDITIONS_KEY] == json.loads(a.provenance)[CONDITIONS_KEY]


def test_the_recorded_grade_is_the_one_the_accelerometer_saw(typical_campaign):
    """Ground truth checks out: the idle in park at the start reads g·sin of the recorded
    floor pitch plus the recorded biases and sensor pitch."""
    for tr in typical_campaign:
        c = trial_conditions(tr.provenance)
        env = trial_environment(P0, c)
        pitch = env.floor.grade(0.0, 0.0)[0] if env.floor is not None else 0.0
        expect = G * math.sin(pitch) + env.params.imu.ax_bias + G * math.sin(env.imu_pitch_rad)
        idle = (tr["t"] < 0.9) & (tr["gear"] == 0) & (tr["truth_vx"] == 0.0)
        assert np.mean(tr["ax"][idle]) == pytest.approx(expect, abs=0.015), tr.id


def test_harsh_campaign_completes_at_parking_speed():
    c = generate_campaign(seed=1, conditions="harsh")
    s = describe_campaign(c)
    assert len(c) == 16 and s.reversals_while_moving == 0
    assert all(21.0 <= tr.duration_s <= 64.0 for tr in c)
    assert max(np.max(np.abs(tr["truth_vx"])) for tr in c) < kmh_to_ms(4.0)


def test_describe_shows_the_conditions_when_present(
    typical_campaign, none_campaign, tmp_path, capsys
):
    out = write_campaign(typical_campaign, tmp_path / "c")
    assert main(["campaign", "describe", str(out)]) == 0
    text = capsys.readouterr().out
    assert "conditions (ground truth, profile typical):" in text
    assert sum(tr.id in text.split("conditions (ground")[1] for tr in typical_campaign) == 16
    assert main(["campaign", "describe", str(out), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(doc["conditions"]) == set(typical_campaign.ids)
    bare = write_campaign(none_campaign, tmp_path / "none")
    assert main(["campaign", "describe", str(bare)]) == 0
    assert "conditions (ground truth" not in capsys.readouterr().out


# ----------------------------------------------------------------- identification never reads it
IDENTIFICATION = ("nss", "actuators", "chain", "metrics", "experiments", "sim")
# identify's data description and model card report the conditions the campaign covers
# (as `campaign describe` does); they feed no fit, which the other modules of identify do
DESCRIBES_DATA = {"experiments/identify/data_stage.py", "experiments/identify/card.py",
                  "experiments/identify/card_html.py"}
FORBIDDEN_NAMES = {"TrialConditions", "trial_conditions", "conditions_summary", "CONDITIONS_KEY"}


def _reads_conditions(path: Path) -> list[str]:
    hits = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Constant) and node.value == CONDITIONS_KEY:
            hits.append(f"{path}:{node.lineno}: string {CONDITIONS_KEY!r}")
        elif isinstance(node, ast.Attribute) and node.attr == "conditions":
            hits.append(f"{path}:{node.lineno}: attribute .conditions")
        elif isinstance(node, ast.Name) and node.id in FORBIDDEN_NAMES:
            hits.append(f"{path}:{node.lineno}: {node.id}")
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith(
            ("parknss.reference.conditions", "parknss.reference.environment")
        ):
            hits.append(f"{path}:{node.lineno}: imports {node.module}")
    return hits


def test_identification_code_never_reads_the_conditions(tmp_path):
    files = [f for pkg in IDENTIFICATION for f in sorted((PACKAGE_DIR / pkg).rglob("*.py"))
             if f.relative_to(PACKAGE_DIR).as_posix() not in DESCRIBES_DATA]
    assert len(files) > 30
    assert [h for f in files for h in _reads_conditions(f)] == []
    probe = tmp_path / "probe.py"  # the scan does see a read
    probe.write_text(
        "from parknss.reference.conditions import trial_conditions\n"
        "x = json.loads(tr.provenance)['conditions']\ny = cfg.conditions\n"
    )
    assert len(_reads_conditions(probe)) == 3
