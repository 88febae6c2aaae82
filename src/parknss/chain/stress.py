"""Envelope stress study (paper §V-E): command streams far outside the data.

Starting from a logged command stream (the first ``stress.seconds`` of a trial), each
scenario distorts it: torque x3; the deceleration command driven to -5 m/s² whenever it
brakes and over a sustained window; steering steps between ±600° slewing at 1000 °/s;
NaN and ±inf injected into every command channel; uniformly random commands far outside
the domains. Every stream runs through the real-time chain and the batched rollout; the
report says, per scenario, whether any actual left its envelope (torque/pressure below
the floor, steering beyond the lock or the rate limit), whether any state is not finite,
the largest deviation between the two paths, and which envelope acted how often.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from parknss.actuators.config import StressConfig, load_actuator_config
from parknss.actuators.envelopes import Activity
from parknss.chain.deployed import DeployedChain, load_chain
from parknss.config import SHIPPED_CHAIN
from parknss.data.trial import Trial
from parknss.nss.campaigns import load_campaign
from parknss.signals import COMMAND_CHANNELS, DT


def scenarios(tr: Trial, cfg: StressConfig, seed: int = 0) -> dict[str, np.ndarray]:
    """name -> command stream (T, 4) [gear, torque_cmd, decel_cmd, steer_cmd]."""
    n = min(tr.n, round(cfg.seconds / DT))
    base = tr.array(COMMAND_CHANNELS)[:n]
    rng = np.random.default_rng(seed)
    out = {"logged": base.copy()}
    s = base.copy()
    s[:, 1] *= cfg.torque_factor
    out["torque_x3"] = s
    s = base.copy()
    s[s[:, 2] < 0, 2] = cfg.decel_ms2
    s[n // 3 : n // 3 + n // 10, 2] = cfg.decel_ms2
    out["decel_-5"] = s
    s = base.copy()
    t = np.arange(n) * DT
    tri = np.clip(cfg.steer_rate_dps * (t % 4.0) - 2 * cfg.steer_step_deg, -1e9, 1e9)
    s[:, 3] = np.clip(np.where((t // 2.0) % 2 == 0, tri, -tri), -cfg.steer_step_deg,
                      cfg.steer_step_deg)
    out["steer_1000dps"] = s
    for name, val in (("nan", np.nan), ("inf", np.inf)):
        s = base.copy()
        for j in (1, 2, 3):
            idx = rng.random(n) < 0.05
            sign = rng.choice([-1.0, 1.0], size=idx.sum())
            s[idx, j] = val * sign if name == "inf" else val
        out[name] = s
    s = base.copy()
    s[:, 1] = rng.uniform(-500, 1500, n)
    s[:, 2] = rng.uniform(-20, 5, n)
    s[:, 3] = rng.uniform(-2000, 2000, n)
    out["random"] = s
    return out


@dataclass
class StressRow:
    """One scenario: envelope violations and non-finite states (counts), the largest
    real-time vs batched vx difference (m/s), the actuals' ranges (N·m, bar, deg), the
    highest steering rate (deg/s) and which envelopes acted how often."""

    scenario: str
    violations: int
    nonfinite_states: int
    max_path_diff: float
    torque_range: tuple[float, float]
    pressure_range: tuple[float, float]
    steer_range: tuple[float, float]
    max_steer_rate_dps: float
    active: list[str]
    activity: dict

    def to_json(self) -> dict:
        return dict(self.__dict__)


def run_stress(
    deployed: DeployedChain, tr: Trial, cfg: StressConfig, seed: int = 0
) -> list[StressRow]:
    """Run every scenario through ``deployed`` (real time and batched)."""
    env = deployed.chain.envelope
    rows = []
    x0 = [tr["vx"][0], tr["yaw_rate"][0]]
    y0 = [tr["torque"][0], tr["brake_pressure"][0], tr["steer"][0]]
    for name, cmds in scenarios(tr, cfg, seed).items():
        deployed.rt.env.activity = Activity()
        deployed.start(x0, y0, cmds[0])
        acts, sts = [], []
        for k in range(len(cmds)):
            a, s = deployed.rt.step(*cmds[k])
            acts.append(a)
            sts.append(s)
        act, st = np.array(acts), np.array(sts)
        with torch.no_grad():
            r = deployed.chain.rollout(cmds[None], torch.tensor([x0]), torch.tensor([y0]),
                                       gear_rule=deployed.rt.shift is not None)
        diff = float(np.max(np.abs(r.nss.vx[0].numpy() - st[:, 0])))
        rate = np.abs(np.diff(np.r_[y0[2], act[:, 2]])) / DT
        viol = int(np.sum(act[:, 0] < env.torque_floor) + np.sum(act[:, 1] < env.pressure_floor)
                   + np.sum(np.abs(act[:, 2]) > env.steer_lock + 1e-9)
                   + np.sum(rate > env.steer_rate_dps * (1 + 1e-9)))
        activity = deployed.rt.env.activity
        rows.append(StressRow(
            name, viol, int(np.sum(~np.isfinite(st))), diff,
            (float(act[:, 0].min()), float(act[:, 0].max())),
            (float(act[:, 1].min()), float(act[:, 1].max())),
            (float(act[:, 2].min()), float(act[:, 2].max())),
            float(rate.max()), activity.active(), activity.to_json(),
        ))
    return rows


def stress_study(
    chain: Path | None = None, data: Path | None = None, config: Path | None = None
) -> dict:
    """``parknss actuators stress``: the stress study of the chain artefact ``chain`` (None:
    the shipped one) on the first park-in trial of the campaign ``data`` (None: the default
    campaign) with the ``stress`` section of the actuator YAML ``config``; one JSON
    document (``ok``: no violation, no non-finite state in any scenario)."""
    torch.set_num_threads(1)
    cfg = load_actuator_config(config)
    campaign = load_campaign(data, "actuators", "parknss actuators stress")
    dep = load_chain(chain or SHIPPED_CHAIN)
    tr = next((t for t in campaign if t.maneuver.startswith("park_in")), campaign[0])
    rows = run_stress(dep, tr, cfg.stress)
    return {"chain": str(chain or SHIPPED_CHAIN), "trial": tr.id,
            "envelope": dep.chain.envelope.to_json(), "rows": [r.to_json() for r in rows],
            "ok": all(r.violations == 0 and r.nonfinite_states == 0 for r in rows)}


def stress_text(doc: dict) -> str:
    """The :func:`stress_study` document as a fixed-width table."""
    lines = [f"{'scenario':14s} {'viol':>5s} {'NaN st':>6s} {'torque':>16s} {'pressure':>14s} "
             f"{'steer':>18s} {'rate°/s':>8s}  active envelopes"]
    for r in doc["rows"]:
        lines.append(
            f"{r['scenario']:14s} {r['violations']:5d} {r['nonfinite_states']:6d} "
            f"{r['torque_range'][0]:7.1f}..{r['torque_range'][1]:<7.1f} "
            f"{r['pressure_range'][0]:5.1f}..{r['pressure_range'][1]:<7.1f} "
            f"{r['steer_range'][0]:8.1f}..{r['steer_range'][1]:<8.1f} "
            f"{r['max_steer_rate_dps']:8.1f}  {', '.join(sorted(set(r['active']))) or '-'}")
    lines.append("all within envelopes, no NaN states" if doc["ok"] else "ENVELOPE VIOLATED")
    return "\n".join(lines)
