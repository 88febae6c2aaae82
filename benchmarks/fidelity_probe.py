"""Probe: where the learned chain departs from the truth (issue 44, the fidelity plan).

    python benchmarks/fidelity_probe.py [--cells 0,26] [--json]
    python benchmarks/fidelity_probe.py --stops 31,12   # per-stop errors of grid cells
    python benchmarks/fidelity_probe.py --steps-only --chain C [--plant nss [--no-latch]]
    python benchmarks/fidelity_probe.py --torque --chain C [--plant nss]  # the torque trap

Two measurements, both on the shipped chain (models/chain, or ``--chain C``) and the
reference vehicle (``--plant nss``: the step tests with the truth's actuators driving the
chain's NSS, the hybrid of ``parknss fidelity --candidate nss``; ``--no-latch`` without the
chain's brake-hold latch, so the NSS's own standstill shows):

1. **Step tests** (open loop, from rest in gear, brake released, steering wheel at 0 or
   360° = 90 % of the lock, forward and reverse): the creep (no torque, no brake, 8 s),
   then the stop from it under the interface's hold (decel_cmd -0.6 m/s², 3 s); and a
   launch (15 or 30 N·m for 2 s). Per test: the speed reached, the curvature ω/vx, the
   time to stop (true |vx| < 0.01 m/s; "-" if still moving) and the speed left after the
   hold, chain against truth (true states of both).
   ``--torque``: the torque trap (docs/closed_loop.md, "the chain's stop offset"): from
   rest, 28 N·m for 1 s, then a constant 15 / 30 / 45 / 60 / 85 N·m, brake released, in
   both gears at 0 and 360°; the true vx at 3 and 7 s. The truth's speed rises with the
   torque; a chain whose speed falls as the torque rises has a speed attractor that a
   speed controller winds into. Passes when vx at 7 s rises with the torque in every
   gear and steering angle, for the chain. Below it, the chain's NSS alone (its own
   rollout, the same torques as its input, steering 0): vx and the second state at 7 s,
   dvx/dt there and with the second state put back on the kinematic prior (ω_res = 0),
   and the torque gain d(dvx/dt)/dτ at the state. A steady speed held by the second
   state (dvx/dt ≈ 0 at the state, far from 0 on the prior) is the hidden speed
   regulator that ``loss.lambda_decouple`` penalises (docs/nss.md).
2. **Command replay**: a grid cell is driven in closed loop under the truth; its
   recorded command sequence (gear, torque, deceleration, steering) is replayed open loop
   into the chain and into a fresh truth of the same seed (which reproduces the run).
   Per regime of the truth's samples, the chain's true vx and yaw-rate errors:
   launch/creep (a drive gear, 0 < |vx| < the blind zone 0.139 m/s, accelerating),
   stop (same speeds, decelerating), hold (|vx| < 0.01 m/s), cruise forward / reverse
   (|vx| ≥ the blind zone), and full lock (|steer| ≥ 300° while moving).
"""

from __future__ import annotations

import argparse
import itertools
import json
from pathlib import Path

import numpy as np

from parknss.plant import Commands
from parknss.sim.closed_loop import ClosedLoopConfig
from parknss.sim.hybrid import make_hybrid
from parknss.sim.plants import ChainPlant, ReferencePlant
from parknss.sim.scenarios import grid_scene
from parknss.sim.session import run_cell

BLIND = 0.5 / 3.6  # the wheel-speed blind zone, m/s


def _run(plant, cmds: list[Commands], gear: int) -> np.ndarray:
    """True (vx, yaw rate) and bus vx after each command; from rest in ``gear``."""
    y = plant.reset(gear=gear)
    out = [(plant.truth(y).vx, plant.truth(y).yaw_rate, y.vx)]
    for c in cmds[:-1]:
        y = plant.step(c)
        t = plant.truth(y)
        out.append((t.vx, t.yaw_rate, y.vx))
    return np.array(out)


def _factory(chain: str | None, plant: str, latch: bool, seed: int):
    def model():
        if plant == "nss":
            return make_hybrid("nss", chain_path=chain, seed=seed, latch=latch)
        return ChainPlant(chain)

    return model


