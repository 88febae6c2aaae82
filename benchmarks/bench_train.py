"""Benchmark: one NSS training epoch at paper size, plain eager loop vs the fused engines.

    python benchmarks/bench_train.py [--data DIR] [--windows 29] [--length 2121]
                                     [--repeats 3] [--threads 1]

Paper size (§IV-B): 29 end-aligned windows of 2121 samples of the campaign (default: the
synthetic default campaign, generated in memory), state net 6x128, output net 3x128,
tanh, forward Euler, the full loss of eq. 8. One epoch = rollout of all windows +
readout + output net + loss + backward + Adam step, timed for

* eager: the plain per-step autograd loop (``engine="eager"``: nn.Linear layers on
  cat([x, u_k]) each step, autograd records every operation),
* fused: ``engine="fused"`` (input projections precomputed, TorchScript forward loop into
  a preallocated buffer, hand-written reverse-time backward, weight gradients as single
  large matmuls; parknss.nss.fused), and
* fast: the fused engine with ``model.fused_kernels: fast`` (the same functions by
  cheaper kernels, rounded differently: tanh(a) = 2·σ(2a) - 1 with the affine 2s - 1
  folded into the next layer's weights, two kernels a layer and step; skinny products
  reordered), and
* native: ``model.fused_kernels: native`` (the per-step loops, their derivatives, the
  hidden layers' weight gradients and the output network in C compiled for this machine,
  parknss.nss.fused_native; the warm-up epoch builds or loads the library),

with identical initial weights, data and loss code, in the same run, interleaved epoch by
epoch, with one intra-op thread. Readout and loss are the same code in all (applied to
the whole stacked trajectory). Prints the seconds per epoch of each (best and median of
``--repeats`` after one warm-up epoch), the loss of every epoch of all (they train
identically up to float32 rounding), the ratio eager / each of the best times and, last,
the median and range of the ratios of paired (back-to-back) epochs of eager and each
fused variant, in wall seconds and in CPU seconds
(``time.process_time``: on a loaded machine the wall time of an epoch counts the other
processes' turns, its CPU time much less so).

Last, the arithmetic: the multiply-adds of one epoch's matrix products (counted from the
shapes: the state net's forward, reverse-time and weight-gradient products, the output
net's three passes), timed at torch's GEMM rates on this machine in the same run (the
per-step B x H x H product for the two recurrences, the stacked (B·T) x H x H product for
the rest): the best ratio eager / fused an engine built on torch's products could reach
with nothing but them (the native kernels run their own products, faster than these).
The load average before and after is printed too (the machine may be shared).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import torch

from parknss.data.normalize import Normalizer
from parknss.data.windows import make_windows
from parknss.nss.batch import Batch, make_batch
from parknss.nss.config import NSSConfig, with_overrides
from parknss.nss.model import NORMALIZED
from parknss.nss.step import epoch_loss
from parknss.nss.train import build_model, geometry_of


def load_campaign(data: str | None):
    if data:
        from parknss.data.io import read_campaign

        return read_campaign(data)
    from parknss.reference.campaign import generate_campaign

    return generate_campaign(seed=0)


def paper_batch(cfg: NSSConfig, campaign, n_windows: int, length: int):
    norm = Normalizer.fit(
        list(campaign), NORMALIZED, cfg.data.normalizer, cfg.data.clip_percentiles
    )
    w = make_windows(list(campaign), length)
    if w.n < n_windows:
        raise SystemExit(f"campaign gives only {w.n} windows of {length}")
    model = build_model(cfg, norm, geometry_of(campaign))
    b = make_batch(model, w, cfg.loss.blind_zone_kmh)
    t = b.targets
    sel = slice(0, n_windows)
    for k in t.__dataclass_fields__:
        setattr(t, k, getattr(t, k)[sel])
    return norm, Batch(b.x0[sel], b.u[sel], t, b.lengths[sel])


class Runner:
    """A model, its optimizer and one engine: ``epoch()`` runs and times one epoch."""

    def __init__(self, cfg, norm, geom, batch, engine: str) -> None:
        self.cfg, self.batch, self.engine = cfg, batch, engine
        self.model = build_model(cfg, norm, geom)
        self.opt = torch.optim.Adam(self.model.parameters(), lr=cfg.train.lr)
        self.times: list[float] = []
        self.cpu: list[float] = []
        self.losses: list[float] = []

    def epoch(self, record: bool = True) -> None:
        t0, c0 = time.perf_counter(), time.process_time()
        self.opt.zero_grad(set_to_none=True)
        terms = epoch_loss(self.model, self.batch, self.cfg, engine=self.engine)
        terms.total.backward()
        self.opt.step()
        dt, dc = time.perf_counter() - t0, time.process_time() - c0
        self.losses.append(float(terms.total.detach()))
        if record:
            self.times.append(dt)
            self.cpu.append(dc)


def epoch_macs(batch: Batch, m) -> tuple[float, float]:
    """Multiply-adds of one epoch's products: (the two recurrences' per-step products, the
    rest), from the shapes alone (B windows x T samples, state net m.state_layers x
    m.state_units on [x (2), u (4)] -> 2, output net m.output_layers x m.output_units on
    5 -> 2)."""
    n_s, n_o = batch.n * (batch.steps - 1), batch.n * batch.steps
    H, Ho = m.state_units, m.output_units
    hid = (m.state_layers - 1) * H * H
    fwd_step = 2 * H + hid + 2 * H  # the x-part of the first layer, hidden layers, head
    rev_step = 2 * H + hid + 2 * H  # head, hidden layers, first layer's x-part
    stacked_s = 4 * H + 6 * H + hid + 2 * H  # input projection; weight gradients
    o_pass = 5 * Ho + (m.output_layers - 1) * Ho * Ho + 2 * Ho
    return n_s * (fwd_step + rev_step), n_s * stacked_s + n_o * 3 * o_pass


def gemm_rate(rows: int, H: int, dtype: torch.dtype, repeats: int) -> float:
    """Multiply-adds per CPU second of a rows x H x H product into a preallocated out."""
    a, w = torch.rand(rows, H, dtype=dtype), torch.rand(H, H, dtype=dtype)
    out = torch.empty(rows, H, dtype=dtype)
    torch.mm(a, w, out=out)
    c0 = time.process_time()
    for _ in range(repeats):
        torch.mm(a, w, out=out)
    return rows * H * H * repeats / (time.process_time() - c0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None, help="campaign folder (default: generated)")
    ap.add_argument("--windows", type=int, default=29)
    ap.add_argument("--length", type=int, default=2121)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    load0 = os.getloadavg()[0]
    cfg = NSSConfig()
    campaign = load_campaign(a.data)
    norm, batch = paper_batch(cfg, campaign, a.windows, a.length)
    geom = geometry_of(campaign)
    m = cfg.model
    print(
        f"epoch at paper size: {batch.n} windows x {batch.steps} steps, state net "
        f"{m.state_layers}x{m.state_units}, output net {m.output_layers}x{m.output_units}, "
        f"{torch.get_num_threads()} thread(s), torch {torch.__version__}"
    )
    runners = {
        "eager": Runner(cfg, norm, geom, batch, "eager"),
        "fused": Runner(cfg, norm, geom, batch, "fused"),
    }
    for kernels in ("fast", "native"):
        kcfg = with_overrides(cfg, model={"fused_kernels": kernels})
        runners[kernels] = Runner(kcfg, norm, geom, batch, "fused")
    for r in runners.values():
        r.epoch(record=False)  # warm-up (TorchScript profiling, buffer allocation)
    for _ in range(a.repeats):  # interleaved, so both see the same machine load
        for r in runners.values():
            r.epoch()
    best = {}
    for e, r in runners.items():
        best[e] = min(r.times)
        losses = ", ".join(f"{v:.7f}" for v in r.losses)
        print(
            f"{e:>6}: best {best[e]:.3f} s/epoch, median {statistics.median(r.times):.3f} s/epoch "
            f"(CPU best {min(r.cpu):.3f} s) over {len(r.times)} epochs; losses {losses}"
        )
    fused = [name for name in runners if name != "eager"]
    for name in fused:
        print(f"speedup eager/{name}: {best['eager'] / best[name]:.2f}x")
    for clock in ("times", "cpu"):
        for name in fused:
            eager, other = getattr(runners["eager"], clock), getattr(runners[name], clock)
            paired = [e / f for e, f in zip(eager, other, strict=True)]
            print(f"paired epochs eager/{name} ({'wall' if clock == 'times' else 'CPU'}): median "
                  f"{statistics.median(paired):.2f}x [{min(paired):.2f}-{max(paired):.2f}] over "
                  f"{len(paired)} pairs")
    rec, rest = epoch_macs(batch, m)
    dtype = runners["eager"].model.dtype
    small = gemm_rate(batch.n, m.state_units, dtype, 4000)
    big = gemm_rate(batch.n * batch.steps, m.state_units, dtype, 5)
    floor = rec / small + rest / big
    print(f"arithmetic: {(rec + rest) / 1e9:.1f} G multiply-adds an epoch "
          f"({rec / 1e9:.1f} G in the per-step products at torch's {small / 1e9:.0f} G/s, "
          f"{rest / 1e9:.1f} G stacked at {big / 1e9:.0f} G/s): {floor:.3f} CPU s; "
          f"eager CPU best / that {min(runners['eager'].cpu) / floor:.2f}x")
    print(f"load average (1 min) {load0:.1f} before, {os.getloadavg()[0]:.1f} after, "
          f"{os.cpu_count()} CPUs")


if __name__ == "__main__":
    main()
