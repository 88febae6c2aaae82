"""Benchmark: one NSS sweep in-process, on the local pool and on a local Ray; same numbers?

    python benchmarks/bench_executors.py [--seeds N] [--epochs E] [--workers W] [--json]

Runs the seed-noise study's fold jobs (the ``quick`` budget's tiny net of
configs/experiments.yaml, ``--epochs`` epochs, seeds 0..N-1) three times without a cache:
in-process (workers = 1), on the loky pool and on a freshly started local Ray with
``--workers`` CPUs. Prints the wall time of each, Ray's overhead over the local pool, and
whether all three returned bit-identical fold errors.
"""

from __future__ import annotations

import argparse
import json
import os
import time

from parknss.executor import run_jobs
from parknss.experiments.config import load_experiments_config, merge_overrides
from parknss.experiments.sweep import Sweep, fold_spec


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--epochs", type=int, default=4)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    cfg = load_experiments_config()
    ov = cfg.quick.overrides
    sweep = Sweep(progress=False)
    jobs = [
        fold_spec(sweep, "cv", 1, merge_overrides(ov, {"train": {"epochs": a.epochs, "seed": s}}))
        for s in range(a.seeds)
    ]
    runs = {}
    for label, kw in (
        ("in-process", {"workers": 1}),
        ("local pool", {"workers": a.workers}),
        ("ray", {"workers": a.workers, "executor": "ray"}),
    ):
        t0 = time.perf_counter()
        res = run_jobs(jobs, progress=False, **kw)
        runs[label] = (time.perf_counter() - t0, [(r["errors"], r["truth_errors"]) for r in res])
    base = runs["in-process"][1]
    doc = {
        "jobs": len(jobs),
        "epochs": a.epochs,
        "workers": a.workers,
        "wall_s": {k: round(v[0], 2) for k, v in runs.items()},
        "identical": {k: v[1] == base for k, v in runs.items()},
        "ray_overhead_s": round(runs["ray"][0] - runs["local pool"][0], 2),
        "vx_mse_moving_kmh2": [e["vx_mse_moving_kmh2"] for e, _ in base],
    }
    if a.json:
        print(json.dumps(doc, indent=2))
        return
    for k, (w, _) in runs.items():
        print(f"{k:<12} {w:7.2f} s  identical to in-process: {doc['identical'][k]}")
    print(f"ray overhead over the local pool: {doc['ray_overhead_s']:+.2f} s for {len(jobs)} jobs")
    print("vx MSE per seed:", ", ".join(f"{v:.4f}" for v in doc["vx_mse_moving_kmh2"]))


if __name__ == "__main__":
    main()
