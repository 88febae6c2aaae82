"""ISO/TS 18571:2014 objective rating of a predicted against a measured time history.

Both signals lie on one time grid (spacing ``dt`` s, same length N, same unit). The
measured signal is the standard's reference curve T, the prediction its comparison
curve C. Four sub-ratings in [0, 1] are combined into the overall rating R:

* corridor Z: on the full, unshifted curves. With t_norm = max|T|, the inner and outer
  corridor half-widths are a0·t_norm and b0·t_norm; a sample with |C_i - T_i| within the
  inner corridor scores 1, outside the outer corridor 0, in between
  ((b0·t_norm - |C_i - T_i|) / ((b0 - a0)·t_norm))^kz; Z is the mean over samples.
* phase EP: the Pearson correlation of the two curves is evaluated at every shift of
  up to floor(εP·N) samples in both directions, the shift applied by truncating both
  curves to their overlap. The shift n with the largest correlation wins; ties go to
  the smaller |n| and, at equal |n|, to the prediction lagging (the standard's rho_L
  before rho_R). Correlations within 1e-12 of the best count as ties, so that
  rounding noise cannot override the standard's minimum-shift rule. EP = 1 for n = 0,
  0 for |n| >= εP·N, else ((εP·N - |n|)/(εP·N))^kp.
* magnitude EM (EEARTH): the phase-shifted, truncated curves (length L) are aligned by
  dynamic time warping (squared-difference local cost, steps (1,0), (0,1), (1,1) of
  weight 1, Sakoe-Chiba band |i - j| < ceil(band·L)); along the warping path the
  relative error e = Σ|C_w - T_w| / Σ|T_w| gives EM = ((εM - e)/εM)^km, 0 for e > εM.
* slope ES: central-difference derivatives of the truncated curves (one-sided at the
  ends), each smoothed by a centred 9-point moving average whose window shrinks
  symmetrically to 1, 3, 5, 7 points at the ends; e = Σ|C' - T'| / Σ|T'| gives
  ES = ((εS - e)/εS)^ks, 0 for e >= εS.
* R = wZ·Z + wP·EP + wM·EM + wS·ES, graded Excellent (R > 0.94), Good (> 0.80),
  Fair (> 0.58), else Poor.

Degenerate input is defined, never NaN:

* non-finite samples (NaN, ±inf) or a non-positive dt: DataError.
* length mismatch or non-1-D input: DataError (resample onto one grid first; no
  implicit interpolation or cropping).
* too short: N must leave at least ``slope_window`` (9) samples after the largest
  allowed shift floor(εP·N) (N >= 11 with the defaults), else DataError.
* zero variance: the Pearson correlation at a shift where either truncated curve is
  constant is 0 (no linear association is measurable). Hence a constant or all-zero
  measurement, or an identically zero prediction, gives shift 0 and EP = 1 (no time
  shift is identified); the other sub-ratings carry the disagreement.
* all-zero measurement: t_norm = 0 collapses both corridors to zero width; a sample
  scores 1 where C_i = T_i exactly and 0 elsewhere.
* zero denominators in EM and ES (an all-zero truncated measurement, or a constant one
  for ES): the relative error is 0 when the numerator is 0 too, else infinite, so the
  sub-rating is 1 for an exact match and 0 otherwise.

Implementation: the correlation at every shift comes from prefix sums and one FFT
cross-correlation (NumPy's: SciPy's signal module is imported by the low-pass alone);
shifts within 1e-7 of the best are re-evaluated exactly (two-pass centred Pearson)
before the tie rule is applied. The warping runs over anti-diagonals of the band,
carrying the cost and the path sums of the standard's back-tracked path (ties to
(i-1, j), then (i, j-1), then (i-1, j-1)) along with it, so memory is linear in N and
no N x N matrix is formed. :func:`rate_many` rates several pairs (a trial's channels,
raw and filtered) with one warping sweep over all of them: each pair's arithmetic is
unchanged, the per-operation overhead of the sweep is shared.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Literal

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from pydantic import Field, model_validator

from parknss.config import StrictModel
from parknss.errors import ConfigError, DataError

GRADES: tuple[str, ...] = ("Excellent", "Good", "Fair", "Poor")
REFINE_TOL = 1.0e-7  # shifts this close to the best correlation are re-evaluated exactly
COND_TOL = 1.0e-6  # prefix-sum variances below this share of Σa² are re-evaluated exactly
TIE_TOL = 1.0e-12  # exact correlations this close to the best are ties (rounding noise)


class ISORatingConfig(StrictModel):
    """ISO/TS 18571 parameters; the defaults are the standard's."""

    # added after stored ratings existed (it changes no number): their digests stay
    omit_at_default = frozenset({"dtw_engine"})

    a0: float = Field(0.05, gt=0, description="inner corridor half-width / max|T|")
    b0: float = Field(0.5, gt=0, description="outer corridor half-width / max|T|")
    corridor_exponent: float = Field(2.0, gt=0, description="kz")
    max_shift_fraction: float = Field(0.2, gt=0, lt=1, description="εP, of N")
    phase_exponent: float = Field(1.0, gt=0, description="kp")
    dtw_band_fraction: float = Field(0.1, gt=0, le=1, description="DTW band, of L")
    dtw_engine: Literal["auto", "numpy", "native"] = Field(
        "auto", description="the magnitude rating's DTW: numpy (the sweep here), native (the "
        "same in C, metrics/dtw_native.py, bit for bit) or auto (native where a C compiler "
        "builds it)")
    magnitude_limit: float = Field(0.5, gt=0, description="εM")
    magnitude_exponent: float = Field(1.0, gt=0, description="km")
    slope_window: int = Field(9, ge=1, description="moving-average points (odd)")
    slope_limit: float = Field(2.0, gt=0, description="εS")
    slope_exponent: float = Field(1.0, gt=0, description="ks")
    weight_corridor: float = Field(0.4, ge=0)
    weight_phase: float = Field(0.2, ge=0)
    weight_magnitude: float = Field(0.2, ge=0)
    weight_slope: float = Field(0.2, ge=0)
    grade_excellent: float = Field(0.94, description="R above this: Excellent")
    grade_good: float = Field(0.80, description="R above this: Good")
    grade_fair: float = Field(0.58, description="R above this: Fair, else Poor")

    @model_validator(mode="after")
    def _consistent(self) -> ISORatingConfig:
        if not self.a0 < self.b0:
            raise ValueError("a0 must be smaller than b0")
        if self.slope_window % 2 != 1:
            raise ValueError("slope_window must be odd")
        total = self.weight_corridor + self.weight_phase + self.weight_magnitude
        if abs(total + self.weight_slope - 1.0) > 1e-9:
            raise ValueError("the four weights must sum to 1")
        if not self.grade_excellent > self.grade_good > self.grade_fair:
            raise ValueError("grade thresholds must decrease: excellent > good > fair")
        return self


