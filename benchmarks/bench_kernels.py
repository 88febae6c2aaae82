"""Accuracy of the fused engine's ``fast`` and ``native`` kernels against ``reference``, float64.

    python benchmarks/bench_kernels.py [--epochs 40] [--fold 0] [--seed 0] [--skip-fits]

1. Gradients at paper size (29 windows of 2121 samples of the default synthetic campaign,
   the default config's initial weights): one epoch's loss gradient in float64 (reference
   kernels) and in float32 with each kernel set; prints, per kernel set, the largest
   relative error max|g32 - g64| / max|g64| over the parameter tensors and the loss's
   relative error.
2. A short paper-recipe fit of CV fold ``--fold`` (seed ``--seed``, ``--epochs`` epochs,
   checkpoint on the fold's held-out trials as in the study) with each kernel set, one
   after the other: the held-out open-loop errors (moving-region MSE of vx, yaw rate, ax,
   ay against the logged channels), the best epoch and the fit's CPU seconds.

One torch thread. The machine's load shifts CPU seconds little and wall seconds a lot:
compare kernels by the CPU seconds of the same run.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).parent))
from bench_train import load_campaign, paper_batch

from parknss.nss.config import NSSConfig, with_overrides
from parknss.nss.fused import KERNELS
from parknss.nss.step import epoch_loss
from parknss.nss.train import build_model, geometry_of

CHANNELS = ("vx_mse_moving_kmh2", "yaw_mse_moving_degs2", "ax_mse_moving_ms2",
            "ay_mse_moving_ms2")


def gradients(cfg: NSSConfig, norm, geom, batch) -> tuple[float, dict[str, torch.Tensor]]:
    model = build_model(cfg, norm, geom)
    terms = epoch_loss(model, batch, cfg)
    terms.total.backward()
    return float(terms.total.detach()), {n: p.grad.double() for n, p in model.named_parameters()}


def gradient_errors(cfg: NSSConfig) -> None:
    campaign = load_campaign(None)
    norm, batch = paper_batch(cfg, campaign, 29, 2121)
    geom = geometry_of(campaign)
    loss64, g64 = gradients(with_overrides(cfg, train={"dtype": "float64"}), norm, geom, batch)
    print(f"gradients at paper size ({batch.n} windows x {batch.steps} steps), float32 "
          f"against float64 (reference kernels, loss {loss64:.10f}):")
    for k in KERNELS:
        loss, g = gradients(with_overrides(cfg, model={"fused_kernels": k}), norm, geom, batch)
        rel = {n: float((g[n] - g64[n]).abs().max() / g64[n].abs().max()) for n in g64}
        worst = max(rel, key=rel.get)
        print(f"  {k:>9}: loss rel. error {abs(loss - loss64) / abs(loss64):.1e}; gradients "
              f"max rel. error {rel[worst]:.1e} ({worst}), median over tensors "
              f"{sorted(rel.values())[len(rel) // 2]:.1e}")


def short_fits(epochs: int, fold: int, seed: int) -> None:
    from parknss.experiments.folds import fold_job

    print(f"paper-recipe fit of CV fold {fold}, seed {seed}, {epochs} epochs, held-out "
          f"moving-region MSE ({', '.join(CHANNELS)}):")
    for k in KERNELS:
        doc = fold_job("cv", fold, overrides={"train": {"epochs": epochs, "seed": seed},
                                              "model": {"fused_kernels": k}})
        e = doc["errors"]
        errs = "  ".join(f"{e[c]:.5g}" for c in CHANNELS)
        print(f"  {k:>9}: {errs}   best epoch {doc['best_epoch']}, "
              f"CPU {doc['cpu_s']:.1f} s, wall {doc['wall_s']:.1f} s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--epochs", type=int, default=40)
    ap.add_argument("--fold", type=int, default=0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--skip-fits", action="store_true")
    a = ap.parse_args()
    torch.set_num_threads(1)
    gradient_errors(NSSConfig())
    if not a.skip_fits:
        short_fits(a.epochs, a.fold, a.seed)


if __name__ == "__main__":
    main()
