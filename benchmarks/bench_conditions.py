"""Benchmark: how a model generalises to fresh campaigns under each conditions profile.

    python benchmarks/bench_conditions.py [--model DIR] [--seeds 7,8,9]
        [--profiles none,typical,harsh] [--cars reference,alt] [--json]

For every car (the reference car of ``configs/reference_vehicle.yaml`` and the other car of
``configs/reference_vehicle_alt.yaml``), profile and seed it generates a fresh 16-trial
campaign (``generate_campaign``, the same call as ``parknss campaign generate``), rolls the
NSS (default: the shipped one) out from the logged actuals and prints the moving-region
MSE of vx [(km/h)²] and ω_z [(°/s)²] against the logged channels, per seed and mean, and
for the first seed also against the noise-free truth: the table of issue 14
(docs/reference.md, "Per-trial conditions").
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

from parknss.config import CONFIG_DIR, SHIPPED_NSS
from parknss.metrics.errors import logged_and_truth_errors
from parknss.nss.checkpoint import load_model
from parknss.nss.predict import predict_trials
from parknss.reference.campaign import generate_campaign

CARS = {
    "reference": CONFIG_DIR / "reference_vehicle.yaml",
    "alt": CONFIG_DIR / "reference_vehicle_alt.yaml",
}
PAPER = {"vx": (0.108, 0.038), "yaw": (0.344, 0.170)}


def measure(model, car: str, profile: str, seed: int) -> dict:
    """Moving-region vx/ω_z MSE vs logged and vs truth on one fresh campaign."""
    t0 = time.perf_counter()
    campaign = generate_campaign(seed=seed, vehicle_yaml=CARS[car], conditions=profile)
    t_gen = time.perf_counter() - t0
    trials = list(campaign)
    logged, truth = logged_and_truth_errors(predict_trials(model, trials), trials, None)
    return {
        "car": car, "profile": profile, "seed": seed, "generate_s": round(t_gen, 2),
        "vx": logged["vx_mse_moving_kmh2"], "yaw": logged["yaw_mse_moving_degs2"],
        "vx_truth": truth["vx_mse_moving_kmh2"], "yaw_truth": truth["yaw_mse_moving_degs2"],
    }


def table(rows: list[dict]) -> str:
    """One line per (car, profile): per-seed values, their mean, the first seed vs truth."""
    out = ["| car | profile | vx moving (km/h)², per seed | mean | ω_z moving (°/s)², per seed"
           " | mean | first seed vs truth (vx / ω_z) |", "| --- " * 7 + "|"]
    keys = dict.fromkeys((r["car"], r["profile"]) for r in rows)
    for car, prof in keys:
        rs = [r for r in rows if r["car"] == car and r["profile"] == prof]
        vx = " / ".join(f"{r['vx']:.4g}" for r in rs)
        yw = " / ".join(f"{r['yaw']:.4g}" for r in rs)
        out.append(
            f"| {car} | {prof} | {vx} | {np.mean([r['vx'] for r in rs]):.4g} | {yw} | "
            f"{np.mean([r['yaw'] for r in rs]):.4g} | "
            f"{rs[0]['vx_truth']:.4g} / {rs[0]['yaw_truth']:.4g} |"
        )
    out.append(f"| paper, held-out trials of its real car (Table II) | | "
               f"{PAPER['vx'][0]} ± {PAPER['vx'][1]} | | "
               f"{PAPER['yaw'][0]} ± {PAPER['yaw'][1]} | | |")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", type=Path, default=SHIPPED_NSS)
    ap.add_argument("--seeds", default="7,8,9")
    ap.add_argument("--profiles", default="none,typical,harsh")
    ap.add_argument("--cars", default="reference,alt")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    torch.set_num_threads(1)
    model = load_model(a.model).model
    rows = [
        measure(model, car, prof, int(seed))
        for car in a.cars.split(",")
        for prof in a.profiles.split(",")
        for seed in a.seeds.split(",")
    ]
    if a.json:
        print(json.dumps({"model": str(a.model), "rows": rows}, indent=1))
    else:
        print(f"model {a.model}")
        print(table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