@dataclass(frozen=True)
class Rating:
    """One ISO/TS 18571 rating. Sub-ratings and overall in [0, 1].

    ``shift_samples`` is the phase shift found, in samples: positive when the prediction
    lags the measurement (pred[i + n] matches meas[i]), negative when it leads.
    """

    corridor: float
    phase: float
    magnitude: float
    slope: float
    overall: float
    grade: str
    shift_samples: int

    def as_dict(self) -> dict:
        """Plain JSON-ready dict of the fields."""
        return asdict(self)


def grade_of(overall: float, config: ISORatingConfig | None = None) -> str:
    """The ISO/TS 18571 grade of an overall rating (strict '>' at each threshold)."""
    cfg = config or ISORatingConfig()
    if overall > cfg.grade_excellent:
        return "Excellent"
    if overall > cfg.grade_good:
        return "Good"
    if overall > cfg.grade_fair:
        return "Fair"
    return "Poor"


def min_samples(config: ISORatingConfig | None = None) -> int:
    """Smallest N that leaves ``slope_window`` samples after the largest allowed shift."""
    cfg = config or ISORatingConfig()
    n = cfg.slope_window
    while n - math.floor(n * cfg.max_shift_fraction) < cfg.slope_window:
        n += 1
    return n


def _check_pair(measured, predicted, dt: float, cfg: ISORatingConfig, label: str):
    """Validate and return the two curves as float64 1-D arrays."""
    try:
        ok = math.isfinite(float(dt)) and float(dt) > 0
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise DataError(f"{label}: dt must be a positive finite number of seconds, got {dt!r}")
    out = []
    for name, arr in (("measured", measured), ("predicted", predicted)):
        a = np.asarray(arr, dtype=np.float64)
        if a.ndim != 1:
            raise DataError(f"{label}: {name} must be 1-D, got shape {a.shape}")
        bad = ~np.isfinite(a)
        if bad.any():
            first = int(np.flatnonzero(bad)[0])
            raise DataError(
                f"{label}: {name} has {int(bad.sum())} non-finite samples (first at index {first})"
            )
        out.append(a)
    m, p = out
    if m.size != p.size:
        raise DataError(
            f"{label}: measured has {m.size} samples, predicted {p.size}; "
            "rate both on one time grid"
        )
    need = min_samples(cfg)
    if m.size < need:
        raise DataError(
            f"{label}: {m.size} samples; the rating needs at least {need} "
            f"({cfg.slope_window} after the largest allowed phase shift)"
        )
    return m, p


