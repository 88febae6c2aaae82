"""The gymnasium environment: gymnasium's env checker, seeded determinism, highway-env's
reward (analytic values, vectorised), termination rules, render, the vector version, and
raw commands on the chain plant."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import parknss.envs  # noqa: F401  (registers parknss/Parking-v0)
from parknss.envs import ENV_ID, ParkingEnv, make_vec
from parknss.envs.parking import goal_reward
from parknss.errors import ConfigError

torch.set_num_threads(1)
gym = pytest.importorskip("gymnasium")


def test_env_checker_passes():
    import warnings

    from gymnasium.utils.env_checker import check_env

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(ParkingEnv(render_mode="rgb_array"), skip_render_check=False)
    texts = [str(w.message) for w in caught]
    assert not [t for t in texts if "bound" in t.lower() or "infin" in t.lower()], texts


def test_observation_space_is_finite_and_holds_every_observation():
    """Finite bounds from the scenes' maps and the speed bound; a car driven at full
    torque (raw commands) is reported at the speed bound, never outside the space."""
    env = ParkingEnv(plant="chain", actions="raw", obs_speed_max_ms=0.2)
    box = env.observation_space["observation"]
    assert np.all(np.isfinite(box.low)) and np.all(np.isfinite(box.high))
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    fastest = 0.0
    for _ in range(40):
        obs, *_ = env.step(np.array([1.0, 1.0, 0.0, 1.0], np.float32))
        assert env.observation_space.contains(obs)
        fastest = max(fastest, float(np.hypot(*obs["observation"][2:4])) * 5.0)
    assert fastest == pytest.approx(0.2, abs=1e-6)  # the chain reaches 0.2 m/s: clamped


def test_reward_is_highway_envs_weighted_p_norm():
    env = ParkingEnv()
    w = np.array([1, 0.3, 0, 0, 0.02, 0.02])
    a = np.array([0.1, 0.2, 0, 0, 1, 0])
    d = np.array([0.0, 0.0, 0, 0, 0, 1])
    want = -np.sqrt(0.1 + 0.3 * 0.2 + 0.02 + 0.02)
    assert env.compute_reward(a, d, {}) == pytest.approx(want)
    batch = env.compute_reward(np.stack([a, d, a]), np.stack([d, d, a]), [{}] * 3)
    assert batch.shape == (3,)
    assert batch == pytest.approx([want, 0.0, 0.0])
    assert goal_reward(a, a, w, 0.5) == 0.0


def _rollout(env, seed, n=30):
    obs, _ = env.reset(seed=seed)
    env.action_space.seed(seed)
    out = [obs["observation"]]
    for _ in range(n):
        obs, _, term, trunc, _ = env.step(env.action_space.sample())
        out.append(obs["observation"])
        if term or trunc:
            break
    return np.array(out)


def test_seeding_is_deterministic():
    env = gym.make(ENV_ID)
    a, b = _rollout(env, 7), _rollout(env, 7)
    assert np.array_equal(a, b)


def test_time_limit_truncates_and_success_terminates():
    env = ParkingEnv(time_limit_s=0.5)
    env.reset(seed=0)
    steps = 0
    while True:
        _, _, term, trunc, info = env.step(np.zeros(2, np.float32))
        steps += 1
        if term or trunc:
            break
    assert trunc and not term and steps == 5 and info["reason"] == "time_limit"
    env.reset(seed=0)
    env.goal = env._obs()["achieved_goal"]  # standing on the goal: success at once
    _, r, term, _, info = env.step(np.zeros(2, np.float32))
    assert term and info["is_success"] and r > -env.cfg.success_goal_reward
    assert info["reason"] == "success"


def test_collision_terminates():
    env = ParkingEnv(scenes="cell:0", time_limit_s=120)
    env.reset(seed=0)
    for _ in range(600):
        _, r, term, trunc, info = env.step(np.array([1.0, 1.0], np.float32))
        if term or trunc:
            break
    assert term and info["crashed"] and r < env.cfg.collision_reward + 1e-9
    assert info["reason"] in ("collision", "left_map")


def test_render_rgb_array():
    """An RGB array; driving adds the trail and moves the car and its heading arrow, so
    the picture changes where the car went (and only a little elsewhere)."""
    env = ParkingEnv(render_mode="rgb_array")
    env.reset(seed=1)
    img = env.render()
    assert img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8
    assert img.std() > 0  # something is drawn
    for _ in range(15):
        env.step(np.array([0.6, 0.3], np.float32))
    later = env.render()
    assert later.shape == img.shape
    changed = np.any(later != img, axis=2)
    assert 0.001 < changed.mean() < 0.2  # the trail, the car, the arrow, the title


def test_vector_env_matches_single_envs():
    vec = make_vec(2)
    obs, _ = vec.reset(seed=3)
    single = [ParkingEnv() for _ in range(2)]
    for i, e in enumerate(single):
        o, _ = e.reset(seed=3 + i)
        assert np.array_equal(obs["observation"][i], o["observation"])
    act = np.array([[0.5, 0.1], [-0.5, -0.2]], np.float32)
    obs, r, *_ = vec.step(act)
    for i, e in enumerate(single):
        o, ri, *_ = e.step(act[i])
        assert np.array_equal(obs["observation"][i], o["observation"]) and r[i] == ri
    vec.close()


def test_raw_commands_drive_the_chain_and_refuse_the_kinematic_plant():
    with pytest.raises(ConfigError, match="raw commands"):
        ParkingEnv(actions="raw")
    env = ParkingEnv(plant="chain", actions="raw")
    assert env.action_space.shape == (4,)
    env.reset(seed=0)
    for _ in range(5):  # full torque in drive: the car moves off
        obs, *_ = env.step(np.array([1.0, 1.0, 0.0, 1.0], np.float32))
    assert abs(obs["observation"][2]) + abs(obs["observation"][3]) > 0


def test_the_car_is_the_vehicle_yaml_and_the_scenes_scale_with_it():
    """The env plans, checks and draws the named car (issue 17: one car end to end): the
    TPCAP car's grid slots are sized for it, and its steering lock bounds the action."""
    from parknss.config import CONFIG_DIR
    from parknss.sim import scenarios as sc
    from parknss.vehicle import load_vehicle_geometry

    path = CONFIG_DIR / "tpcap_vehicle.yaml"
    car = load_vehicle_geometry(path)
    env = ParkingEnv(plant="kinematic", scenes="36", vehicle_yaml=str(path))
    assert env.geom == car and car.wheelbase == pytest.approx(2.8)
    env.reset(seed=0, options={"scene": ("36", 0)})

    def same(a, b) -> bool:
        oa, ob = a.obstacle_arrays(), b.obstacle_arrays()
        return len(oa) == len(ob) and all(
            p.shape == q.shape and np.allclose(p, q) for p, q in zip(oa, ob, strict=True))

    assert same(env.scene, sc.cell_scene("36", 0, geom=car))
    assert not same(env.scene, sc.cell_scene("36", 0))  # the default car's slot differs
