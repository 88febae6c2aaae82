"""Benchmark: the 20 TPCAP parking cases, planned and driven in closed loop.

    python benchmarks/bench_tpcap.py [--vehicle configs/tpcap_vehicle.yaml] [--cases 1-20]
        [--plants kinematic] [--expansions N] [--budget S] [--out FILE.json] [--json]
        [--settings "margin 0.10"] [--moved]

Reads the cases in place from ../shared/planning/tpcap (never copied into the
repository; ``--tpcap`` elsewhere) with :func:`parknss.sim.scene_formats.read_tpcap`
(obstacles as drawn: non-convex ones split into convex parts, walls drawn as lines,
far-away cases shifted to a local frame) and, per case and setting, reports: plannable,
search time, refinement time and outcome, path length, cusps, the exact dense clearance,
and the closed-loop completion and goal error under each plant (default: the kinematic
plant). Two settings:

* ``margin 0.10``: the paper's safety margin (0.10 m) with the closed-loop steering
  reserve (configs/closed_loop.yaml, 10 % of the lock): the plan every run drives;
* ``TPCAP-style``: no margin and the full lock, as the competition scores paths.

``--vehicle`` (default: the TPCAP car, configs/tpcap_vehicle.yaml; ``--vehicle default``:
parknss's default car, to show the geometry flows) is the car planned and driven.
``--expansions`` overrides the search budget (planning.yaml ``max_expansions``: 1200 node
expansions, the same on any machine), ``--budget`` the wall-clock guard (``time_budget_s``:
60 s). Timings are wall-clock, one process, one thread (run with OMP_NUM_THREADS=1).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
from pathlib import Path

from parknss.config import CONFIG_DIR, override
from parknss.sim.closed_loop import load_closed_loop_config
from parknss.sim.planner import plan_scene
from parknss.sim.planning.frame import move_scene
from parknss.sim.planning.hybrid_astar import PlanningConfig, load_planning_config
from parknss.sim.scene_formats import read_tpcap
from parknss.sim.session import run_cell
from parknss.vehicle import VehicleGeometry, load_vehicle_geometry

ROOT = Path(__file__).resolve().parents[1]
TPCAP = ROOT.parent / "shared" / "planning" / "tpcap"
SETTINGS = {
    "margin 0.10": {"plan_margin_m": 0.10},
    "TPCAP-style": {"plan_margin_m": 0.0, "steer_reserve": 0.0},
}


def _cases(spec: str) -> list[int]:
    out: list[int] = []
    for part in spec.split(","):
        lo, _, hi = part.partition("-")
        out.extend(range(int(lo), int(hi or lo) + 1))
    return out


MOVE = (math.radians(37.0), (123.4, -56.7), True)
"""``--moved``: mirror in y, rotate by 37 degrees, shift by (+123.4, -56.7) m."""


def run_case(path: Path, geom: VehicleGeometry, setting: dict, plants: list[str],
             planning: PlanningConfig, moved: bool = False):
    """One case under one setting: the plan summary and each plant's outcome."""
    scene = read_tpcap(path)
    if moved:
        angle, shift, mirror = MOVE
        scene = move_scene(scene, angle, shift, mirror)
    loop = override(load_closed_loop_config(), setting, source="bench setting")
    plan = plan_scene(scene, loop, planning, geom)
    row = plan.to_json(scene)
    row.pop("trajectory")
    row["length_full_m"] = None if plan.trajectory is None else plan.trajectory.length
    row["case"] = int(path.stem.lower().removeprefix("case"))
    row["runs"] = {}
    if plan.trajectory is not None and plants:
        _, outcomes = run_cell(scene, plants, loop, None, planning, geom, plan.trajectory)
        for o in outcomes:
            row["runs"][o.plant] = {
                "completed": o.completed,
                "reason": o.reason,
                "goal_error_cm": o.goal_error_cm,
                "clearance_cm": o.clearance_cm,
            }
    return row


def _f(v, spec: str) -> str:
    return "-" if v is None else format(v, spec)