def rest_holds(
    seed: int = 5, chain: str | None = None, plant: str = "chain", latch: bool = True
) -> list[dict]:
    """The standstill: from rest in gear, a full brake request (decel_cmd -0.8 m/s²) held
    for 3 s; per plant the largest |vx| over the hold and vx at its end (true states)."""
    model = _factory(chain, plant, latch, seed)
    rows = []
    for gear in (1, -1):
        for steer in (0.0, 360.0):
            cmds = [Commands(gear, 0.0, -0.8, steer)] * 300
            res = {}
            for name, p in (("chain", model()), ("truth", ReferencePlant(seed=seed))):
                v = _run(p, cmds, gear)[:, 0]
                res[name] = {"max_abs_vx": float(np.abs(v).max()), "vx_end": float(v[-1])}
            rows.append({"gear": gear, "steer_deg": steer, **res})
    return rows


def step_tests(
    seed: int = 5, chain: str | None = None, plant: str = "chain", latch: bool = True
) -> list[dict]:
    """Creep (8 s, no torque, no brake), a launch (``torque`` N·m for 2 s from rest) and
    the stop from the creep under the interface's hold (decel_cmd -0.6 m/s², 3 s), of the
    chain ``chain`` (``plant`` "chain") or of its NSS driven by the truth's actuators
    (``plant`` "nss", with or without the chain's brake-hold latch)."""

    model = _factory(chain, plant, latch, seed)
    rows = []
    for gear in (1, -1):
        for steer in (0.0, 360.0):
            for torque in (0.0, 15.0, 30.0):
                if torque == 0.0:
                    cmds = [Commands(gear, 0.0, 0.0, steer)] * 800
                    cmds += [Commands(gear, 0.0, -0.6, steer)] * 300
                else:
                    cmds = [Commands(gear, torque, 0.0, steer)] * 200
                res = {}
                for name, p in (("chain", model()), ("truth", ReferencePlant(seed=seed))):
                    s = _run(p, cmds, gear)
                    end = 799 if torque == 0.0 else 199
                    vx, w = s[end, :2]
                    r = {"vx": float(vx), "curvature": float(w / vx) if abs(vx) > 0.05 else None}
                    if torque == 0.0:
                        after = s[800:, 0]
                        moving = np.flatnonzero(np.abs(after) >= 0.01)
                        r["stop_s"] = (
                            None
                            if len(moving) and moving[-1] == len(after) - 1
                            else float((moving[-1] + 1 if len(moving) else 0) * 0.01)
                        )
                        r["vx_after_hold"] = float(after[-1])
                    res[name] = r
                rows.append({"gear": gear, "steer_deg": steer, "torque_nm": torque, **res})
    return rows


TRAP_TORQUES = (15.0, 30.0, 45.0, 60.0, 85.0)


def torque_trap(
    seed: int = 5, chain: str | None = None, plant: str = "chain", latch: bool = True
) -> list[dict]:
    """The torque trap (module doc, ``--torque``): per gear and steering angle, the true vx
    at 3 s and 7 s for each torque of ``TRAP_TORQUES``, chain and truth, and whether the
    chain's vx at 7 s rises with the torque (strictly, in the gear's direction)."""
    model = _factory(chain, plant, latch, seed)
    rows = []
    for gear in (1, -1):
        for steer in (0.0, 360.0):
            res: dict[str, list] = {"chain": [], "truth": []}
            for torque in TRAP_TORQUES:
                cmds = [Commands(gear, 28.0, 0.0, steer)] * 100
                cmds += [Commands(gear, torque, 0.0, steer)] * 601
                for name, p in (("chain", model()), ("truth", ReferencePlant(seed=seed))):
                    v = _run(p, cmds, gear)[:, 0]
                    res[name].append((float(v[300]), float(v[700])))
            end = [gear * v7 for _, v7 in res["chain"]]
            mono = all(b > a for a, b in itertools.pairwise(end))
            rows.append({"gear": gear, "steer_deg": steer, "monotone": mono, **res})
    return rows


