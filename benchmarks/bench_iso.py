"""Benchmark: parknss ISO/TS 18571 against objective-rating-metrics on 6000-sample pairs.

    python benchmarks/bench_iso.py [--n 6000] [--repeats 3] [--json]

Builds deterministic 6000-sample pairs (lagged noisy mix of sines, step responses, a
speed-like profile against a lagged model, a damped oscillation), rates each with
``parknss.metrics.iso18571.rate`` and with the reference ``ISO18571`` class (numba
compiled; its one-off JIT compilation is timed separately and excluded), prints per
pair both times and the largest sub-rating difference, and last the speed ratio
(reference time / parknss time, summed over the pairs, best of ``--repeats``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from parknss.metrics.iso18571 import rate

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


def best_time(fn, repeats: int) -> tuple[float, object]:
    """Smallest wall time of `repeats` calls, and the last result."""
    times, res = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        res = fn()
        times.append(time.perf_counter() - t0)
    return min(times), res


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=6000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    log = (lambda *a: print(*a, file=sys.stderr)) if args.json else print

    t0 = time.perf_counter()
    from objective_rating_metrics.rating import ISO18571

    t_import = time.perf_counter() - t0
    warm = np.sin(np.arange(200) * 0.05)
    t0 = time.perf_counter()
    reference_rating(ISO18571, warm, 1.1 * warm)
    t_jit = time.perf_counter() - t0
    log(f"reference import {t_import:.2f} s, first call incl. numba JIT {t_jit:.2f} s (excluded)")
    log(
        f"{'pair':<22} {'n':>6} {'parknss s':>10} {'reference s':>12} {'ratio':>7} "
        f"{'shift':>6} {'max |diff|':>11}"
    )
    rows, ours_total, ref_total = [], 0.0, 0.0
    for name, (m, p) in pairs(args.n).items():
        t_ours, ours = best_time(lambda m=m, p=p: rate(m, p, DT), args.repeats)
        t_ref, ref = best_time(
            lambda m=m, p=p: reference_rating(ISO18571, m, p), max(1, args.repeats - 1)
        )
        diff = {f: abs(getattr(ours, f) - float(ref[f])) for f in FIELDS}
        ours_total += t_ours
        ref_total += t_ref
        rows.append(
            {
                "pair": name,
                "n": int(m.size),
                "parknss_s": t_ours,
                "reference_s": t_ref,
                "shift": ours.shift_samples,
                "max_abs_diff": max(diff.values()),
                **{f"diff_{f}": d for f, d in diff.items()},
            }
        )
        log(
            f"{name:<22} {m.size:>6} {t_ours:>10.3f} {t_ref:>12.3f} {t_ref / t_ours:>7.1f} "
            f"{ours.shift_samples:>6} {max(diff.values()):>11.2e}"
        )
    ratio = ref_total / ours_total
    if args.json:
        print(
            json.dumps(
                {
                    "pairs": rows,
                    "parknss_total_s": ours_total,
                    "reference_total_s": ref_total,
                    "reference_jit_s": t_jit,
                    "speed_ratio": ratio,
                },
                indent=2,
            )
        )
    else:
        print(f"total: parknss {ours_total:.3f} s, reference {ref_total:.3f} s")
        print(f"speed ratio (reference / parknss): {ratio:.1f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
