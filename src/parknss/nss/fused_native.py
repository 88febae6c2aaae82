"""The native kernels of the fused engine: its per-step loops and the output network in C.

A paper-size epoch of the fused engine (:mod:`parknss.nss.fused`) spends most of its time
in two sequential loops over the T-1 steps, forward and reverse, each step a handful of
B x H x H products (29 x 128 x 128) and elementwise kernels, and in the output network
over all B·T rows. Through torch every one of them is a dispatched kernel of its own, and
on the development machine MKL runs these products at 30-40 G multiply-adds/s on one core.
Here the same arithmetic is plain C, compiled by the system C compiler for this machine
(:func:`parknss.cbuild.compile_library`, built once and cached) and called once per loop
through ctypes with the torch buffers' addresses:

* one product kernel, register-blocked in 7 rows x 32 columns (GNU C vector extensions,
  16 float32 lanes, which the compiler lowers to the machine's vector width): each output
  accumulates over k in order, from its bias or input part; 50 G multiply-adds/s measured
  at 29 x 128 x 128 on the development machine;
* tanh on the rows just computed while they are in cache, by a polynomial e^x - 1 (range
  reduction to |r| <= ln2/2, degree-7 Taylor; within 2 ulp, tests/nss/test_fused_native.py);
  the reverse loop's derivative 1 - h² likewise, on the delta it multiplies;
* the weight gradients of the hidden layers summed inside the reverse loop, a rank-B
  update a layer and step into a block of partial sums that is added to the total every
  FLUSH = 32 steps; the bias and head sums in double (sums of many terms that cancel);
* the output network in chunks of :data:`CHUNK_ROWS` rows (forward: its layers stay in
  cache; backward: deltas, weight-gradient sums and dL/dx chunk by chunk).

The formulation is the reference kernels' (activations h = tanh(a), plain weights; the
``fast`` kernels' folding of tanh into σ was for torch's slow tanh and costs digits); the
rounding is its own: multiplies and adds may be contracted into fused multiply-adds, tanh
is the polynomial's, sums run in their own order. Float32 only (any other dtype is refused
in one line); deterministic on one machine and build; as close to float64 as the torch
kernels (tests/nss/test_fused_native.py, docs/nss.md). The first layer's weight and input
gradients from its deltas stay torch's (skinny products, :mod:`parknss.nss.fused`).

Shapes (all C-contiguous float32): X (T, B, n_x) with X[0] = x0; P (T-1, B, H) the first
layer's input parts W0u·u + b0, which may be the activations' layer 0 itself (the first
product then accumulates in place); W0xT (n_x, H) = W0xᵀ; hidden weights stacked
(NL-1, H, H): W_iᵀ forward, W_i reverse; biases (NL-1, H); Wo (n_x, H) = Δt·Wout;
c (n_x,) = Δt·bout; activations Hs (NL, T-1, B, H) layer-major (or (NL, 1, B, H) scratch
when not stored); the first layer's deltas D0 (T-1, B, H); Lam (T, B, n_x).
"""

from __future__ import annotations

import ctypes
import functools
from dataclasses import dataclass

import torch
from torch import Tensor

from parknss.cbuild import NATIVE_FLAGS, compile_library
from parknss.errors import ParknssError

