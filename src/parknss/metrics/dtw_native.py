"""The magnitude rating's banded DTW in C: the same cells, rules and sums, bit for bit.

:func:`parknss.metrics.iso18571.dtw_path_sums_many` holds the algorithm as a NumPy sweep
over anti-diagonals, bound by NumPy's per-call overhead at the bands of a rating (a few
hundred cells). Here the same dynamic programme runs row by row in C (compiled by the
system C compiler through :func:`parknss.cbuild.compile_library`, cached per machine):
local cost (x_i - y_j)², steps (1,0), (0,1), (1,1), cells |i - j| <= band; the
predecessor is (i-1, j) unless (i, j-1) is strictly cheaper, and (i-1, j-1) only if
strictly cheaper than both; each cell carries the sums Σ|x - y| and Σ|y| of its path,
each a sum in path order with one rounding per addition, exactly as the sweep carries
them. The build keeps ISO C's floating-point semantics (``-std=c99``: no contraction of
a multiply and an add), so every cost and sum is the sweep's to the last bit
(tests/metrics/test_dtw_native.py); 2.3-3.8x faster than the sweep on the benchmark's
6000-sample pairs, one pair or four. Memory: six rows of 2·band + 1 doubles.
"""

from __future__ import annotations

import ctypes
import functools

import numpy as np

from parknss.cbuild import NATIVE_FLAGS, compile_library
from parknss.errors import ParknssError

C_SOURCE = r"""
#include <math.h>

/* out[0] = Σ|x_i - y_j|, out[1] = Σ|y_j| over the path back-tracked from (L-1, L-1).
   Rows i hold the cells j = i - band + o, o = 0 .. 2·band; work: 6·(2·band + 1) doubles. */
void pk_dtw(int L, int band, const double *x, const double *y, double *out, double *work) {
  int W = 2 * band + 1;
  double *cp = work, *cc = work + W, *rp = work + 2 * W, *rc = work + 3 * W;
  double *ip = work + 4 * W, *ic = work + 5 * W;
  const double inf = HUGE_VAL;
  for (int o = 0; o < W; o++) { cp[o] = inf; rp[o] = 0.0; ip[o] = 0.0; }
  for (int i = 0; i < L; i++) {
    int olo = band - i > 0 ? band - i : 0;              /* j >= 0 */
    int ohi = L - 1 - i + band < W - 1 ? L - 1 - i + band : W - 1;  /* j <= L - 1 */
    for (int o = 0; o < olo; o++) { cc[o] = inf; rc[o] = 0.0; ic[o] = 0.0; }
    for (int o = olo; o <= ohi; o++) {
      int j = i - band + o;
      double d = x[i] - y[j];
      double sq = d * d, ar = fabs(d), ai = fabs(y[j]);
      if (i == 0 && j == 0) { cc[o] = sq; rc[o] = ar; ic[o] = ai; continue; }
      double up = o + 1 < W ? cp[o + 1] : inf;  /* (i-1, j) */
      double left = o > 0 ? cc[o - 1] : inf;    /* (i, j-1) */
      double diag = cp[o];                      /* (i-1, j-1) */
      int tl = left < up;
      double b = left < up ? left : up;
      int nd = b <= diag;
      cc[o] = (diag < b ? diag : b) + sq;
      double pr, pi;
      if (nd) {
        if (tl) { pr = rc[o - 1]; pi = ic[o - 1]; } else { pr = rp[o + 1]; pi = ip[o + 1]; }
      } else { pr = rp[o]; pi = ip[o]; }
      rc[o] = pr + ar;
      ic[o] = pi + ai;
    }
    for (int o = ohi + 1; o < W; o++) { cc[o] = inf; rc[o] = 0.0; ic[o] = 0.0; }
    double *t;
    t = cp; cp = cc; cc = t;
    t = rp; rp = rc; rc = t;
    t = ip; ip = ic; ic = t;
  }
  out[0] = rp[band]; /* (L-1, L-1) */
  out[1] = ip[band];
}
"""

_P = ctypes.c_void_p


@functools.cache
def library() -> ctypes.CDLL:
    """The compiled DTW (built once per machine, cached; ParknssError without a compiler)."""
    try:
        path = compile_library({"pk_dtw.c": C_SOURCE}, NATIVE_FLAGS)
    except ParknssError as e:
        raise ParknssError(f"the native DTW: {e}; or ISORatingConfig dtw_engine numpy") from e
    lib = ctypes.CDLL(str(path))
    lib.pk_dtw.argtypes = [ctypes.c_int, ctypes.c_int, _P, _P, _P, _P]
    lib.pk_dtw.restype = None
    return lib


@functools.cache
def available() -> bool:
    """Whether the native DTW builds here (a C compiler is found and compiles it)."""
    try:
        library()
    except ParknssError:
        return False
    return True


def path_sums(x: np.ndarray, y: np.ndarray, band: int) -> tuple[float, float]:
    """(Σ|x_i - y_j|, Σ|y_j|) over the banded DTW path of x (rows) against y (columns),
    both (L,) float64: :func:`parknss.metrics.iso18571.dtw_path_sums`, bit for bit."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    y = np.ascontiguousarray(y, dtype=np.float64)
    if x.ndim != 1 or y.shape != x.shape or not 0 <= band < x.size:
        raise ValueError("dtw_path_sums needs equal lengths and 0 <= band < L")
    out = np.empty(2)
    work = np.empty(6 * (2 * band + 1))
    library().pk_dtw(x.size, band, x.ctypes.data, y.ctypes.data, out.ctypes.data,
                     work.ctypes.data)
    return float(out[0]), float(out[1])