def corridor_rating(measured: np.ndarray, predicted: np.ndarray, config=None) -> float:
    """Corridor sub-rating Z of two equal-length curves (no shift applied)."""
    cfg = config or ISORatingConfig()
    t_norm = float(np.max(np.abs(measured)))
    inner, outer = cfg.a0 * t_norm, cfg.b0 * t_norm
    dev = np.abs(predicted - measured)
    score = np.zeros_like(dev)
    score[dev <= inner] = 1.0
    mid = (dev > inner) & (dev <= outer)
    score[mid] = ((outer - dev[mid]) / (outer - inner)) ** cfg.corridor_exponent
    return float(score.mean())


def _run_lengths(a: np.ndarray) -> tuple[int, int]:
    """Lengths of the leading and trailing runs of samples equal to the end samples."""
    lead = np.flatnonzero(a != a[0])
    trail = np.flatnonzero(a != a[-1])
    n = a.size
    return (int(lead[0]) if lead.size else n), (n - 1 - int(trail[-1]) if trail.size else n)


def _pearson(a: np.ndarray, b: np.ndarray) -> float:
    """Two-pass centred Pearson correlation; 0 where either side has zero variance."""
    da, db = a - a.mean(), b - b.mean()
    saa, sbb = float(da @ da), float(db @ db)
    if saa == 0.0 or sbb == 0.0:
        return 0.0
    return float(np.clip((da @ db) / math.sqrt(saa * sbb), -1.0, 1.0))


def _windows(m: np.ndarray, p: np.ndarray, shift: int) -> tuple[np.ndarray, np.ndarray]:
    """The overlap of the two curves at a shift (positive: the prediction lags)."""
    n = m.size
    if shift >= 0:
        return m[: n - shift], p[shift:]
    return m[-shift:], p[: n + shift]


def _shift_order(kmax: int) -> np.ndarray:
    """Shifts in the standard's priority: 0, +1, -1, +2, -2, ... (+: prediction lags)."""
    ks = np.arange(1, kmax + 1)
    return np.concatenate([[0], np.stack([ks, -ks], axis=1).ravel()]).astype(np.int64)


