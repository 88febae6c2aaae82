"""Real-time step latency of the deployed chain (one vehicle, one 10 ms sample per call).

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_chain.py [CHAIN] [--steps N] [--json]

Replays a logged command stream of the default campaign through ``DeployedChain.step``
(the Plant interface the simulator uses) and reports the median, 10th and 90th
percentile of the per-step wall time in µs and the real-time factor 10 ms / median.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from parknss.config import SHIPPED_CHAIN
from parknss.plant import Commands


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("chain", nargs="?", default=str(SHIPPED_CHAIN))
    ap.add_argument("--steps", type=int, default=5000)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    import torch

    from parknss.chain import load_chain
    from parknss.nss.campaigns import default_campaign

    torch.set_num_threads(1)
    dep = load_chain(a.chain)
    tr = max(default_campaign(), key=lambda t: t.n)
    cm = tr.array(("gear", "torque_cmd", "decel_cmd", "steer_cmd"))
    cmds = [Commands(int(r[0]), float(r[1]), float(r[2]), float(r[3])) for r in cm]
    dep.reset()
    for c in cmds[:200]:  # warm-up
        dep.step(c)
    dep.reset()
    ts = np.empty(a.steps)
    for k in range(a.steps):
        c = cmds[k % len(cmds)]
        t0 = time.perf_counter()
        dep.step(c)
        ts[k] = time.perf_counter() - t0
    us = ts * 1e6
    doc = {"chain": a.chain, "steps": a.steps, "median_us": float(np.median(us)),
           "p10_us": float(np.percentile(us, 10)), "p90_us": float(np.percentile(us, 90)),
           "real_time_factor": float(dep.dt * 1e6 / np.median(us)),
           "specs": dep.chain.specs()}
    if a.json:
        print(json.dumps(doc, indent=2))
    else:
        print(f"{doc['median_us']:.1f} µs/step median (p10 {doc['p10_us']:.1f}, "
              f"p90 {doc['p90_us']:.1f}); real-time factor {doc['real_time_factor']:.0f}x; "
              f"{doc['specs']}")


if __name__ == "__main__":
    main()