def regulator(chain: str | None = None) -> list[dict]:
    """The chain's NSS alone (``<chain>/nss``), open loop from rest: 28 N·m for 1 s, then
    each torque of ``TRAP_TORQUES`` for 6 s, brake released, steering 0, both gears; at
    7 s the speed, the scaled second state, dvx/dt at the state and on the kinematic
    prior, and the gain per 10 N·m, all m/s and m/s² (module doc, ``--torque``)."""
    import torch

    from parknss.config import SHIPPED_PLANT
    from parknss.nss.checkpoint import load_model

    m = load_model(Path(chain or SHIPPED_PLANT) / "nss").model.double()
    rows = []
    for gear in (1.0, -1.0):
        for torque in TRAP_TORQUES:
            u = torch.zeros(1, 701, 4, dtype=torch.float64)
            u[..., 0] = gear
            u[..., 1] = torque
            u[0, :100, 1] = 28.0
            with torch.no_grad():
                r = m.rollout(torch.zeros(1, 2, dtype=torch.float64), u, engine="eager")
                x = r.state_s[0, -1:].clone()
                us = m.scale_inputs(u[0, -1:])
                hi = us.clone()
                hi[:, 1] += 10.0 / m.in_sc[1]
                prior = x.clone()
                prior[:, 1] = 0.0 if m.cfg.residual_yaw else m.yaw_scaled(
                    m.yaw_ref(x[:, 0], us[:, 3]))

                def acc(xs, uu):
                    return float(m.derivative(xs, uu)[0, 0] * m.st_sc[0])

                rows.append({"gear": int(gear), "torque_nm": torque,
                             "vx": float(r.vx[0, -1]), "state2_s": float(x[0, 1]),
                             "accel": acc(x, us), "accel_on_prior": acc(prior, us),
                             "gain_per_10nm": acc(x, hi) - acc(x, us)})  # fmt: skip
    return rows


def replay(cell: int, seed: int = 5, chain_path: str | None = None) -> dict:
    scene = grid_scene(cell)
    cfg = ClosedLoopConfig(plant_seed=seed)
    _, (truth_run,) = run_cell(scene, ["reference"], cfg)
    s = truth_run.series
    cmds = [
        Commands(int(g), float(tq), float(d), float(st))
        for g, tq, d, st in zip(
            s["gear_cmd"], s["torque_cmd"], s["decel_cmd"], s["steer_cmd"], strict=True
        )
    ]
    chain = _run(ChainPlant(chain_path), cmds, 0)
    truth = _run(ReferencePlant(seed=seed), cmds, 0)
    v, dv = truth[:, 0], np.gradient(truth[:, 0]) * 100.0
    a = np.abs(v)
    regimes = {
        "launch/creep": (a > 0.01) & (a < BLIND) & (dv * np.sign(v) > 0),
        "stop": (a > 0.01) & (a < BLIND) & (dv * np.sign(v) <= 0),
        "hold": a <= 0.01,
        "cruise forward": v >= BLIND,
        "cruise reverse": v <= -BLIND,
        "full lock": (a >= BLIND) & (np.abs(s["steer_cmd"]) >= 300.0),
    }
    out = {"cell": cell, "scene": scene.meta.name, "samples": len(v)}
    for name, m in regimes.items():
        if not m.any():
            continue
        e_v = chain[m, 0] - v[m]
        e_w = np.degrees(chain[m, 1] - truth[m, 1])
        out[name] = {
            "share": float(m.mean()),
            "vx_bias_ms": float(e_v.mean()),
            "vx_rmse_ms": float(np.sqrt(np.mean(e_v**2))),
            "yaw_rmse_dps": float(np.sqrt(np.mean(e_w**2))),
        }
    # the replayed truth reproduces the closed-loop run: its bus vx, sample for sample
    out["replay_bus_vx_max_dev"] = float(np.max(np.abs(truth[:, 2] - s["vx"])))
    return out