C_SOURCE = r"""
#include <stdint.h>
#include <string.h>

typedef float v16 __attribute__((vector_size(64)));
#define LANES 16

static inline v16 ld(const float *p) { v16 v; memcpy(&v, p, sizeof v); return v; }
static inline void st(float *p, v16 v) { memcpy(p, &v, sizeof v); }

/* e^x - 1 for x <= 0 (clamped at -87): x = n·ln2 + r with |r| <= ln2/2 (ln2 in two parts),
   e^r - 1 = q(r) by its degree-7 Taylor polynomial without the constant (relative error
   about 1e-8), then 2^n·q + (2^n - 1), exact in its last addend for n >= -24, so no digits
   cancel for small |x| (e^x - 1 itself would lose them). */
static inline float pk_expm1(float x) {
  x = x < -87.0f ? -87.0f : x;
  float t = x * 1.44269504088896341f + 12582912.0f; /* 1.5·2^23: rounds to an integer */
  float n = t - 12582912.0f;
  float r = x - n * 0.693359375f;
  r = r + n * 2.12194440e-4f;
  float q = 1.0f / 5040.0f;
  q = q * r + 1.0f / 720.0f;
  q = q * r + 1.0f / 120.0f;
  q = q * r + 1.0f / 24.0f;
  q = q * r + 1.0f / 6.0f;
  q = q * r + 0.5f;
  q = q * r + 1.0f;
  q = q * r;
  int32_t ti, e;
  memcpy(&ti, &t, 4);
  e = (ti - 0x4B400000 + 127) << 23;
  float s;
  memcpy(&s, &e, 4);
  return s * q + (s - 1.0f);
}

/* a[i] = tanh(a[i]) = sign(a)·(-m / (2 + m)) with m = e^(-2|a|) - 1 (about 1 ulp) */
static void tanh_inplace(float *a, long n) {
  for (long i = 0; i < n; i++) {
    float v = a[i];
    float m = pk_expm1(v < 0.0f ? 2.0f * v : -2.0f * v);
    float t = -m / (2.0f + m);
    a[i] = v < 0.0f ? -t : t;
  }
}

/* d[i] = d[i]·(1 - h[i]²): the delta times the tanh derivative at the stored h */
static void dtanh_inplace(float *d, const float *h, long n) {
  for (long i = 0; i < n; i++) d[i] = d[i] * (1.0f - h[i] * h[i]);
}

/* out[r][c] = init[r][c] + Σ_k x(r, k)·W[k][c] for R rows from r0 and NV·16 columns from
   c0; x(r, k) = x[r·xr + k·xk], init rows ldi apart (0: one row for all), W (K, N)
   row-major, out rows N apart. */
static inline __attribute__((always_inline)) void block(
    int R, int NV, int K, int N, const float *x, long xr, long xk, const float *W,
    const float *init, long ldi, float *out, int r0, int c0) {
  v16 acc[7][2];
  for (int i = 0; i < R; i++)
    for (int j = 0; j < NV; j++) acc[i][j] = ld(init + (r0 + i) * ldi + c0 + LANES * j);
  for (int k = 0; k < K; k++) {
    const float *w = W + (long)k * N + c0;
    v16 wv[2];
    for (int j = 0; j < NV; j++) wv[j] = ld(w + LANES * j);
    for (int i = 0; i < R; i++) {
      float a = x[(r0 + i) * xr + k * xk];
      for (int j = 0; j < NV; j++) acc[i][j] += a * wv[j];
    }
  }
  for (int i = 0; i < R; i++)
    for (int j = 0; j < NV; j++) st(out + (long)(r0 + i) * N + c0 + LANES * j, acc[i][j]);
}

/* the rows r0 .. r0+R-1 of gemm's product: 32 columns at a time, then 16 */
#define ROWS(R)                                                                   \
  do {                                                                            \
    int c = 0;                                                                    \
    for (; c + 2 * LANES <= N; c += 2 * LANES)                                    \
      block(R, 2, K, N, x, xr, xk, W, init, ldi, out, r, c);                      \
    for (; c + LANES <= N; c += LANES) block(R, 1, K, N, x, xr, xk, W, init, ldi, out, r, c); \
  } while (0)

/* out (M, N) = init + x (M, K) · W (K, N), x(r, k) = x[r·xr + k·xk]; out may be init
   itself (ldi = N): each block reads its part of init before writing it. Blocks of 7 rows
   x 32 columns (14 accumulators: the fastest shape measured at 29 x 128 x 128 on the
   development machine, 53 G multiply-adds/s against 42 for 4 x 64), then 4 rows, then 1. */
static void gemm(int M, int K, int N, const float *x, long xr, long xk, const float *W,
                 const float *init, long ldi, float *out) {
  int r = 0;
  for (; r + 7 <= M; r += 7) ROWS(7);
  for (; r + 4 <= M; r += 4) ROWS(4);
  for (; r < M; r++) ROWS(1);
  int cv = N - N % LANES; /* the columns past the last whole vector */
  for (r = 0; r < M; r++)
    for (int c = cv; c < N; c++) {
      float s = init[(long)r * ldi + c];
      for (int k = 0; k < K; k++) s += x[(long)r * xr + (long)k * xk] * W[(long)k * N + c];
      out[(long)r * N + c] = s;
    }
}

/* out (B, N) = init + x (B, K) · W (K, N), x rows ldx apart */
static void matmul(int B, int K, int N, const float *x, int ldx, const float *W,
                   const float *init, int ldi, float *out) {
  gemm(B, K, N, x, ldx, 1, W, init, ldi, out);
}

/* G (M, N) += dᵀ·s for d (B, M), s (B, N): the weight gradient's share of one step */
static void rank_update(int B, int M, int N, const float *d, const float *s, float *G) {
  gemm(M, B, N, d, 1, M, s, G, N, G);
}

/* col (N) += Σ_r d[r][:] over B rows, in double: the bias gradients are sums of many
   terms that largely cancel (float32 sums in sequence lost digits against torch's pairwise) */
static void col_sum(int B, int N, const float *d, double *col) {
  for (int r = 0; r < B; r++)
    for (int c = 0; c < N; c++) col[c] += d[(long)r * N + c];
}

/* λᵀ·h and Σλ of one block of B rows into the double sums GH (nx, H) and lsum (nx) */
static void head_sums(int B, int H, int nx, const float *lam, const float *h, double *GH,
                      double *lsum) {
  for (int r = 0; r < B; r++)
    for (int q = 0; q < nx; q++) {
      double l = lam[r * nx + q];
      double *gh = GH + (long)q * H;
      for (int c = 0; c < H; c++) gh[c] += l * h[(long)r * H + c];
      lsum[q] += l;
    }
}

/* a[i] += b[i] over n, b then zeroed: a block of partial sums flushed into the total */
static void flush(float *a, float *b, long n) {
  for (long i = 0; i < n; i++) { a[i] += b[i]; b[i] = 0.0f; }
}

/* Σ_k a[k]·b[k] over n, in 16 lanes then across them */
static inline float dot(const float *a, const float *b, int n) {
  v16 acc = {0};
  int k = 0;
  for (; k + LANES <= n; k += LANES) acc += ld(a + k) * ld(b + k);
  float s = 0.0f;
  for (int l = 0; l < LANES; l++) s += acc[l];
  for (; k < n; k++) s += a[k] * b[k];
  return s;
}

void pk_nss_forward(int T1, int B, int H, int NL, int nx, int store, float *X, const float *P,
                    const float *W0xT, const float *WhT, const float *bh, const float *Wo,
                    const float *c, float *Hs) {
  long bh_ = (long)B * H;
  long layer = (store ? (long)T1 : 1L) * bh_;
  for (int k = 0; k < T1; k++) {
    long j = store ? k : 0;
    const float *xk = X + (long)k * B * nx;
    float *xn = X + (long)(k + 1) * B * nx;
    float *h = Hs + j * bh_;
    matmul(B, nx, H, xk, nx, W0xT, P + (long)k * bh_, H, h);
    tanh_inplace(h, bh_);
    for (int i = 1; i < NL; i++) {
      float *hi = Hs + i * layer + j * bh_;
      matmul(B, H, H, h, H, WhT + (long)(i - 1) * H * H, bh + (long)(i - 1) * H, 0, hi);
      tanh_inplace(hi, bh_);
      h = hi;
    }
    for (int r = 0; r < B; r++)
      for (int q = 0; q < nx; q++)
        xn[r * nx + q] = (xk[r * nx + q] + dot(h + (long)r * H, Wo + (long)q * H, H)) + c[q];
  }
}

/* The reverse loop. Out: Lam (T, B, nx); D0 (T-1, B, H) the first layer's deltas
   δ = dL/da; the weight-gradient sums (zeroed here) G (NL-1, H, H) = Σ δ_iᵀ·h_{i-1} of the
   hidden layers i = 1..NL-1, and in double col (NL, H) = Σ δ_i, GH (nx, H) =
   Σ λ_{k+1}ᵀ·h_{NL-1}, lsum (nx) = Σ λ_{k+1}, over all windows and steps. G is built in
   blocks of FLUSH steps that are then added to the total (two-level summation). Work:
   scratch (2, B, H) for the upper layers' deltas; part, as many floats as G. */
#define FLUSH 32
void pk_nss_backward(int T1, int B, int H, int NL, int nx, const float *gX, const float *Hs,
                     float *D0, const float *W0xT, const float *Wh, const float *Wo,
                     const float *zeros, float *Lam, float *G, double *col, double *GH,
                     double *lsum, float *scratch, float *part) {
  long bh_ = (long)B * H;
  long layer = (long)T1 * bh_;
  long nG = (long)(NL - 1) * H * H;
  memset(part, 0, sizeof(float) * nG);
  memset(G, 0, sizeof(float) * nG);
  memset(col, 0, sizeof(double) * NL * H);
  memset(GH, 0, sizeof(double) * nx * H);
  memset(lsum, 0, sizeof(double) * nx);
  memcpy(Lam + (long)T1 * B * nx, gX + (long)T1 * B * nx, sizeof(float) * B * nx);
  for (int k = T1 - 1; k >= 0; k--) {
    const float *ln = Lam + (long)(k + 1) * B * nx;
    float *lk = Lam + (long)k * B * nx;
    const float *gk = gX + (long)k * B * nx;
    const float *sl = Hs + (long)(NL - 1) * layer + k * bh_;
    head_sums(B, H, nx, ln, sl, GH, lsum);
    float *d = NL - 1 > 0 ? scratch + (long)((NL - 1) % 2) * bh_ : D0 + k * bh_;
    matmul(B, nx, H, ln, nx, Wo, zeros, 0, d);
    dtanh_inplace(d, sl, bh_);
    for (int i = NL - 1; i > 0; i--) {
      const float *sp = Hs + (long)(i - 1) * layer + k * bh_;
      col_sum(B, H, d, col + (long)i * H);
      rank_update(B, H, H, d, sp, part + (long)(i - 1) * H * H);
      float *dp = i - 1 > 0 ? scratch + (long)((i - 1) % 2) * bh_ : D0 + k * bh_;
      matmul(B, H, H, d, H, Wh + (long)(i - 1) * H * H, zeros, 0, dp);
      dtanh_inplace(dp, sp, bh_);
      d = dp;
    }
    col_sum(B, H, d, col);
    for (int r = 0; r < B; r++)
      for (int q = 0; q < nx; q++)
        lk[r * nx + q] =
            (gk[r * nx + q] + ln[r * nx + q]) + dot(d + (long)r * H, W0xT + (long)q * H, H);
    if (k % FLUSH == 0) flush(G, part, nG);
  }
}

/* The output network over N rows: h_0 = tanh(b0 + x·W0T), h_i = tanh(bh_i + h_{i-1}·WT_i),
   y = bo + h·Woᵀ (rows of Wo dotted), in chunks of `chunk` rows whose layers stay in cache.
   x (N, n_in), W0T (n_in, H), WT (NL-1, H, H), bh (NL-1, H), Wo (n_out, H); out: the
   activations S (NL, N, H), y (N, n_out). */
void pk_mlp_forward(int chunk, int N, int n_in, int H, int NL, int n_out, const float *x,
                    const float *W0T, const float *b0, const float *WT, const float *bh,
                    const float *Wo, const float *bo, float *S, float *y) {
  long layer = (long)N * H;
  for (int r0 = 0; r0 < N; r0 += chunk) {
    int m = N - r0 < chunk ? N - r0 : chunk;
    float *s = S + (long)r0 * H;
    matmul(m, n_in, H, x + (long)r0 * n_in, n_in, W0T, b0, 0, s);
    tanh_inplace(s, (long)m * H);
    for (int i = 1; i < NL; i++) {
      float *si = S + i * layer + (long)r0 * H;
      matmul(m, H, H, s, H, WT + (long)(i - 1) * H * H, bh + (long)(i - 1) * H, 0, si);
      tanh_inplace(si, (long)m * H);
      s = si;
    }
    for (int r = 0; r < m; r++)
      for (int q = 0; q < n_out; q++)
        y[(long)(r0 + r) * n_out + q] = bo[q] + dot(s + (long)r * H, Wo + (long)q * H, H);
  }
}

/* Its backward for the upstream gradient g (N, n_out): gx (N, n_in) = dL/dx, and the sums
   (zeroed here) G0 (n_in, H) = Σ xᵀ·δ_0, G (NL-1, H, H) = Σ δ_iᵀ·h_{i-1}, and in double
   col (NL, H) = Σ δ_i, GH (n_out, H) = Σ gᵀ·h_{NL-1}, gsum (n_out) = Σ g, with δ_i = dL/da_i,
   the weights W0T (n_in, H) = W0ᵀ, W (NL-1, H, H) = W_i, Wo (n_out, H) = W_out.
   Work: scratch (2, chunk, H). */
void pk_mlp_backward(int chunk, int N, int n_in, int H, int NL, int n_out, const float *x,
                     const float *g, const float *S, const float *W0T, const float *W,
                     const float *Wo, const float *zeros, float *gx, float *G0, float *G,
                     double *col, double *GH, double *gsum, float *scratch) {
  long layer = (long)N * H;
  long cbh = (long)chunk * H;
  memset(G0, 0, sizeof(float) * n_in * H);
  memset(G, 0, sizeof(float) * (NL - 1) * H * H);
  memset(col, 0, sizeof(double) * NL * H);
  memset(GH, 0, sizeof(double) * n_out * H);
  memset(gsum, 0, sizeof(double) * n_out);
  for (int r0 = 0; r0 < N; r0 += chunk) {
    int m = N - r0 < chunk ? N - r0 : chunk;
    const float *gc = g + (long)r0 * n_out;
    const float *sl = S + (NL - 1) * layer + (long)r0 * H;
    head_sums(m, H, n_out, gc, sl, GH, gsum);
    float *d = scratch + (long)((NL - 1) % 2) * cbh;
    matmul(m, n_out, H, gc, n_out, Wo, zeros, 0, d);
    dtanh_inplace(d, sl, (long)m * H);
    for (int i = NL - 1; i > 0; i--) {
      const float *sp = S + (i - 1) * layer + (long)r0 * H;
      col_sum(m, H, d, col + (long)i * H);
      rank_update(m, H, H, d, sp, G + (long)(i - 1) * H * H);
      float *dp = scratch + (long)((i - 1) % 2) * cbh;
      matmul(m, H, H, d, H, W + (long)(i - 1) * H * H, zeros, 0, dp);
      dtanh_inplace(dp, sp, (long)m * H);
      d = dp;
    }
    col_sum(m, H, d, col);
    rank_update(m, n_in, H, x + (long)r0 * n_in, d, G0);
    for (int r = 0; r < m; r++)
      for (int q = 0; q < n_in; q++)
        gx[(long)(r0 + r) * n_in + q] = dot(d + (long)r * H, W0T + (long)q * H, H);
  }
}
"""

