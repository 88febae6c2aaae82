"""Benchmark: what an epoch of the coarse-to-fine recipe's phase 1 costs against a paper epoch.

    python benchmarks/bench_coarse.py [--data DIR] [--fold 1] [--factors 1,4,8,16]
                                      [--epochs 5] [--repeats 3] [--kernels reference]

On one fold of the stratified CV split of the campaign (default: the bundled synthetic
campaign), the paper-size NSS with the shipped config's weights and one torch thread:
for each factor m, the batch ``train.recipe: coarse`` trains on in phase 1 (the paper's
windows of the training trials decimated by m, rolled out with an Euler step of m·dt;
m = 1 is the paper's own full batch), timed as full training steps (forward, backward,
Adam) in process CPU time, the factors interleaved, ``--epochs`` epochs per factor per
repeat; the median per factor and its ratio to m = 1, all measured in this run. Also the
CPU time of one held-out validation at the full rate (whole trials, open loop: what every
validation costs whatever the factor) and the load average before and after.
``--kernels`` picks the fused engine's kernels (``model.fused_kernels``; default the
shipped config's).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import torch

from parknss.data.io import read_campaign
from parknss.data.normalize import Normalizer
from parknss.data.windows import whole_trials, window_length
from parknss.experiments.folds import make_fold
from parknss.nss.batch import make_batch
from parknss.nss.config import load_nss_config, with_overrides
from parknss.nss.fused import KERNELS
from parknss.nss.model import NORMALIZED
from parknss.nss.recipes import make_recipe
from parknss.nss.step import local_step
from parknss.nss.train import build_model, geometry_of, validation_losses

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(ROOT / "campaigns" / "default"))
    ap.add_argument("--fold", type=int, default=1)
    ap.add_argument("--factors", default="1,4,8,16")
    ap.add_argument("--epochs", type=int, default=5)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--kernels", choices=KERNELS, default=None)
    args = ap.parse_args()
    torch.set_num_threads(1)
    factors = [int(f) for f in args.factors.split(",")]
    camp = read_campaign(args.data)
    fold = make_fold(camp, "cv", args.fold)  # the fold job's own split
    train, val = [camp[i] for i in fold.train], [camp[i] for i in fold.val]
    base = load_nss_config()
    if args.kernels:
        base = with_overrides(base, model={"fused_kernels": args.kernels})
    norm = Normalizer.fit(train, NORMALIZED, base.data.normalizer, base.data.clip_percentiles)
    model = build_model(base, norm, geometry_of(camp))
    L = window_length([t.n for t in train], base.data.window)
    batches = {}
    for m in factors:
        cfg = with_overrides(base, train={"recipe": "coarse"}, coarse={"factor": m})
        r = make_recipe(cfg, model, train, L)
        batches[m] = r.full if m == 1 else r.coarse
    opt = torch.optim.Adam(model.parameters(), lr=1e-4)
    print(f"campaign {args.data}, fold {args.fold}: {len(train)} training trials, "
          f"{base.model.fused_kernels} kernels; "
          f"load before {os.getloadavg()[0]:.2f}")
    for m, b in batches.items():
        print(f"  factor {m:>2}: {b.n} windows x {b.steps} steps of {m * base.model.dt:.2f} s")
    per: dict[int, list[float]] = {m: [] for m in factors}
    for _ in range(args.repeats):
        for m in factors:
            for _ in range(args.epochs):
                c0 = time.process_time()
                opt.zero_grad(set_to_none=True)
                local_step(model, batches[m], base, 1)
                opt.step()
                per[m].append(time.process_time() - c0)
    ref = statistics.median(per[factors[0]])
    for m in factors:
        med = statistics.median(per[m])
        print(f"factor {m:>2}: median {med:.3f} CPU s/epoch over {len(per[m])} epochs; "
              f"factor {factors[0]} / factor {m}: {ref / med:.1f}x")
    vb = make_batch(model, whole_trials(val), base.loss.blind_zone_kmh)
    vals = []
    for _ in range(args.repeats):
        c0 = time.process_time()
        validation_losses(model, vb, base)
        vals.append(time.process_time() - c0)
    print(f"held-out validation at the full rate ({vb.n} trials, {vb.steps} steps): "
          f"median {statistics.median(vals):.3f} CPU s")
    print(f"load after {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