def stop_errors(cell: int, seed: int = 5) -> dict:
    """Each segment's stop, chain and truth on the same plan: the rear axle's position
    at the segment's last sample against the segment's planned end pose, along the
    direction of travel (> 0: overshoot, m) and across it (m)."""
    scene = grid_scene(cell)
    plan, outs = run_cell(scene, ["chain", "reference"], ClosedLoopConfig(plant_seed=seed))
    segs = plan.trajectory.segments
    doc = {"cell": cell, "scene": scene.meta.name}
    for o in outs:
        s = o.series
        rows = []
        for i, seg in enumerate(segs):
            idx = np.flatnonzero(s["segment"] == i)
            if not len(idx):
                break
            k = idx[-1]
            ex, ey, eth = seg.poses[-1]
            dx, dy = s["x"][k] - ex, s["y"][k] - ey
            along = seg.direction * (dx * np.cos(eth) + dy * np.sin(eth))
            across = -dx * np.sin(eth) + dy * np.cos(eth)
            rows.append((float(along), float(across)))
        doc[o.plant] = {"stops": rows, "goal_cm": o.goal_error_cm}
    return doc


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cells", default="26")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--stops", default=None, help="cells whose per-stop errors to print")
    ap.add_argument("--chain", default=None, help="chain artefact (default models/chain)")
    ap.add_argument("--plant", choices=("chain", "nss"), default="chain",
                    help="step tests of the chain or of its NSS under the truth's actuators")
    ap.add_argument("--no-latch", action="store_true", help="--plant nss without the latch")
    ap.add_argument("--steps-only", action="store_true", help="skip the command replay")
    ap.add_argument("--torque", action="store_true", help="the torque trap only")
    args = ap.parse_args()
    if args.torque:
        rows = torque_trap(chain=args.chain, plant=args.plant, latch=not args.no_latch)
        if args.json:
            print(json.dumps(rows, indent=2))
            return
        print("torque trap (true vx at 7 s, m/s) at " + " / ".join(f"{t:.0f}" for t in
              TRAP_TORQUES) + " N·m: gear steer | chain | truth | chain rises with torque")
        for r in rows:
            c = " / ".join(f"{v7:+.3f}" for _, v7 in r["chain"])
            t = " / ".join(f"{v7:+.2f}" for _, v7 in r["truth"])
            print(f"{r['gear']:>3} {r['steer_deg']:>5.0f} | {c} | {t} | "
                  f"{'yes' if r['monotone'] else 'NO'}")
        print("passes" if all(r["monotone"] for r in rows) else "FAILS: the trap is there")
        print("the chain's NSS alone (steering 0) at 7 s: gear torque | vx | second state "
              "(scaled) | dvx/dt at the state | on the kinematic prior | gain per 10 N·m")
        for r in regulator(args.chain):
            print(f"{r['gear']:>3} {r['torque_nm']:>5.0f} | {r['vx']:+.3f} | "
                  f"{r['state2_s']:+.4f} | {r['accel']:+.3f} | {r['accel_on_prior']:+.3f} | "
                  f"{r['gain_per_10nm']:+.3f}")
        return
    if args.stops:
        for c in args.stops.split(","):
            d = stop_errors(int(c))
            print(f"cell {d['cell']} ({d['scene']}): stop error along/across [cm] per segment")
            for p in ("chain", "reference"):
                st = " ".join(f"{100 * a:+.1f}/{100 * b:+.1f}" for a, b in d[p]["stops"])
                print(f"  {p:<9} goal {d[p]['goal_cm']:.1f} cm | {st}")
        return
    kw = {"chain": args.chain, "plant": args.plant, "latch": not args.no_latch}
    cells = [] if args.steps_only else [int(c) for c in args.cells.split(",")]
    doc = {"steps": step_tests(**kw), "holds": rest_holds(**kw),
           "replay": [replay(c, chain_path=args.chain) for c in cells]}  # fmt: skip
    if args.json:
        print(json.dumps(doc, indent=2))
        return
    print(
        "step tests (true states): gear steer torque | vx (creep at 8 s, launch at 2 s) "
        "chain/truth | curvature chain/truth | stop s chain/truth | vx after 3 s hold"
    )
    for r in doc["steps"]:
        c, t = r["chain"], r["truth"]

        def f(v, spec=".3f"):
            return "-" if v is None else format(v, spec)

        print(
            f"{r['gear']:>3} {r['steer_deg']:>5.0f} {r['torque_nm']:>5.0f} | "
            f"{f(c['vx'])}/{f(t['vx'])} | {f(c['curvature'])}/{f(t['curvature'])} | "
            f"{f(c.get('stop_s'), '.2f')}/{f(t.get('stop_s'), '.2f')} | "
            f"{f(c.get('vx_after_hold'), '.4f')}/{f(t.get('vx_after_hold'), '.4f')}"
        )
    print("hold from rest (decel_cmd -0.8, 3 s): gear steer | max |vx| chain/truth | vx end")
    for r in doc["holds"]:
        c, t = r["chain"], r["truth"]
        print(
            f"{r['gear']:>3} {r['steer_deg']:>5.0f} | {c['max_abs_vx']:.4f}/{t['max_abs_vx']:.4f}"
            f" | {c['vx_end']:+.4f}/{t['vx_end']:+.4f}"
        )
    for r in doc["replay"]:
        print(
            f"replay cell {r['cell']} ({r['scene']}, {r['samples']} samples; replayed "
            f"truth's bus vx within {r['replay_bus_vx_max_dev']:.2g} m/s of the run):"
        )
        for k, v in r.items():
            if isinstance(v, dict):
                print(
                    f"  {k:<15} share {v['share']:.2f}  vx bias {v['vx_bias_ms']:+.3f} m/s  "
                    f"vx rmse {v['vx_rmse_ms']:.3f} m/s  yaw rmse {v['yaw_rmse_dps']:.2f} °/s"
                )


if __name__ == "__main__":
    main()