FLAGS: tuple[str, ...] = (*NATIVE_FLAGS, "-ffp-contract=fast")
"""This machine's build with contraction into fused multiply-adds (the kernels' rounding is
their own anyway; module doc); a compiler that refuses them gets the portable build."""

CHUNK_ROWS = 256
"""Rows of the output network processed together (their layers, 3 x 256 x 128 floats at
paper size, stay in the core's cache between the products)."""

_P = ctypes.c_void_p
_I = ctypes.c_int


@functools.cache
def library() -> ctypes.CDLL:
    """The compiled kernels (built once per machine, cached; ParknssError without a C
    compiler or on a failed build, naming the way out)."""
    try:
        path = compile_library({"pk_nss.c": C_SOURCE}, FLAGS)
    except ParknssError as e:
        raise ParknssError(f"the native fused kernels: {e}; or use model.fused_kernels "
                           "reference (--set model.fused_kernels=reference)") from e
    lib = ctypes.CDLL(str(path))
    lib.pk_nss_forward.argtypes = [_I] * 6 + [_P] * 8
    lib.pk_nss_forward.restype = None
    lib.pk_nss_backward.argtypes = [_I] * 5 + [_P] * 14
    lib.pk_nss_backward.restype = None
    lib.pk_mlp_forward.argtypes = [_I] * 6 + [_P] * 9
    lib.pk_mlp_forward.restype = None
    lib.pk_mlp_backward.argtypes = [_I] * 6 + [_P] * 14
    lib.pk_mlp_backward.restype = None
    return lib