def table(name: str, rows: list[dict], plants: list[str]) -> str:
    """A fixed-width table of one setting and its summary lines."""
    head = (
        f"{'case':>4} {'plan':>4} {'search s':>8} {'refine s':>8} {'refined':>7} "
        f"{'len m':>6} {'cusps':>5} {'clr m':>6} "
        + " ".join(f"{p[:5]:>5} {'goal cm':>7}" for p in plants)
        + "  note"
    )
    lines = [f"== {name}", head, "-" * len(head)]
    for r in rows:
        runs = " ".join(
            f"{('yes' if r['runs'][p]['completed'] else r['runs'][p]['reason'][:5]):>5} "
            f"{_f(r['runs'][p]['goal_error_cm'], '7.2f'):>7}"
            if p in r["runs"]
            else f"{'-':>5} {'-':>7}"
            for p in plants
        )
        note = r["reason"] if not r["plannable"] else (r["refine_reason"] or "")
        lines.append(
            f"{r['case']:>4} {'yes' if r['plannable'] else 'no':>4} {r['search_time_s']:>8.2f} "
            f"{r['refine_time_s']:>8.2f} {'yes' if r['refined'] else 'no':>7} "
            f"{_f(r['length_m'], '6.1f'):>6} {_f(r['cusps'], '5d'):>5} "
            f"{_f(r['min_clearance_m'], '6.3f'):>6} {runs}  {note[:60]}"
        )
    lines.append("-" * len(head))
    lines.append(summary_line(rows, plants))
    return "\n".join(lines)


def summarize(rows: list[dict], plants: list[str]) -> dict:
    ok = [r for r in rows if r["plannable"]]
    times = [r["plan_time_s"] for r in ok]
    out = {
        "cases": len(rows),
        "plannable": len(ok),
        "refined": sum(r["refined"] for r in ok),
        "plan_time_median_s": statistics.median(times) if times else None,
        "plan_time_max_s": max(times) if times else None,
    }
    for p in plants:
        runs = [r["runs"][p] for r in ok if p in r["runs"]]
        done = [x for x in runs if x["completed"]]
        out[f"{p}_completed"] = len(done)
        out[f"{p}_goal_max_cm"] = max((x["goal_error_cm"] for x in done), default=None)
    return out


def summary_line(rows: list[dict], plants: list[str]) -> str:
    s = summarize(rows, plants)
    text = (
        f"plannable {s['plannable']}/{s['cases']}, refined {s['refined']}, plan time median "
        f"{_f(s['plan_time_median_s'], '.2f')} s max {_f(s['plan_time_max_s'], '.2f')} s"
    )
    for p in plants:
        text += (
            f"; {p} parked {s[f'{p}_completed']}/{s['plannable']} "
            f"(goal max {_f(s[f'{p}_goal_max_cm'], '.2f')} cm)"
        )
    return text


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tpcap", type=Path, default=TPCAP)
    ap.add_argument("--vehicle", default=str(CONFIG_DIR / "tpcap_vehicle.yaml"))
    ap.add_argument("--cases", default="1-20")
    ap.add_argument("--plants", default="kinematic")
    ap.add_argument("--settings", default=",".join(SETTINGS))
    ap.add_argument("--expansions", type=int, default=None)
    ap.add_argument("--budget", type=float, default=None)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--moved", action="store_true",
                    help="move every case rigidly first (mirror in y, rotate 37 deg, shift "
                    "(+123.4, -56.7) m): the table must not change")
    a = ap.parse_args(argv)
    if not a.tpcap.is_dir():
        print(f"{a.tpcap}: TPCAP cases not found", file=sys.stderr)
        return 2
    geom = VehicleGeometry() if a.vehicle == "default" else load_vehicle_geometry(a.vehicle)
    plants = [p for p in a.plants.split(",") if p]
    budgets = {"max_expansions": a.expansions, "time_budget_s": a.budget}
    planning = override(load_planning_config(),
                        {k: v for k, v in budgets.items() if v is not None}, source="options")
    doc: dict = {"vehicle": geom.to_dict(), "settings": {}}
    for name in a.settings.split(","):
        rows = []
        for c in _cases(a.cases):
            rows.append(run_case(a.tpcap / f"Case{c}.csv", geom, SETTINGS[name], plants, planning,
                                 a.moved))
            print(f"[{name}] case {c}: {rows[-1]['reason']}", file=sys.stderr, flush=True)
        doc["settings"][name] = {"rows": rows, "summary": summarize(rows, plants)}
        if not a.json:
            print(table(name, rows, plants), flush=True)
    if a.out is not None:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(json.dumps(doc, indent=1))
    if a.json:
        print(json.dumps(doc, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
