"""Benchmark: parknss ISO/TS 18571 against objective-rating-metrics on 6000-sample pairs.

    python benchmarks/bench_iso.py [--n 6000] [--repeats 3] [--engine auto] [--json]

Builds deterministic 6000-sample pairs (lagged noisy mix of sines, step responses, a
speed-like profile against a lagged model, a damped oscillation) and rates them with
the reference ``ISO18571`` class (numba compiled; its one-off JIT compilation is timed
separately and excluded), with ``parknss.metrics.iso18571.rate`` pair by pair, and with
``rate_many`` all four at once (how ``parknss rate`` rates a trial's channels). Each
repeat times the three side by side in one run; per pair it prints the best times and
the largest sub-rating difference, then the speed ratios (reference time / parknss
time over the four pairs) as the median and range over the repeats, in wall and CPU
time (on a shared machine the CPU ratio is the steadier one). ``--engine`` picks the
magnitude rating's DTW (``ISORatingConfig.dtw_engine``: auto, numpy or native; the same
ratings either way).
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from parknss.metrics.iso18571 import ISORatingConfig, rate, rate_many

DT = 0.01
FIELDS = ("corridor", "phase", "magnitude", "slope", "overall")


def pairs(n: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Deterministic (measured, predicted) pairs of n samples at 100 Hz."""
    rng = np.random.default_rng(2024)
    t = np.arange(n + 40) * DT
    mix = np.sin(2 * np.pi * 0.17 * t) + 0.4 * np.sin(2 * np.pi * 0.93 * t + 0.3)
    out = {"lagged_noisy_mix": (mix[25 : 25 + n] + 0.05 * rng.standard_normal(n), 1.1 * mix[:n])}
    t = t[:n]
    step = lambda t0, tau: np.where(t > t0, 1 - np.exp(-np.clip(t - t0, 0, None) / tau), 0.0)  # noqa: E731
    out["step_responses"] = (step(5.0, 1.0), 1.05 * step(5.4, 1.4))
    v = 0.8 * np.abs(np.sin(np.pi * t / 12.0)) * np.sign(np.sin(np.pi * t / 24.0))
    out["speed_profile"] = (
        v + 0.02 * rng.standard_normal(n),
        np.concatenate([np.zeros(12), v[:-12]]) * 0.97,
    )
    out["damped_oscillation"] = (
        np.exp(-0.05 * t) * np.sin(2 * np.pi * 0.3 * t),
        np.exp(-0.07 * t) * np.sin(2 * np.pi * 0.31 * t + 0.1),
    )
    return out


def reference_rating(cls, m: np.ndarray, p: np.ndarray) -> dict:
    """All reference sub-ratings, unrounded, with one DTW (as in its overall_rating)."""
    t = np.arange(m.size) * DT
    r = cls(np.column_stack([t, m]), np.column_stack([t, p]), dt=DT)
    out = {
        "corridor": r.corridor_rating(-1),
        "phase": r.phase_rating(-1),
        "magnitude": r.magnitude_rating(-1),
        "slope": r.slope_rating(-1),
    }
    w = (r._w_z, r._w_p, r._w_m, r._w_s)
    out["overall"] = sum(wi * out[f] for wi, f in zip(w, FIELDS[:4], strict=True))
    return out


def timed(fn) -> tuple[float, float, object]:
    """(wall s, CPU s, result) of one call."""
    w0, c0 = time.perf_counter(), time.process_time()
    res = fn()
    return time.perf_counter() - w0, time.process_time() - c0, res


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=6000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--engine", choices=("auto", "numpy", "native"), default="auto")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    cfg = ISORatingConfig(dtw_engine=args.engine)
    log = (lambda *a: print(*a, file=sys.stderr)) if args.json else print

    t0 = time.perf_counter()
    from objective_rating_metrics.rating import ISO18571

    t_import = time.perf_counter() - t0
    warm = np.sin(np.arange(200) * 0.05)
    t0 = time.perf_counter()
    reference_rating(ISO18571, warm, 1.1 * warm)
    t_jit = time.perf_counter() - t0
    log(f"reference import {t_import:.2f} s, first call incl. numba JIT {t_jit:.2f} s (excluded); "
        f"parknss DTW engine {args.engine}")
    rate(warm, 1.1 * warm, DT, cfg)  # builds or loads the native DTW (excluded)
    data = pairs(args.n)
    names = list(data)
    ours_t = {k: [] for k in names}  # (wall, cpu) per repeat
    ref_t = {k: [] for k in names}
    many_t, ours_res, ref_res, many_res = [], {}, {}, []
    for _ in range(args.repeats):
        for name, (m, p) in data.items():
            w, c, ours_res[name] = timed(lambda m=m, p=p: rate(m, p, DT, cfg))
            ours_t[name].append((w, c))
            w, c, ref_res[name] = timed(lambda m=m, p=p: reference_rating(ISO18571, m, p))
            ref_t[name].append((w, c))
        w, c, many_res = timed(lambda: rate_many(list(data.values()), DT, cfg))
        many_t.append((w, c))
    if [ours_res[k] for k in names] != many_res:
        raise SystemExit("rate_many differs from rate pair by pair")
    log(
        f"{'pair':<22} {'n':>6} {'parknss s':>10} {'reference s':>12} {'ratio':>7} "
        f"{'shift':>6} {'max |diff|':>11}"
    )
    rows = []
    for name in names:
        ours, ref = ours_res[name], ref_res[name]
        diff = {f: abs(getattr(ours, f) - float(ref[f])) for f in FIELDS}
        t_ours = min(w for w, _ in ours_t[name])
        t_ref = min(w for w, _ in ref_t[name])
        rows.append({"pair": name, "n": int(data[name][0].size), "parknss_s": t_ours,
                     "reference_s": t_ref, "shift": ours.shift_samples,
                     "max_abs_diff": max(diff.values()),
                     **{f"diff_{f}": d for f, d in diff.items()}})
        log(
            f"{name:<22} {data[name][0].size:>6} {t_ours:>10.3f} {t_ref:>12.3f} "
            f"{t_ref / t_ours:>7.1f} {ours.shift_samples:>6} {max(diff.values()):>11.2e}"
        )

    def ratios(ours: list[tuple[float, float]], clock: int) -> list[float]:
        ref_round = [sum(ref_t[k][r][clock] for k in names) for r in range(args.repeats)]
        return sorted(ref_round[r] / ours[r][clock] for r in range(args.repeats))

    one_by_one = [tuple(sum(ours_t[k][r][i] for k in names) for i in (0, 1))
                  for r in range(args.repeats)]
    summary = {}
    modes = (("pair by pair (rate)", one_by_one), ("four at once (rate_many)", many_t))
    for label, series in modes:
        for clock, clock_name in ((0, "wall"), (1, "cpu")):
            rs = ratios(series, clock)
            summary[f"{label} {clock_name}"] = {
                "median": float(np.median(rs)), "min": rs[0], "max": rs[-1]}
    if args.json:
        print(json.dumps({"pairs": rows, "reference_jit_s": t_jit, "repeats": args.repeats,
                          "max_abs_diff": max(r["max_abs_diff"] for r in rows),
                          "speed_ratio": summary}, indent=2))
    else:
        print(f"speed ratio, reference / parknss over the {len(names)} pairs, median [range] "
              f"of {args.repeats} repeats in one run:")
        for key, r in summary.items():
            print(f"  {key:<32} {r['median']:6.1f}x  [{r['min']:.1f}-{r['max']:.1f}]")
        print(f"largest sub-rating difference: {max(r['max_abs_diff'] for r in rows):.2e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