def _approx_correlations(m: np.ndarray, p: np.ndarray, shifts: np.ndarray) -> np.ndarray:
    """Pearson correlation at every shift from prefix sums and an FFT cross-correlation.

    Accurate to ~1e-10 where it is not 1; ill-conditioned shifts read 1 (refine them).
    """
    n = m.size
    a, b = m - m.mean(), p - p.mean()
    ca = np.concatenate([[0.0], np.cumsum(a)])
    cb = np.concatenate([[0.0], np.cumsum(b)])
    caa = np.concatenate([[0.0], np.cumsum(a * a)])
    cbb = np.concatenate([[0.0], np.cumsum(b * b)])
    nfft = 1 << (2 * n - 1).bit_length()  # no wrap-around: nfft >= 2n - 1
    fa, fb = np.fft.rfft(a, nfft), np.fft.rfft(b, nfft)
    cross = np.fft.irfft(fa * np.conj(fb), nfft)  # [k mod nfft] = Σ a[i+k] b[i]
    k = np.abs(shifts)
    lag = shifts >= 0
    length = (n - k).astype(np.float64)
    # prediction lags (shift > 0): a[0:n-k] with b[k:n]; else a[k:n] with b[0:n-k]
    a0 = np.where(lag, 0, k)
    b0 = np.where(lag, k, 0)
    sa = ca[a0 + n - k] - ca[a0]
    sb = cb[b0 + n - k] - cb[b0]
    saa = caa[a0 + n - k] - caa[a0]
    sbb = cbb[b0 + n - k] - cbb[b0]
    sab = cross[(-shifts) % nfft]
    var_a = length * saa - sa * sa
    var_b = length * sbb - sb * sb
    cov = length * sab - sa * sb
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = np.clip(cov / np.sqrt(var_a * var_b), -1.0, 1.0)
    # where cancellation leaves fewer than ~10 digits, report 1 so the shift is re-evaluated
    shaky = ~((var_a > COND_TOL * length * saa) & (var_b > COND_TOL * length * sbb))
    return np.where(shaky | ~np.isfinite(rho), 1.0, rho)


def phase_shift(measured: np.ndarray, predicted: np.ndarray, config=None) -> int:
    """The standard's phase shift in samples (positive: the prediction lags)."""
    cfg = config or ISORatingConfig()
    m, p = measured, predicted
    n = m.size
    kmax = int(np.floor(n * cfg.max_shift_fraction))
    shifts = _shift_order(kmax)
    rho = _approx_correlations(m, p, shifts)
    # windows with an exactly constant side have correlation 0 by definition
    lead_m, trail_m = _run_lengths(m)
    lead_p, trail_p = _run_lengths(p)
    length = n - np.abs(shifts)
    pos = shifts >= 0
    flat_m = np.where(pos, length <= lead_m, length <= trail_m)
    flat_p = np.where(pos, length <= trail_p, length <= lead_p)
    flat = flat_m | flat_p
    rho[flat] = 0.0
    exact = flat.copy()
    best = 0.0 if flat.any() else -np.inf
    for idx in np.argsort(-rho, kind="stable"):
        if exact[idx]:
            continue
        if rho[idx] < best - REFINE_TOL:
            break
        rho[idx] = _pearson(*_windows(m, p, int(shifts[idx])))
        exact[idx] = True
        best = max(best, rho[idx])
    # every unrefined shift is provably below the best; near-equal maxima are ties
    winners = exact & (rho >= best - TIE_TOL)
    return int(shifts[int(np.argmax(winners))])


def phase_rating(shift: int, n: int, config=None) -> float:
    """Phase sub-rating EP of a shift of ``shift`` samples on curves of N = ``n``."""
    cfg = config or ISORatingConfig()
    limit = n * cfg.max_shift_fraction
    if shift == 0:
        return 1.0
    if abs(shift) >= limit:
        return 0.0
    return float(((limit - abs(shift)) / limit) ** cfg.phase_exponent)


