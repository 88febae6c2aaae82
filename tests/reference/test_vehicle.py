"""The reference vehicle: one test per phenomenon, each tied to its parameter."""

import math

import numpy as np
import pytest

from parknss.config import CONFIG_DIR
from parknss.errors import ConfigError, DataError
from parknss.plant import Commands, Plant, PlantOutput
from parknss.reference.actuators import DriveActuator
from parknss.reference.params import DriveParams, ReferenceVehicleParams, load_vehicle_params
from parknss.reference.vehicle import ReferenceVehicle
from parknss.signals import BLIND_ZONE_MS, DT, G, kmh_to_ms

P0 = ReferenceVehicleParams()
QUIET = P0.replace(
    imu={"ax_noise": 0.0, "ay_noise": 0.0, "yaw_rate_noise": 0.0, "mount_yaw_deg": 0.0},
    bus={"torque_noise_nm": 0.0, "pressure_noise_bar": 0.0, "steer_noise_deg": 0.0},
    wheel_speed={"noise_ms": 0.0},
)


def cmds(T: int, gear=0, torque=0.0, decel=0.0, steer=0.0) -> np.ndarray:
    """(T, 4) command array with constant columns."""
    c = np.zeros((T, 4))
    c[:, 0], c[:, 1], c[:, 2], c[:, 3] = gear, torque, decel, steer
    return c


def run(c: np.ndarray, params: ReferenceVehicleParams = P0, **reset) -> dict:
    return ReferenceVehicle(params, seed=7).simulate(c, **reset)


def stop_and_hold(T: int = 1200, gear: int = 1) -> np.ndarray:
    """Creep 4 s, brake 2 s (decel -0.6), then no command at all."""
    c = cmds(T, gear=gear)
    c[400:600, 2] = -0.6
    return c


# ----------------------------------------------------------------- plant protocol, config
def test_is_a_plant_and_step_matches_simulate():
    car = ReferenceVehicle(seed=3)
    assert isinstance(car, Plant) and car.dt == DT
    c = stop_and_hold(300)
    out = car.simulate(c)
    y = car.reset()
    assert isinstance(y, PlantOutput)
    stepped = [y.vx]
    for row in c[:-1]:
        stepped.append(car.step(Commands(int(row[0]), *row[1:])).vx)
    np.testing.assert_array_equal(np.array(stepped), out["vx"])
    assert car.last_truth.vx == out["truth_vx"][-1]


def test_default_yaml_lists_every_parameter_at_its_default():
    path = CONFIG_DIR / "reference_vehicle.yaml"
    assert load_vehicle_params(path) == ReferenceVehicleParams()
    text = path.read_text()
    for group, fields in P0.model_dump().items():
        for name in fields if isinstance(fields, dict) else [group]:
            assert f"{name}:" in text, name


def test_unknown_parameter_is_a_config_error(tmp_path):
    bad = tmp_path / "v.yaml"
    bad.write_text("brake:\n  gain_typo: 3\n")
    with pytest.raises(ConfigError, match="gain_typo"):
        load_vehicle_params(bad)


def test_commands_are_clamped_or_rejected():
    base = cmds(200, gear=1, decel=0.0, steer=100.0)
    positive = base.copy()
    positive[:, 2] = 2.0  # a positive deceleration request means no braking
    a, b = run(base), run(positive)
    np.testing.assert_array_equal(a["truth_vx"], b["truth_vx"])
    over = base.copy()
    over[:, 3] = 900.0
    assert np.max(run(over)["truth_steer"]) == pytest.approx(P0.geometry.steer_lock_deg)
    nan = base.copy()
    nan[50, 1] = np.nan
    with pytest.raises(DataError, match="torque_cmd"):
        run(nan)
    bad_gear = base.copy()
    bad_gear[10, 0] = 2
    with pytest.raises(DataError, match="gear"):
        run(bad_gear)


# ----------------------------------------------------------------- creep
@pytest.mark.parametrize("gear", [1, -1])
def test_creep_moves_the_car_in_the_gear_direction(gear):
    out = run(cmds(600, gear=gear))
    v = out["truth_vx"]
    assert gear * v[-1] > kmh_to_ms(0.5)  # creeping, out of the blind zone after 6 s
    assert np.all(gear * v >= 0.0)  # never the wrong way
    assert gear * v[-1] < kmh_to_ms(P0.drive.creep_fade_kmh)  # creep fades with speed
    assert out["torque"][-1] > 0.0  # the motor delivers it with no torque request


