"""The parking task as a gymnasium environment, in highway-env's goal-conditioned convention.

:class:`ParkingEnv` (registered as ``parknss/Parking-v0`` by importing :mod:`parknss.envs`)
drives any parknss plant (kinematic, chain, reference: :func:`parknss.sim.plants.make_plant`)
in a scene of the scenario grids or a scene file, at ``steps_per_action`` 10 ms plant steps
per env step.

* **Observation**: a Dict of ``observation``, ``achieved_goal`` (both the rear-axle state
  [x, y, vx·cos h, vx·sin h, cos h, sin h] divided by ``obs_scales``) and ``desired_goal``
  (the goal pose in the same features, speed 0), float32 (6,), as highway-env's parking-v0.
  The space is finite: x, y within the union of the scenes' maps grown by the car's length,
  the speed within ``obs_speed_max_ms`` (a faster car, raw commands only, is reported at
  that bound: the one documented clamp).
* **Action** (Box [-1, 1]): ``requests`` (default) [speed, steer]: a signed speed request of
  up to ``max_speed_ms`` (|a| below ``speed_deadband``: stop and hold) and a steering-wheel
  angle of up to the lock, through the plant's command interface
  (:class:`~parknss.sim.control.interface.CommandInterface`: gear only at standstill,
  brake-hold, PI speed control); ``raw`` [torque, decel, steer, gear]: the production
  commands directly (torque_cmd 0..torque_max, decel_cmd decel_min..0, steer_cmd ±lock,
  gear -1/0/1 by thirds), chain and reference plants only.
* **Reward**: :meth:`ParkingEnv.compute_reward`, -‖(achieved - desired)·w‖_p (the weighted
  p-norm with p = 0.5 of highway-env), vectorised over leading axes; plus
  ``collision_reward`` on a collision.
* **Termination** on success (goal reward > -``success_goal_reward``) or a collision (the
  footprint overlaps an obstacle or leaves the map), **truncation** at ``time_limit_s``.
  ``info["reason"]`` says which: ``"success"``, ``"collision"``, ``"left_map"``,
  ``"time_limit"`` (``None`` while the episode runs).
* **Seeding**: ``reset(seed=...)`` draws the scene (and the reference plant's sensor seed)
  from the env's generator, so the same seed gives the same episode.
* ``render()`` returns an RGB array drawn by the report's scene drawing
  (:func:`parknss.report.plan_figure.scene_axes`, ``outline``): the map in metres with
  axes, the goal (dotted), the car's footprint with a heading arrow, and the rear axle's
  trail so far (solid forward, dashed reverse).
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from parknss.envs.config import EnvConfig, load_env_config
from parknss.errors import ConfigError
from parknss.plant import Commands
from parknss.sim import geometry
from parknss.sim import scenarios as sc
from parknss.sim.control.interface import Request, load_interface_config
from parknss.sim.plants import PoseIntegrator, make_plant
from parknss.sim.vehicles import resolve_vehicle
from parknss.vehicle import VehicleGeometry

ENV_ID = "parknss/Parking-v0"


def goal_reward(achieved: np.ndarray, desired: np.ndarray, weights, p: float) -> np.ndarray:
    """-(Σ_i w_i·|a_i - d_i|)^p over the last axis (any leading shape)."""
    return -np.power(np.dot(np.abs(achieved - desired), np.asarray(weights, float)), p)


class ParkingEnv(gym.Env):
    """See the module doc. ``config``: an :class:`EnvConfig` (default: the shipped YAML);
    keyword overrides (``plant="chain"``) replace its fields."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, config: EnvConfig | None = None, render_mode: str | None = None,
                 **overrides: Any) -> None:
        cfg = config or load_env_config()
        self.cfg = cfg.model_copy(update=overrides) if overrides else cfg
        if overrides:
            self.cfg = EnvConfig.model_validate(self.cfg.model_dump())
        if render_mode not in (None, "rgb_array"):
            raise ConfigError(f"render_mode {render_mode!r}: only 'rgb_array'")
        if self.cfg.actions == "raw" and self.cfg.plant == "kinematic":
            raise ConfigError("raw commands need the chain or the reference plant "
                              "(the kinematic plant has no actuators)")
        self.render_mode = render_mode
        # the car: the vehicle YAML, else the chain's own, else the default (sim/vehicles.py)
        self.geom = resolve_vehicle(self.cfg.vehicle_yaml, self.cfg.chain_path)
        self.iface_cfg = load_interface_config()
        self._scene_specs = self._scenes(self.cfg.scenes, self.geom)
        self._scene_cache: dict[Any, sc.Scene] = {}
        self.plant = None if self.cfg.plant == "reference" else self._make_plant(None)
        box = self._observation_box()
        self.observation_space = spaces.Dict(
            {"observation": box, "achieved_goal": box, "desired_goal": box})
        n_act = 4 if self.cfg.actions == "raw" else 2
        self.action_space = spaces.Box(-1.0, 1.0, shape=(n_act,), dtype=np.float32)
        self.scene: sc.Scene | None = None

    # --------------------------------------------------------------- set-up
    @staticmethod
    def _scenes(spec: str, geom: VehicleGeometry) -> list[Any]:
        if spec in sc.GRIDS:
            return [(spec, i) for i in sc.grid_cells(spec)]
        if spec.startswith("cell:"):
            return [sc.resolve_scene(spec[5:], geom=geom)]
        return [sc.resolve_scene(spec, geom=geom)]

    def _scene(self, key: Any) -> sc.Scene:
        if isinstance(key, sc.Scene):
            return key
        if key not in self._scene_cache:
            self._scene_cache[key] = sc.cell_scene(key[0], key[1], geom=self.geom)
        return self._scene_cache[key]

    def _make_plant(self, seed: int | None):
        return make_plant(self.cfg.plant, geom=self.geom, vehicle_yaml=self.cfg.vehicle_yaml,
                          chain_path=self.cfg.chain_path, seed=seed,
                          chain_engine=self.cfg.chain_engine)

    # ---------------------------------------------------------- observation
    def _observation_box(self) -> spaces.Box:
        """The finite feature box (module doc): every scene's map grown by the car's length
        (the rear axle of a car whose footprint just left the map), the speed bound."""
        b = np.array([self._scene(k).bounds for k in self._scene_specs], dtype=float)
        grow = self.geom.length + self.cfg.max_speed_ms * self.cfg.steps_per_action * 0.01
        v = self.cfg.obs_speed_max_ms
        lo = np.array([b[:, 0].min() - grow, b[:, 1].min() - grow, -v, -v, -1.0, -1.0])
        hi = np.array([b[:, 2].max() + grow, b[:, 3].max() + grow, v, v, 1.0, 1.0])
        sc_ = np.asarray(self.cfg.obs_scales, float)
        self._obs_lo, self._obs_hi = (lo / sc_).astype(np.float32), (hi / sc_).astype(np.float32)
        return spaces.Box(self._obs_lo, self._obs_hi, shape=(6,), dtype=np.float32)

    def _features(self, x: float, y: float, h: float, v: float) -> np.ndarray:
        v = min(max(v, -self.cfg.obs_speed_max_ms), self.cfg.obs_speed_max_ms)
        f = np.array([x, y, v * math.cos(h), v * math.sin(h), math.cos(h), math.sin(h)])
        f = (f / np.asarray(self.cfg.obs_scales)).astype(np.float32)
        return np.clip(f, self._obs_lo, self._obs_hi)

    def _obs(self) -> dict[str, np.ndarray]:
        x, y, h = self.integ.pose
        ach = self._features(x, y, h, self.y.vx)
        return {"observation": ach.copy(), "achieved_goal": ach, "desired_goal": self.goal.copy()}

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray,
                       info: dict | list | None) -> np.ndarray | float:
        """highway-env's goal reward, vectorised over leading axes (HER relabelling)."""
        r = goal_reward(np.asarray(achieved_goal, float), np.asarray(desired_goal, float),
                        self.cfg.reward_weights, self.cfg.reward_p)
        return float(r) if np.ndim(r) == 0 else r

    # ------------------------------------------------------------ the loop
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        opts = options or {}
        if "scene" in opts:
            key: Any = opts["scene"]
        else:
            key = self._scene_specs[int(self.np_random.integers(len(self._scene_specs)))]
        self.scene = self._scene(key)
        if self.cfg.plant == "reference":
            self.plant = self._make_plant(int(self.np_random.integers(2**31 - 1)))
        self.iface = self.plant.command_interface(self.iface_cfg, self.plant.dt)
        self.y = self.plant.reset()
        self.integ = PoseIntegrator(self.scene.start, self.plant.dt)
        self.obstacles = self.scene.obstacle_arrays()
        self.circles = geometry.polygon_circles(self.obstacles)
        self.direction = 0
        self.t = 0.0
        gx, gy, gh = self.scene.goal
        self.goal = self._features(gx, gy, gh, 0.0)
        self.trail = [(*self.integ.pose[:2], 1)]
        return self._obs(), {"scene": self.scene.meta.name, "is_success": False,
                             "reason": None}

    def _command(self, a: np.ndarray) -> Commands:
        lock = self.geom.steer_lock_deg
        if self.cfg.actions == "raw":
            ic = self.iface_cfg
            gear = -1 if a[3] < -1 / 3 else (1 if a[3] > 1 / 3 else 0)
            return Commands(gear, float((a[0] + 1) / 2 * ic.torque_max_nm),
                            float((1 - a[1]) / 2 * ic.decel_min_ms2), float(a[2] * lock))
        s = float(a[0])
        if abs(s) >= self.cfg.speed_deadband:
            self.direction = 1 if s > 0 else -1
        speed = abs(s) * self.cfg.max_speed_ms if abs(s) >= self.cfg.speed_deadband else 0.0
        req = Request(self.direction, speed, float(a[1]) * lock)
        return self.iface.step(req, self.y)

    def step(self, action):
        a = self.checked_action(action)
        poses: list = []
        for _ in range(self.cfg.steps_per_action):
            self.advance(self.plant.step(self.command(a)), poses)
        return self.outcome(poses)

    # the step in phases, for ParkingVecEnv (which steps its envs' plants together)
    def checked_action(self, action) -> np.ndarray:
        """The action clipped to [-1, 1]; ConfigError for a wrong shape or non-finite."""
        a = np.clip(np.asarray(action, dtype=np.float64).reshape(-1), -1.0, 1.0)
        if a.shape != self.action_space.shape or not np.all(np.isfinite(a)):
            raise ConfigError(f"action must be {self.action_space.shape} finite numbers")
        return a

    def command(self, a: np.ndarray) -> Commands:
        """The plant command of one 10 ms sample under the checked action ``a``."""
        return self._command(a)

    def advance(self, y, poses: list) -> None:
        """Take the plant's output ``y`` of one sample: move the pose (appended to
        ``poses``) and the clock."""
        self.y = y
        poses.append(self.integ.step(*self.plant.motion))
        self.t += self.plant.dt

    def outcome(self, poses: list):
        """(obs, reward, terminated, truncated, info) after the samples of ``poses``."""
        p = np.asarray(poses)
        sign = 1 if self.y.vx >= 0 else -1
        self.trail.extend((float(x), float(y), sign) for x, y in p[:, :2])
        hit = bool(np.any(geometry.collides(p, self.geom, self.obstacles, circles=self.circles)))
        out = not bool(np.all(geometry.inside_map(p, self.geom, self.scene)))
        obs = self._obs()
        reward = float(self.compute_reward(obs["achieved_goal"], obs["desired_goal"], {}))
        success = reward > -self.cfg.success_goal_reward
        if hit or out:
            reward += self.cfg.collision_reward
        terminated = bool(success or hit or out)
        truncated = bool(self.t >= self.cfg.time_limit_s - 1e-9) and not terminated
        reason = ("success" if success else "collision" if hit else "left_map" if out
                  else "time_limit" if truncated else None)
        info = {"is_success": bool(success), "crashed": hit or out, "t": self.t,
                "gear": self.y.gear, "reason": reason}
        return obs, reward, terminated, truncated, info

    # -------------------------------------------------------------- render
    def render(self) -> np.ndarray | None:
        """The scene with axes in metres, the goal (dotted), the rear axle's trail (solid
        forward, dashed reverse) and the car's footprint with a heading arrow, as an RGB
        array (H, W, 3)."""
        if self.render_mode != "rgb_array" or self.scene is None:
            return None
        import matplotlib.pyplot as plt

        from parknss.report.plan_figure import outline, scene_axes

        fig, ax = scene_axes(self.scene, frame=True)
        try:
            outline(ax, geometry.footprint(self.scene.goal, self.geom), color="#1e8449", ls=":")
            tr = np.asarray(self.trail)
            cut = np.flatnonzero(np.diff(tr[:, 2])) + 1  # direction changes
            for seg in np.split(tr, cut):
                ax.plot(seg[:, 0], seg[:, 1], "-" if seg[0, 2] > 0 else "--",
                        color="#5dade2", lw=1.2)
            outline(ax, geometry.footprint(self.integ.pose, self.geom), color="#2471a3", lw=2)
            x, y, h = self.integ.pose
            arrow = 0.6 * self.geom.wheelbase
            ax.annotate("", xy=(x + arrow * math.cos(h), y + arrow * math.sin(h)), xytext=(x, y),
                        arrowprops={"arrowstyle": "-|>", "color": "#2471a3", "lw": 1.5})
            xmin, ymin, xmax, ymax = self.scene.bounds
            ax.set_aspect("equal")
            ax.set_xlim(xmin - 0.5, xmax + 0.5)
            ax.set_ylim(ymin - 0.5, ymax + 0.5)
            ax.set_xlabel("x [m]")
            ax.set_ylabel("y [m]")
            ax.set_title(f"{self.scene.meta.name}  t = {self.t:.1f} s  vx = {self.y.vx:+.2f} m/s"
                         f"  gear {self.y.gear:+.0f}")
            fig.set_dpi(self.cfg.render_dpi)
            fig.canvas.draw()
            return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
        finally:
            plt.close(fig)