def _diagonal_terms(xw, yw, x0: int, y0: int, u0: int, u1: int, penalty: np.ndarray):
    """Data terms of anti-diagonals u0..u1-1 of one parity, shape (u1-u0, K·S).

    xw, yw: sliding windows (width S) of the padded x and of the reversed padded y, shape
    (K, windows, S). Row r, pair k, column c (flat index k·S + c) pairs xp[k, x0 + u + c]
    with yp[k, y0 + u - c] (u = u0 + r); returns the local cost (x - y)² and the path-sum
    increment |x - y| + 1j·|y|. ``penalty`` (K·S,) is added to the cost: +inf outside
    the pair's band and in the separator column, else 0.
    """
    m = yw.shape[1] + yw.shape[2] - 1
    xs = xw[:, x0 + u0 : x0 + u1].transpose(1, 0, 2)
    ys = yw[:, m - y0 - u1 : m - y0 - u0][:, ::-1].transpose(1, 0, 2)
    d = np.empty(xs.shape)
    inc = np.empty(xs.shape, complex)
    np.subtract(xs, ys, out=d)
    np.abs(d, out=inc.real)
    np.abs(ys, out=inc.imag)
    np.square(d, out=d)
    d, inc = d.reshape(len(d), -1), inc.reshape(len(d), -1)
    np.add(d, penalty, out=d)
    return d, inc


def dtw_path_sums(x: np.ndarray, y: np.ndarray, band: int, block: int = 12):
    """Banded DTW of x (rows i) against y (columns j), both of length L.

    Local cost (x_i - y_j)², steps (1,0), (0,1), (1,1) of weight 1, cells |i - j| <= band.
    Returns (Σ|x_i - y_j|, Σ|y_j|) over the path that back-tracking from (L-1, L-1)
    takes, preferring (i-1, j), then (i, j-1), then (i-1, j-1) on equal cumulative cost.
    One pair of :func:`dtw_path_sums_many`, which holds the algorithm.
    """
    num, den = dtw_path_sums_many([x], [y], [band], block)
    return float(num[0]), float(den[0])


