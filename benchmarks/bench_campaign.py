"""Benchmark: generate the synthetic campaign and print the figures issue 2 asks for.

    python benchmarks/bench_campaign.py [--seed N] [--vehicle YAML]
        [--conditions none|typical|harsh] [--repeat N] [--json]

Times generate_campaign (16 trials), then reports per trial the class, length, direction
changes, blind-zone fraction and max |vx|; and for the campaign the R² of the
kinematic-bicycle yaw rate (constant ratio, logged vx and steer, moving region) against
the logged yaw rate, the least-squares steering ratio, the total direction changes and
whether every reversal happened at standstill. Independent of parknss.data.describe.
``--conditions`` draws per-trial conditions of that profile (default: the YAML's);
``--repeat N`` times the generation N times and reports the fastest and the median.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import minimize_scalar

from parknss.reference.campaign import generate_campaign
from parknss.signals import BLIND_ZONE_MS, moving_mask, ms_to_kmh
from parknss.vehicle import VehicleGeometry, yaw_rate_ref


def direction_changes(gear: np.ndarray) -> int:
    """Reverse <-> drive changes (neutral/park samples skipped)."""
    nz = gear[gear != 0]
    return int(np.sum(nz[1:] != nz[:-1]))


def reversals_at_standstill(tr) -> bool:
    """Every gear change with the car truly at rest and the wheel speed in the blind zone."""
    ks = np.flatnonzero(np.diff(tr["gear"]) != 0) + 1
    v, log = tr["truth_vx"], tr["vx"]
    return bool(
        np.all(v[ks - 1] == 0.0)
        and np.all(v[ks] == 0.0)
        and np.all(np.abs(log[ks]) < BLIND_ZONE_MS)
    )


def yaw_checks(campaign, geom: VehicleGeometry) -> tuple[float, float]:
    """(R² of the kinematic yaw rate, least-squares steering ratio) on the moving region."""
    w, v, s = [], [], []
    for tr in campaign:
        m = moving_mask(tr["vx"])
        w.append(tr["yaw_rate"][m])
        v.append(tr["vx"][m])
        s.append(tr["steer"][m])
    w, v, s = np.concatenate(w), np.concatenate(v), np.concatenate(s)
    ref = yaw_rate_ref(v, s, geom)
    r2 = 1.0 - np.sum((w - ref) ** 2) / np.sum((w - w.mean()) ** 2)
    fit = minimize_scalar(
        lambda i: np.sum((w - v / geom.wheelbase * np.tan(np.radians(s / i))) ** 2),
        bounds=(5.0, 30.0),
        method="bounded",
    )
    return float(r2), float(fit.x)


def run(seed: int, vehicle: Path | None, conditions: str | None = None, repeat: int = 1) -> dict:
    times = []
    for _ in range(max(repeat, 1)):
        t0 = time.perf_counter()
        campaign = generate_campaign(seed=seed, vehicle_yaml=vehicle, conditions=conditions)
        times.append(time.perf_counter() - t0)
    elapsed = min(times)
    geom = VehicleGeometry.from_dict(campaign.meta["vehicle_geometry"])
    r2, ratio = yaw_checks(campaign, geom)
    trials = [
        {
            "id": tr.id,
            "class": tr.maneuver,
            "length_s": round(tr.duration_s, 2),
            "direction_changes": direction_changes(tr["gear"]),
            "blind_zone_fraction": round(float(1.0 - moving_mask(tr["vx"]).mean()), 3),
            "max_speed_kmh": round(float(ms_to_kmh(np.abs(tr["vx"]).max())), 2),
            "reversals_at_standstill": reversals_at_standstill(tr),
        }
        for tr in campaign
    ]
    return {
        "seed": seed,
        "vehicle": str(vehicle) if vehicle else "defaults",
        "conditions": campaign.meta.get("conditions_profile", "none"),
        "generation_s": round(elapsed, 2),
        "generation_median_s": round(float(np.median(times)), 2),
        "repeats": len(times),
        "trials": trials,
        "yaw_r2": round(r2, 4),
        "steer_ratio_fit": round(ratio, 3),
        "nominal_steer_ratio": geom.steer_ratio,
        "direction_changes": sum(t["direction_changes"] for t in trials),
        "all_reversals_at_standstill": all(t["reversals_at_standstill"] for t in trials),
        "blind_zone_fraction": round(float(np.mean([t["blind_zone_fraction"] for t in trials])), 3),
    }


def print_table(res: dict) -> None:
    print(
        f"vehicle {res['vehicle']}, seed {res['seed']}, conditions {res['conditions']}: "
        f"generated in {res['generation_s']} s (median {res['generation_median_s']} s "
        f"of {res['repeats']})"
    )
    print(f"{'trial':20s} {'length s':>8s} {'dir.ch.':>7s} {'blind':>6s} {'max km/h':>8s}")
    for t in res["trials"]:
        print(
            f"{t['id']:20s} {t['length_s']:8.1f} {t['direction_changes']:7d} "
            f"{t['blind_zone_fraction']:6.2f} {t['max_speed_kmh']:8.2f}"
        )
    print(
        f"yaw R2 {res['yaw_r2']:.4f} | steering-ratio fit {res['steer_ratio_fit']:.3f} "
        f"(nominal {res['nominal_steer_ratio']}) | direction changes {res['direction_changes']} "
        f"| all at standstill {res['all_reversals_at_standstill']} "
        f"| mean blind-zone fraction {res['blind_zone_fraction']:.3f}"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--vehicle", type=Path, default=None, help="reference-vehicle YAML")
    ap.add_argument(
        "--conditions",
        choices=("none", "typical", "harsh"),
        default=None,
        help="per-trial conditions profile (default: the vehicle YAML's)",
    )
    ap.add_argument("--repeat", type=int, default=1, help="time the generation N times")
    ap.add_argument("--json", action="store_true", help="print one JSON document")
    args = ap.parse_args(argv)
    res = run(args.seed, args.vehicle, args.conditions, args.repeat)
    if args.json:
        print(json.dumps(res, indent=2))
    else:
        print_table(res)
    return 0


if __name__ == "__main__":
    sys.exit(main())
