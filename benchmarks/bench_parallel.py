"""Benchmark: a paper-size NSS fit on one process against the same fit data-parallel.

    python benchmarks/bench_parallel.py [--data DIR] [--fold 1] [--processes 2]
                                        [--epochs 10] [--updates 40] [--finish 5]
                                        [--repeats 2]

The fit of ``parknss.nss.train.fit`` on one fold of the stratified CV split of the
campaign (default: the bundled synthetic campaign, campaigns/default), paper-size net,
run with ``train.processes`` 1 and P (nss/parallel.py), interleaved fit by fit, each
``--repeats`` times, in the same run:

* paper: ``--epochs`` full-batch epochs of the paper recipe (validation every 5),
* fast: the fast recipe shortened to ``--updates`` minibatch updates (8 windows of 1024
  samples, validation every 20) and ``--finish`` full-window epochs.

Prints, per segment (paper epochs, fast phase-1 updates, fast phase-2 epochs), the
median wall seconds per step of each (the first step of a fit left out: it waits for
the workers to start) and the ratio 1-process / P-process; the whole fits' wall time
(worker start-up included) and CPU time (the fit's ``cpu_s``: its process and its
workers'); and the largest relative difference of the training loss between the two at
any step (the same objective rounded differently: it grows as the fits drift apart, as
two fits rounded differently do). The load average before and after is printed (a busy
second core takes the speed-up away).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import torch

from parknss.data.io import read_campaign
from parknss.data.splits import stratified_folds
from parknss.nss.config import load_nss_config, with_overrides
from parknss.nss.train import fit, geometry_of

ROOT = Path(__file__).resolve().parents[1]


def timed_fit(train, val, cfg, geometry) -> tuple[list[float], object, float]:
    """(wall seconds of each step, the fit, its wall time)."""
    stamps: list[float] = []
    t0 = time.perf_counter()
    res = fit(train, val, cfg, geometry, progress=False,
              on_epoch=lambda e: stamps.append(time.perf_counter()))
    wall = time.perf_counter() - t0
    steps = [b - a for a, b in zip([t0, *stamps[:-1]], stamps, strict=True)]
    return steps, res, wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(ROOT / "campaigns" / "default"))
    ap.add_argument("--fold", type=int, default=1)
    ap.add_argument("--processes", type=int, default=2)
    ap.add_argument("--epochs", type=int, default=10)
    ap.add_argument("--updates", type=int, default=40)
    ap.add_argument("--finish", type=int, default=5)
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()
    torch.set_num_threads(1)
    camp = read_campaign(args.data)
    fold = stratified_folds(camp)[args.fold]
    by_id = {t.id: t for t in camp}
    train = [by_id[i] for i in fold.train]
    val = [by_id[i] for i in fold.val]
    base = load_nss_config()
    recipes = {
        "paper": {"train": {"epochs": args.epochs}},
        "fast": {"train": {"recipe": "fast"},
                 "fast": {"updates": args.updates, "finish_epochs": args.finish}},
    }
    print(f"campaign {args.data}, fold {args.fold}: {len(train)} training trials, "
          f"{len(val)} held out; load before {os.getloadavg()[0]:.2f}")
    for name, over in recipes.items():
        seg_of = (lambda k: "paper") if name == "paper" else (
            lambda k: "phase 1" if k <= args.updates else "phase 2")
        per: dict[tuple[int, str], list[float]] = {}
        totals: dict[int, list[tuple[float, float]]] = {1: [], args.processes: []}
        losses: dict[int, list[float]] = {}
        for _ in range(args.repeats):
            for p in (1, args.processes):
                train_over = {**over.get("train", {}), "processes": p}
                cfg = with_overrides(base, **{**over, "train": train_over})
                steps, res, wall = timed_fit(train, val, cfg, geometry_of(camp))
                for k, s in enumerate(steps[1:], start=2):
                    per.setdefault((p, seg_of(k)), []).append(s)
                totals[p].append((wall, res.cpu_s or 0.0))
                losses[p] = [r["train_total"] for r in res.history.rows]
        print(f"\n== {name} recipe: {len(losses[1])} steps, {args.repeats} fits each")
        for seg in dict.fromkeys(seg_of(k) for k in range(2, len(losses[1]) + 1)):
            one = statistics.median(per[(1, seg)])
            many = statistics.median(per[(args.processes, seg)])
            print(f"{seg:>8}: 1 process {one:.3f} s/step, {args.processes} processes "
                  f"{many:.3f} s/step: {one / many:.2f}x")
        for p, rows in totals.items():
            walls = ", ".join(f"{w:.1f}" for w, _ in rows)
            cpus = ", ".join(f"{c:.1f}" for _, c in rows)
            print(f"  processes {p}: fit wall {walls} s, CPU {cpus} s")
        dev = max(abs(a - b) / abs(a) for a, b in zip(losses[1], losses[args.processes],
                                                      strict=True))
        print(f"  largest relative difference of the training loss: {dev:.2e}")
    print(f"\nload after {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