def _ptrs(*tensors: Tensor, dtype: torch.dtype = torch.float32) -> list[_P]:
    """Addresses of C-contiguous CPU tensors of ``dtype`` (ParknssError on any other)."""
    out = []
    for t in tensors:
        if t.dtype != dtype:
            raise ParknssError(
                f"the native fused kernels are float32 only (got {t.dtype}); "
                "use train.dtype float32 or model.fused_kernels reference"
            )
        if not t.is_contiguous() or t.device.type != "cpu":
            raise ParknssError("the native fused kernels need contiguous CPU tensors")
        out.append(_P(t.data_ptr()))
    return out


def stacked(ts: list[Tensor], shape: tuple[int, ...], dtype: torch.dtype) -> Tensor:
    """The tensors ``ts`` (each of ``shape``) as one contiguous (len, *shape) tensor, the
    layout the kernels read per-layer weights and biases in; (0, *shape) when there are none."""
    return torch.stack(ts) if ts else torch.empty((0, *shape), dtype=dtype)


def forward(x0: Tensor, P: Tensor, W0xT: Tensor, WhT: Tensor, bh: Tensor, Wo: Tensor,
            c: Tensor, Hs: Tensor, store: bool) -> Tensor:
    """X (T, B, n_x) of the forward loop; the activations h into Hs (module doc)."""
    T1, B, H = P.shape
    nx = x0.shape[1]
    X = torch.empty((T1 + 1, B, nx), dtype=x0.dtype)
    X[0] = x0
    NL = Hs.shape[0]
    library().pk_nss_forward(T1, B, H, NL, nx, int(store),
                             *_ptrs(X, P, W0xT, WhT, bh, Wo, c, Hs))
    return X


