"""Benchmark: plan the 36-cell scenario grid and the PythonRobotics comparison slots.

    python benchmarks/bench_plan.py [--repeats N] [--refine] [--json]

Plans every cell of the deterministic 36-cell grid with the default planning config and
prints the plannable count (the paper's stack: 31/36), the median and max planning time
per bay type, and the minimum dense (2 cm / 0.5°) exact clearance over all plans. Then
times, as the median of ``--repeats`` runs, a perpendicular bay (W + 0.4 m) and parallel
slots of 1.31 and 1.2 car lengths (open lane and with the barrier), next to the anchor
figures quoted in issue 6 for PythonRobotics' HybridAStar with the same vehicle
(perpendicular bay at 1 m / 15°: 1.3-2.0 s; parallel 1.31 car lengths: about 9 s;
parallel 1.2 car lengths: no plan within 90 s). Those anchors were not re-measured here.
Timings are wall-clock on this machine, one process, one thread.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time

from parknss.sim import geometry
from parknss.sim.planning.hybrid_astar import HybridAStar, load_planning_config
from parknss.sim.scenarios import BAYS, build_scene, grid_scene
from parknss.vehicle import VehicleGeometry

ANCHORS_S = {
    "perpendicular W+0.4 m": (1.3, 2.0),
    "parallel 1.31 L": (9.0, 9.0),
    "parallel 1.20 L": (90.0, math.inf),  # no plan within 90 s
}


def dense_clearance(traj, scene, geom) -> float:
    """Exact minimum clearance (m) along a trajectory checked every 2 cm / 0.5°."""
    return min(
        geometry.dense_clearance(seg.poses, geom, scene.obstacle_arrays())[0]
        for seg in traj.segments
    )


def refine_time(scene, traj, geom) -> float | None:
    """Wall time of the refinement stage, or None when it is not installed."""
    try:
        from parknss.sim.planning.refine import refine
    except ImportError:
        return None
    t0 = time.perf_counter()
    refine(scene, traj, geom)
    return time.perf_counter() - t0


def run_grid(planner: HybridAStar, geom: VehicleGeometry, with_refine: bool) -> dict:
    rows = []
    for i in range(36):
        scene = grid_scene(i)
        res = planner.plan(scene)
        row = {
            "cell": i,
            "name": scene.meta.name,
            "bay": scene.meta.bay,
            "plannable": res.found,
            "reason": res.reason,
            "plan_time_s": res.stats.time_s,
            "expansions": res.stats.expansions,
        }
        if res.found:
            row["length_m"] = res.trajectory.length
            row["cusps"] = res.trajectory.cusps
            row["min_clearance_m"] = dense_clearance(res.trajectory, scene, geom)
            if with_refine:
                row["refine_time_s"] = refine_time(scene, res.trajectory, geom)
        rows.append(row)
        print(
            f"  {i:2d} {scene.meta.name:32s} {'ok ' if res.found else 'NO '} "
            f"{res.stats.time_s:6.3f} s  {row.get('cusps', '-')!s:>3} cusps",
            file=sys.stderr,
        )
    per_bay = {}
    for bay in BAYS:
        times = [r["plan_time_s"] for r in rows if r["bay"] == bay and r["plannable"]]
        n = sum(r["bay"] == bay for r in rows)
        per_bay[bay] = {
            "plannable": f"{len(times)}/{n}",
            "median_s": statistics.median(times) if times else None,
            "max_s": max(times) if times else None,
        }
    ok = [r for r in rows if r["plannable"]]
    return {
        "plannable": len(ok),
        "cells": len(rows),
        "per_bay": per_bay,
        "median_s": statistics.median(r["plan_time_s"] for r in ok) if ok else None,
        "max_s": max((r["plan_time_s"] for r in ok), default=None),
        "min_clearance_m": min((r["min_clearance_m"] for r in ok), default=None),
        "rows": rows,
    }


def run_anchors(planner: HybridAStar, geom: VehicleGeometry, repeats: int) -> list[dict]:
    cases = [
        ("perpendicular W+0.4 m", "open", build_scene("perpendicular", "left", 2, False)),
        ("perpendicular W+0.4 m", "barrier", build_scene("perpendicular", "left", 2, True)),
    ]
    for label, factor in (("parallel 1.31 L", 1.31), ("parallel 1.20 L", 1.20)):
        for barrier in (False, True):
            scene = build_scene(
                "parallel", "left", 1, barrier, slot_override_m=factor * geom.length
            )
            cases.append((label, "barrier" if barrier else "open", scene))
    out = []
    for label, lane, scene in cases:
        times, res = [], None
        for _ in range(repeats):
            res = planner.plan(scene)
            times.append(res.stats.time_s)
        med = statistics.median(times)
        lo, hi = ANCHORS_S[label]
        out.append(
            {
                "case": label,
                "lane": lane,
                "found": res.found,
                "median_s": med,
                "cusps": res.trajectory.cusps if res.found else None,
                "min_clearance_m": dense_clearance(res.trajectory, scene, geom)
                if res.found
                else None,
                "anchor_s": [lo, hi],
                "speedup_vs_anchor": (lo / med) if res.found else None,
            }
        )
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--refine", action="store_true", help="also time the refinement")
    ap.add_argument("--json", action="store_true", help="print one JSON document")
    args = ap.parse_args(argv)
    geom = VehicleGeometry()
    planner = HybridAStar(load_planning_config(), geom)
    print("planning the 36-cell grid ...", file=sys.stderr)
    grid = run_grid(planner, geom, args.refine)
    print("timing the comparison slots ...", file=sys.stderr)
    anchors = run_anchors(planner, geom, args.repeats)
    if args.json:
        print(json.dumps({"grid": grid, "anchors": anchors}, indent=2))
        return 0
    print(f"36-cell grid: plannable {grid['plannable']}/{grid['cells']} (paper: 31/36)")
    print(f"{'bay':<14} {'plannable':>9} {'median s':>9} {'max s':>8}")
    for bay, v in grid["per_bay"].items():
        print(f"{bay:<14} {v['plannable']:>9} {v['median_s']:>9.3f} {v['max_s']:>8.3f}")
    print(
        f"all plannable: median {grid['median_s']:.3f} s, max {grid['max_s']:.3f} s; "
        f"minimum dense clearance {grid['min_clearance_m']:.4f} m"
    )
    print()
    print(f"comparison (median of {args.repeats}; anchors: PythonRobotics, quoted in issue 6)")
    print(f"{'case':<22} {'lane':<8} {'found':>5} {'median s':>9} {'cusps':>5} {'anchor s':>10}")
    for a in anchors:
        lo, hi = a["anchor_s"]
        anchor = f"{lo:g}-{hi:g}" if lo != hi else f"{lo:g}"
        if math.isinf(hi):
            anchor = f">{lo:g} (none)"
        print(
            f"{a['case']:<22} {a['lane']:<8} {'yes' if a['found'] else 'no':>5} "
            f"{a['median_s']:>9.3f} {a['cusps'] if a['cusps'] is not None else '-':>5} "
            f"{anchor:>10}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