def test_no_creep_without_creep_torque_or_in_neutral():
    no_creep = P0.replace(drive={"creep_torque_nm": 0.0})
    assert np.all(run(cmds(400, gear=1), no_creep)["truth_vx"] == 0.0)
    assert np.all(run(cmds(400, gear=0))["truth_vx"] == 0.0)


# ----------------------------------------------------------------- auto-hold
def test_autohold_pressure_persists_at_a_stop_without_command():
    out = run(stop_and_hold(1200))
    p, v = out["truth_brake_pressure"], out["truth_vx"]
    assert np.all(out["decel_cmd"][700:] == 0.0)  # no command after 6 s
    assert np.all(v[700:] == 0.0)  # held against the creep
    assert np.all(np.abs(p[700:] - P0.autohold.hold_bar) < 0.05)  # the held level
    assert np.all(out["brake_pressure"][700:] == P0.autohold.hold_bar)  # and it is logged


def test_autohold_releases_over_its_ramp_after_launch_torque():
    c = stop_and_hold(1500)
    c[1000:, 1] = 50.0  # launch torque request at t = 10 s
    out = run(c)
    trig = int(np.argmax(out["truth_torque"] >= P0.autohold.release_torque_nm))
    gone = trig + int(np.argmax(out["truth_brake_pressure"][trig:] < 0.5))
    release = (gone - trig) * DT
    assert 0.5 <= release <= 1.1
    assert release == pytest.approx(P0.autohold.release_time_s, abs=0.25)
    assert out["truth_vx"][trig] == 0.0 and out["truth_vx"][-1] > 0.0  # then it launches
    faster = run(c, P0.replace(autohold={"release_time_s": 0.3}))
    gone2 = trig + int(np.argmax(faster["truth_brake_pressure"][trig:] < 0.5))
    assert (gone2 - trig) * DT < release - 0.3


def test_without_autohold_the_pressure_follows_the_command():
    out = run(stop_and_hold(1200), P0.replace(autohold={"enabled": False}))
    assert np.all(out["truth_brake_pressure"][700:] < 0.01)
    assert out["truth_vx"][-1] > 0.0  # and the creep moves the car off


# ----------------------------------------------------------------- gear
def test_gear_change_is_refused_while_moving():
    c = cmds(1000, gear=1)
    c[300:, 0] = -1  # request reverse while creeping forward
    c[500:700, 2] = -1.0  # then brake to a stop
    out = run(c)
    v, g = out["truth_vx"], out["gear"]
    moving = np.abs(v) > kmh_to_ms(P0.gear.max_shift_speed_kmh)
    assert np.all(g[300:][moving[300:]] == 1)  # refused while moving
    k = int(np.argmax(g == -1))  # taken at rest
    assert k > 300 and v[k - 1] == 0.0 and v[k] == 0.0
    slow = 300 + int(np.argmax(~moving[300:]))  # first sample slow enough to shift
    assert (k - slow) * DT == pytest.approx(P0.gear.shift_time_s, abs=1.5 * DT)


# ----------------------------------------------------------------- blind zone
def test_speed_below_half_kmh_reads_as_blind_zone_noise():
    out = run(cmds(800, gear=1))  # creep from rest through the blind zone
    v, log = out["truth_vx"], out["vx"]
    inside = np.abs(v) < BLIND_ZONE_MS
    assert inside.sum() > 50
    assert np.all(np.abs(log[inside]) < BLIND_ZONE_MS)  # stays inside the zone
    assert np.mean(log[inside] == 0.0) > 0.5  # mostly no pulse
    assert np.any(log[inside] != 0.0)  # with spikes
    err_inside = np.abs(log[inside] - v[inside])
    assert np.median(err_inside[log[inside] != 0.0]) > 0.02  # which do not measure speed
    above = np.abs(v) > kmh_to_ms(0.7)
    assert np.max(np.abs(log[above] - v[above])) < 6 * P0.wheel_speed.noise_ms + 0.003
    silent = run(
        cmds(800, gear=1), P0.replace(wheel_speed={"spike_prob": 0.0, "motion_spike_prob": 0.0})
    )
    assert np.all(silent["vx"][np.abs(silent["truth_vx"]) < BLIND_ZONE_MS] == 0.0)