@dataclass
class Reverse:
    """What the native reverse loop returns (shapes as in the module doc).

    lam (T, B, n_x) = dL/dx_k; D0 (T-1, B, H) the first layer's deltas δ = dL/da;
    G (NL-1, H, H) = Σ δ_iᵀ·h_{i-1} and col (NL, H) = Σ δ_i over all windows and steps
    (i = 1..NL-1 for G; every layer for col); GH (n_x, H) = Σ λ_{k+1}ᵀ·h_{NL-1},
    lsum (n_x,) = Σ λ_{k+1}: with Δt, the head's gradients."""

    lam: Tensor
    D0: Tensor
    G: Tensor
    col: Tensor
    GH: Tensor
    lsum: Tensor


def backward(gX: Tensor, Hs: Tensor, D0: Tensor, W0xT: Tensor, Wh: Tensor,
             Wo: Tensor) -> Reverse:
    """The reverse loop: dL/dx_k, the first layer's deltas into D0 (T-1, B, H), and the
    other layers' weight-gradient sums, accumulated inside the loop (:class:`Reverse`)."""
    NL, T1, B, H = Hs.shape
    nx = gX.shape[2]
    dt = gX.dtype
    lam = torch.empty_like(gX)
    G = torch.empty((NL - 1, H, H), dtype=dt)
    col = torch.empty((NL, H), dtype=torch.float64)
    GH = torch.empty((nx, H), dtype=torch.float64)
    lsum = torch.empty(nx, dtype=torch.float64)
    zeros = torch.zeros(H, dtype=dt)
    scratch = torch.empty((2, B, H), dtype=dt)
    part = torch.empty_like(G)
    library().pk_nss_backward(
        T1, B, H, NL, nx,
        *_ptrs(gX, Hs, D0, W0xT, Wh, Wo, zeros, lam, G),
        *_ptrs(col, GH, lsum, dtype=torch.float64),
        *_ptrs(scratch, part),
    )
    return Reverse(lam, D0, G, col.to(dt), GH.to(dt), lsum.to(dt))