def dtw_path_sums_many(xs, ys, bands, block: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """:func:`dtw_path_sums` of K pairs (x_k, y_k, band_k) in one sweep: two arrays (K,).

    The pairs may differ in length L_k and band; each gets exactly the floating-point
    operations it would get alone, so the results are bit-identical. Batching shares
    the per-operation overhead of the sweep, which dominates at bands of a few hundred.

    Anti-diagonal s = i + j is swept in two parities: even s = 2u holds i = u + e,
    j = u - e; odd s = 2u + 1 holds i = u + e + 1, j = u - e. Each parity keeps one
    row of cumulative cost and one of path sums (as complex Σ|x-y| + 1j·Σ|y|): the K
    pairs side by side, S columns each (the widest band's cells and an infinite-cost
    separator), with an inf sentinel at each end, so memory is O(K L) and no L x L
    matrix is formed. Cells outside the matrix (x padded with +inf, y with -inf) or
    outside a pair's own band carry infinite cost.
    """
    xs = [np.asarray(x, dtype=np.float64) for x in xs]
    ys = [np.asarray(y, dtype=np.float64) for y in ys]
    bands = [int(b) for b in bands]
    if not xs or not len(xs) == len(ys) == len(bands):
        raise ValueError("dtw_path_sums_many needs one band per pair and at least one pair")
    for x, y, b in zip(xs, ys, bands, strict=True):
        if x.ndim != 1 or y.shape != x.shape or not 0 <= b < x.size:
            raise ValueError("dtw_path_sums needs equal lengths and 0 <= band < L")
    kk, lengths = len(xs), [x.size for x in xs]
    n, band = max(lengths), max(bands)
    half, lo_o, hi_o = band // 2, -((band + 1) // 2), (band - 1) // 2
    we, wo = 2 * half + 1, hi_o - lo_o + 1
    ss, base = max(we, wo) + 1, band + 2  # columns per pair; padding of the signals
    xp, yp = np.full((kk, n + 2 * base), np.inf), np.full((kk, n + 2 * base), -np.inf)
    for k, (x, y) in enumerate(zip(xs, ys, strict=True)):
        xp[k, base : base + x.size], yp[k, base : base + y.size] = x, y
    yr = yp[:, ::-1].copy()
    cols, bk = np.arange(ss)[None, :], np.array(bands)[:, None]
    out_e = np.where((cols >= we) | (2 * np.abs(cols - half) > bk), np.inf, 0.0).ravel()
    out_o = np.where((cols >= wo) | (np.abs(2 * (cols + lo_o) + 1) > bk), np.inf, 0.0).ravel()
    width = kk * ss
    ce, co = np.full(width + 2, np.inf), np.full(width + 2, np.inf)
    ae, ao = np.zeros(width + 2, complex), np.zeros(width + 2, complex)
    xw, yw = sliding_window_view(xp, ss, axis=1), sliding_window_view(yr, ss, axis=1)
    origin = 1 + half + ss * np.arange(kk)  # cell (0, 0) and, at u = L-1, (L-1, L-1)
    sq, inc = _diagonal_terms(xw, yw, base - half, base + half, 0, 1, out_e)
    ce[origin], ae[origin] = sq[0, origin - 1], inc[0, origin - 1]
    ends = np.zeros(kk, complex)
    stop: dict[int, list[int]] = {}
    for k, length in enumerate(lengths):
        stop.setdefault(length - 1, []).append(k)
    for k in stop.get(0, []):
        ends[k] = ae[origin[k]]
    # views: the current row of each parity and its predecessors in the other parity
    c_e, c_o, a_e, a_o = ce[1 : width + 1], co[1 : width + 1], ae[1 : width + 1], ao[1 : width + 1]
    ke, ko = -half - lo_o, lo_o + half + 1  # offset of 'up' in the other parity's buffer
    e_up, e_left = co[ke : ke + width], co[ke + 1 : ke + 1 + width]
    ea_up, ea_left = ao[ke : ke + width], ao[ke + 1 : ke + 1 + width]
    o_up, o_left = ce[ko : ko + width], ce[ko + 1 : ko + 1 + width]
    oa_up, oa_left = ae[ko : ko + width], ae[ko + 1 : ko + 1 + width]
    tle, nde, be = np.empty(width, bool), np.empty(width, bool), np.empty(width)
    tlo, ndo, bo = np.empty(width, bool), np.empty(width, bool), np.empty(width)
    less, less_equal, minimum, add = np.less, np.less_equal, np.minimum, np.add
    putmask, both = np.putmask, np.logical_and
    with np.errstate(invalid="ignore"):
        for b0 in range(1, n, block):
            b1 = min(n, b0 + block)
            sq_o, inc_o = _diagonal_terms(
                xw, yw, base + 1 + lo_o, base - lo_o, b0 - 1, b1 - 1, out_o
            )
            sq_e, inc_e = _diagonal_terms(xw, yw, base - half, base + half, b0, b1, out_e)
            for r in range(b1 - b0):
                # odd diagonal 2u - 1: from (i-1, j) unless (i, j-1) is strictly cheaper,
                # from (i-1, j-1) only if strictly cheaper than both
                less(o_left, o_up, out=tlo)
                minimum(o_up, o_left, out=bo)
                less_equal(bo, c_o, out=ndo)
                minimum(bo, c_o, out=bo)
                add(bo, sq_o[r], out=c_o)
                putmask(a_o, ndo, oa_up)
                putmask(a_o, both(ndo, tlo, out=tlo), oa_left)
                add(a_o, inc_o[r], out=a_o)
                # even diagonal 2u, the same rule
                less(e_left, e_up, out=tle)
                minimum(e_up, e_left, out=be)
                less_equal(be, c_e, out=nde)
                minimum(be, c_e, out=be)
                add(be, sq_e[r], out=c_e)
                putmask(a_e, nde, ea_up)
                putmask(a_e, both(nde, tle, out=tle), ea_left)
                add(a_e, inc_e[r], out=a_e)
                for k in stop.get(b0 + r, ()):
                    ends[k] = ae[origin[k]]  # cell (L-1, L-1): last even diagonal, e = 0
    return ends.real.copy(), ends.imag.copy()


def _ratio(num: float, den: float) -> float:
    """num / den with 0/0 = 0 and x/0 = inf (the degenerate-denominator rule)."""
    if den == 0.0:
        return 0.0 if num == 0.0 else math.inf
    return num / den


def _limited_score(error: float, limit: float, exponent: float, zero_at_limit: bool) -> float:
    """((limit - e)/limit)^k clipped to [0, 1]; 1 at e = 0."""
    if error <= 0.0:
        return 1.0
    if error > limit or (zero_at_limit and error >= limit):
        return 0.0
    return float(((limit - error) / limit) ** exponent)


def _dtw_band(length: int, cfg: ISORatingConfig) -> int:
    """The Sakoe-Chiba band of curves of ``length`` samples: |i - j| < ceil(band·L)."""
    return max(math.ceil(cfg.dtw_band_fraction * length) - 1, 0)


def _magnitude_score(num: float, den: float, cfg: ISORatingConfig) -> float:
    """EM from the warping path's sums Σ|C_w - T_w| and Σ|T_w|."""
    return _limited_score(_ratio(num, den), cfg.magnitude_limit, cfg.magnitude_exponent, False)


def warping_sums(xs, ys, bands, engine: str = "auto") -> tuple[np.ndarray, np.ndarray]:
    """:func:`dtw_path_sums_many` by the DTW ``engine`` (ISORatingConfig.dtw_engine): the
    NumPy sweep, or its C twin :mod:`parknss.metrics.dtw_native` pair by pair (the same
    numbers bit for bit; ``auto``: C where a compiler builds it, else the sweep)."""
    if engine != "numpy":
        from parknss.metrics import dtw_native  # the compiler is looked for only here

        if engine == "native" or dtw_native.available():
            sums = [dtw_native.path_sums(x, y, b) for x, y, b in zip(xs, ys, bands, strict=True)]
            return np.array([s[0] for s in sums]), np.array([s[1] for s in sums])
    return dtw_path_sums_many(xs, ys, bands)


def magnitude_rating(meas_shifted: np.ndarray, pred_shifted: np.ndarray, config=None) -> float:
    """EEARTH magnitude sub-rating EM of the phase-shifted, truncated curves."""
    cfg = config or ISORatingConfig()
    band = _dtw_band(meas_shifted.size, cfg)
    num, den = warping_sums([pred_shifted], [meas_shifted], [band], cfg.dtw_engine)
    return _magnitude_score(float(num[0]), float(den[0]), cfg)


def smoothed_derivative(curve: np.ndarray, dt: float, window: int = 9) -> np.ndarray:
    """Central-difference derivative (one-sided at the ends) smoothed by a centred moving
    average of ``window`` points whose window shrinks symmetrically at the ends.

    curve: shape (L,), L >= window; returns shape (L,) in curve units per second.
    """
    d = np.empty_like(curve)
    d[1:-1] = (curve[2:] - curve[:-2]) / (2.0 * dt)
    d[0] = (curve[1] - curve[0]) / dt
    d[-1] = (curve[-1] - curve[-2]) / dt
    half = window // 2
    out = np.empty_like(d)
    out[half : d.size - half] = np.convolve(d, np.full(window, 1.0 / window), mode="valid")
    for i in range(half):
        width = 2 * i + 1
        out[i] = d[:width].sum() / width
        out[-1 - i] = d[-width:].sum() / width
    return out


def slope_rating(meas_shifted: np.ndarray, pred_shifted: np.ndarray, dt: float, config=None):
    """Slope sub-rating ES of the phase-shifted, truncated curves."""
    cfg = config or ISORatingConfig()
    dm = smoothed_derivative(meas_shifted, dt, cfg.slope_window)
    dp = smoothed_derivative(pred_shifted, dt, cfg.slope_window)
    err = _ratio(float(np.abs(dp - dm).sum()), float(np.abs(dm).sum()))
    return _limited_score(err, cfg.slope_limit, cfg.slope_exponent, True)


def rate(
    measured,
    predicted,
    dt: float,
    config: ISORatingConfig | None = None,
    label: str = "signal",
) -> Rating:
    """ISO/TS 18571 rating of ``predicted`` against ``measured``.

    measured, predicted: shape (N,), same unit, on one grid of spacing dt seconds.
    ``label`` names the pair in error messages (e.g. ``"trial r1 channel vx"``).
    """
    return rate_many([(measured, predicted)], dt, config, [label])[0]


def rate_many(
    pairs,
    dt: float,
    config: ISORatingConfig | None = None,
    labels=None,
) -> list[Rating]:
    """The :func:`rate` of each (measured, predicted) pair, all on grids of spacing dt s.

    Every pair is validated and rated exactly as :func:`rate` would (the results are
    bit-identical); the pairs may differ in length. Their magnitude warpings run in C
    where it builds (:func:`warping_sums`), else in one batched sweep
    (:func:`dtw_path_sums_many`), which makes rating a trial's channels together faster
    than one by one. ``labels`` name the pairs in error
    messages (default ``"signal i"``).
    """
    cfg = config or ISORatingConfig()
    pairs = list(pairs)
    names = list(labels) if labels is not None else [f"signal {i}" for i in range(len(pairs))]
    if len(names) != len(pairs):
        raise ValueError("rate_many needs one label per pair")
    checked = [_check_pair(m, p, dt, cfg, lab) for (m, p), lab in zip(pairs, names, strict=True)]
    if not checked:
        return []
    shifts = [phase_shift(m, p, cfg) for m, p in checked]
    windows = [_windows(m, p, shift) for (m, p), shift in zip(checked, shifts, strict=True)]
    nums, dens = warping_sums(
        [ps for _, ps in windows], [ms for ms, _ in windows],
        [_dtw_band(ms.size, cfg) for ms, _ in windows], cfg.dtw_engine,
    )
    out = []
    for k, ((m, p), shift, (ms, ps)) in enumerate(zip(checked, shifts, windows, strict=True)):
        z = corridor_rating(m, p, cfg)
        ep = phase_rating(shift, m.size, cfg)
        em = _magnitude_score(float(nums[k]), float(dens[k]), cfg)
        es = slope_rating(ms, ps, dt, cfg)
        overall = (
            cfg.weight_corridor * z
            + cfg.weight_phase * ep
            + cfg.weight_magnitude * em
            + cfg.weight_slope * es
        )
        out.append(Rating(z, ep, em, es, float(overall), grade_of(overall, cfg), shift))
    return out


class LowpassConfig(StrictModel):
    """The identical conditioning of §V-F: zero-phase Butterworth low-pass."""

    cutoff_hz: float = Field(5.0, gt=0)
    order: int = Field(4, ge=1, le=12, description="per pass (zero-phase doubles it)")


def lowpass(signal, dt: float, cutoff_hz: float = 5.0, order: int = 4, label: str = "signal"):
    """Zero-phase Butterworth low-pass (forward-backward, second-order sections).

    signal: shape (N,), dt in s, cutoff in Hz below the Nyquist frequency 1/(2 dt).
    """
    a = np.asarray(signal, dtype=np.float64)
    if a.ndim != 1:
        raise DataError(f"{label}: low-pass needs a 1-D signal, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise DataError(f"{label}: low-pass input has non-finite samples")
    if not (math.isfinite(dt) and dt > 0):
        raise DataError(f"{label}: dt must be positive, got {dt!r}")
    nyquist = 0.5 / dt
    if not 0 < cutoff_hz < nyquist:
        raise ConfigError(f"low-pass cutoff {cutoff_hz} Hz must lie in (0, {nyquist:g}) Hz")
    from scipy import signal as sps  # here, not at module level: importing it takes seconds

    sos = sps.butter(order, cutoff_hz, btype="low", fs=1.0 / dt, output="sos")
    padlen = 3 * (2 * len(sos) + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum())))
    if a.size <= padlen:
        raise DataError(
            f"{label}: {a.size} samples; the order-{order} zero-phase low-pass needs > {padlen}"
        )
    return sps.sosfiltfilt(sos, a)