# ----------------------------------------------------------------- quantization
def test_torque_and_pressure_are_quantized():
    c = stop_and_hold(1300)
    c[1000:, 1] = 37.0
    out = run(c)
    for name, q in (("torque", 2.0), ("brake_pressure", 1.0)):
        x = out[name]
        np.testing.assert_allclose(x / q, np.round(x / q), atol=1e-12)
        assert len(np.unique(x)) > 3
    coarse = run(c, P0.replace(bus={"torque_quantum_nm": 5.0}))["torque"]
    np.testing.assert_allclose(coarse / 5.0, np.round(coarse / 5.0), atol=1e-12)
    quiet = run(c, QUIET)
    assert np.max(np.abs(quiet["torque"] - quiet["truth_torque"])) <= 1.0 + 1e-9
    assert np.max(np.abs(quiet["brake_pressure"] - quiet["truth_brake_pressure"])) <= 0.5 + 1e-9


# ----------------------------------------------------------------- IMU pitch coupling
def test_ax_carries_the_pitch_coupling():
    c = stop_and_hold(1300)
    c[1000:, 1] = 80.0
    params = QUIET.replace(imu={"roll_gradient_deg": 0.0})
    out = run(c, params)
    ax = out["truth_ax"]
    imu = params.imu
    k, alpha = math.radians(imu.pitch_gradient_deg), 1.0 - math.exp(-DT / imu.pitch_lag_s)
    pitch = np.zeros_like(ax)  # independent re-implementation of the lagged pitch
    prev = 0.0
    for i, a in enumerate(ax):
        prev += (k * a - prev) * alpha
        pitch[i] = prev
    np.testing.assert_allclose(out["truth_pitch"], pitch, atol=1e-12)
    expected = ax + G * np.sin(pitch) + imu.ax_bias
    np.testing.assert_allclose(out["ax"], expected, atol=1e-12)
    assert np.max(np.abs(G * np.sin(pitch))) > 0.01  # a visible effect
    flat = run(c, params.replace(imu={"pitch_gradient_deg": 0.0, "roll_gradient_deg": 0.0}))
    np.testing.assert_allclose(flat["ax"], flat["truth_ax"] + imu.ax_bias, atol=1e-12)


# ----------------------------------------------------------------- drive lag
def _rise_time(vx: float, gear: int, p: DriveParams) -> float:
    """Time (s) for the motor torque to reach 63 % of a 100 N·m step at fixed speed."""
    act = DriveActuator(p, DT)
    act.reset(0.0)
    creep = act.creep(vx, gear)
    act.torque = creep
    for i in range(1, 500):
        if act.step(100.0, gear, False, vx) >= creep + 0.632 * (100.0 - creep):
            return i * DT
    raise AssertionError("no rise")


def test_drive_torque_response_depends_on_speed_and_gear():
    p = P0.drive
    rest_d, rest_r = _rise_time(0.0, 1, p), _rise_time(0.0, -1, p)
    moving_d = _rise_time(kmh_to_ms(3.0), 1, p)
    assert rest_d == pytest.approx(p.delay_s + p.tau_standstill_s, abs=0.02)
    assert rest_r == pytest.approx(p.delay_s + p.tau_standstill_s * p.reverse_lag_factor, abs=0.03)
    assert moving_d < rest_d - 0.1
    # and in the whole vehicle (braked at rest): R answers slower than D
    c = cmds(300, decel=-3.0)
    c[100:, 1] = 100.0
    t63 = {}
    for gear in (1, -1):
        c[:, 0] = gear
        tq = run(c, QUIET)["truth_torque"]
        t63[gear] = int(np.argmax(tq >= 0.632 * 100.0))
    assert t63[-1] > t63[1] + 5