def mlp_forward(x: Tensor, W0T: Tensor, b0: Tensor, WT: Tensor, bh: Tensor, Wo: Tensor,
                bo: Tensor, S: Tensor) -> Tensor:
    """y (N, n_out) of the output network, the activations h into S (NL, N, H)."""
    N, n_in = x.shape
    NL, _, H = S.shape
    y = torch.empty((N, Wo.shape[0]), dtype=x.dtype)
    library().pk_mlp_forward(CHUNK_ROWS, N, n_in, H, NL, Wo.shape[0],
                             *_ptrs(x, W0T, b0, WT, bh, Wo, bo, S, y))
    return y


@dataclass
class MLPGrads:
    """The output network's backward sums (C source): gx (N, n_in); G0 (n_in, H) = Σ xᵀ·δ_0;
    G (NL-1, H, H) = Σ δ_iᵀ·h_{i-1}; col (NL, H) = Σ δ_i; GH (n_out, H) = Σ gᵀ·h_{NL-1};
    gsum (n_out,) = Σ g: the weight and bias gradients of every layer (G0 transposed)."""

    gx: Tensor
    G0: Tensor
    G: Tensor
    col: Tensor
    GH: Tensor
    gsum: Tensor


def mlp_backward(x: Tensor, g: Tensor, S: Tensor, W0T: Tensor, W: Tensor, Wo: Tensor) -> MLPGrads:
    """The output network's backward: dL/dx and the weight-gradient sums (:class:`MLPGrads`)."""
    N, n_in = x.shape
    NL, _, H = S.shape
    n_out = g.shape[1]
    dt = x.dtype
    f64 = torch.float64
    out = MLPGrads(
        torch.empty((N, n_in), dtype=dt), torch.empty((n_in, H), dtype=dt),
        torch.empty((NL - 1, H, H), dtype=dt), torch.empty((NL, H), dtype=f64),
        torch.empty((n_out, H), dtype=f64), torch.empty(n_out, dtype=f64),
    )
    zeros = torch.zeros(H, dtype=dt)
    scratch = torch.empty((2, CHUNK_ROWS, H), dtype=dt)
    library().pk_mlp_backward(
        CHUNK_ROWS, N, n_in, H, NL, n_out,
        *_ptrs(x, g, S, W0T, W, Wo, zeros, out.gx, out.G0, out.G),
        *_ptrs(out.col, out.GH, out.gsum, dtype=f64),
        *_ptrs(scratch),
    )
    out.col, out.GH, out.gsum = out.col.to(dt), out.GH.to(dt), out.gsum.to(dt)
    return out