# ----------------------------------------------------------------- steering
def test_steering_is_rate_limited():
    c = cmds(200, steer=0.0)
    c[20:, 3] = 400.0
    c[120:, 3] = -400.0
    for limit in (500.0, 200.0):
        out = run(c, P0.replace(steering={"rate_limit_dps": limit}))
        rate = np.abs(np.diff(out["truth_steer"])) / DT
        assert rate.max() <= limit + 1e-9
        assert rate.max() >= 0.99 * limit  # and the limit binds on a step


def test_yaw_rate_is_kinematic_with_the_nonlinear_rack_in_steady_state():
    out = run(cmds(1500, gear=1, steer=300.0), QUIET)
    car = ReferenceVehicle(QUIET)
    v, s, w = out["truth_vx"][-1], out["truth_steer"][-1], out["truth_yaw_rate"][-1]
    geom = car.geometry
    ratio = geom.steer_ratio_lock + (geom.steer_ratio_center - geom.steer_ratio_lock) * (
        1 - (s / geom.steer_lock_deg) ** 2
    )
    k_us = QUIET.lateral.understeer_gradient
    expected = v * math.tan(math.radians(s / ratio)) / (geom.wheelbase + k_us * v * v)
    assert w == pytest.approx(expected, rel=1e-6)
    # the IMU point ahead of the rear axle: ay = vx·ω + x_imu·dω/dt
    dw = (w - out["truth_yaw_rate"][-2]) / DT
    assert out["truth_ay"][-1] == pytest.approx(v * w + QUIET.imu.x_offset_m * dw, rel=1e-9)


# ----------------------------------------------------------------- determinism, physics
def test_deterministic_under_a_seed():
    c = stop_and_hold(600)
    a = ReferenceVehicle(seed=5).simulate(c)
    b = ReferenceVehicle(seed=5).simulate(c)
    d = ReferenceVehicle(seed=6).simulate(c)
    for name in a:
        np.testing.assert_array_equal(a[name], b[name])
    assert not np.array_equal(a["ax"], d["ax"])  # the noise follows the seed
    np.testing.assert_array_equal(a["truth_vx"], d["truth_vx"])  # the physics does not


def test_braking_never_reverses_the_motion():
    rng = np.random.default_rng(0)
    T = 3000
    c = cmds(T)
    for start in range(0, T, 250):  # random gear, torque and brake pieces
        c[start : start + 250, 0] = rng.choice([-1, 0, 1])
        c[start : start + 250, 1] = rng.choice([0.0, 30.0, 80.0])
        c[start : start + 250, 2] = rng.choice([0.0, -0.2, -1.0])
    out = run(c, QUIET, vx=1.0)
    v, g = out["truth_vx"], out["gear"]
    assert np.all(v[:-1] * v[1:] >= 0.0)  # every sign change passes through rest
    for k in np.flatnonzero(v[:-1] * v[1:] == 0.0):  # leaving rest needs drive that way
        if v[k] == 0.0 and v[k + 1] != 0.0:
            assert np.sign(v[k + 1]) == g[k + 1]
    coast = run(cmds(800, gear=0, decel=-0.3), QUIET, vx=1.0)["truth_vx"]
    assert np.all(np.diff(coast) <= 0.0) and coast[-1] == 0.0  # stops, stays stopped
    roll = run(cmds(50, gear=0), QUIET, vx=1.0)["truth_vx"]  # free roll: -c_rr·g exactly
    decel = -np.diff(roll[1:]) / DT
    np.testing.assert_allclose(decel, P0.body.rolling_resistance * G, rtol=1e-9)


def test_alt_vehicle_yaml_is_heavier_and_brakes_slower():
    alt = load_vehicle_params(CONFIG_DIR / "reference_vehicle_alt.yaml")
    c = cmds(300, gear=0)
    c[100:, 2] = -1.0  # a brake step at rest
    t63 = {}
    for name, p in (("default", QUIET), ("alt", alt)):
        pr = run(c, p)["truth_brake_pressure"]
        t63[name] = int(np.argmax(pr >= 0.632 * pr[-1])) - 100
    assert t63["alt"] > t63["default"] + 5
    launch = cmds(200, gear=1, torque=80.0)  # same torque, less acceleration
    a_def = run(launch, QUIET)["truth_vx"][-1]
    a_alt = run(launch, alt)["truth_vx"][-1]
    assert a_alt < a_def * P0.body.mass_kg / alt.body.mass_kg  # F/m with more rolling drag
