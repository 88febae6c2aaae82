"""The chain's 10 ms step as generated C source: the weights of one chain, no Python at run
time.

:func:`chain_c_source` writes a :class:`~parknss.chain.realtime.RealtimeChain` (the NumPy
float64 twin, the reference implementation) as two C99 files, ``pk_chain.h`` and
``pk_chain.c``: every weight and scaling a ``static const double`` literal (``repr``, so
the doubles round-trip exactly), and the twin's arithmetic statement for statement: the
input envelope (NaN hold, ±inf and domain clamps), the gear rule
(:mod:`parknss.actuators.shift`), the three steppers (static, lag1, Hammerstein, lag2,
NARX, GRU, LSTM, the monotone brake with its hold; state-aware features), the output
envelope (floors, steering rate limit, lock) and the NSS's Euler step and readout. Two
things differ from NumPy: the order of the sums inside a matrix-vector product (NumPy's
BLAS), and ``tanh``, which the C computes from IEEE basic operations only (``pk_tanh_v``:
Cephes' rational form below 0.625, else 1 - 2/(e^{2|x|} + 1) with its own e^y; within 1.4
ulp of the exact value (1.34 measured, just above 0.625), where glibc's is within 2 ulp
and NumPy's SIMD one 1.2, and those two differ from each other in a third of the
arguments), vectorised and free of libm, so it has the same bits on every machine and in
every build. The two agree to rounding over whole trials (shipped chain, longest bundled
trial: 2.1e-14 against 1.4e-14 with libm's tanh; tests/chain/test_ccode.py and the FMU
test hold 1e-9).

The C interface (``pk_chain.h``)::

    size_t pk_size(void);                                    bytes of one pk_chain
    void pk_start(pk_chain *s, const double x0[2], const double y0[3], const double cmd0[4]);
    void pk_step(pk_chain *s, const double cmd[4], double out[PK_NOUT]);
    void pk_run(pk_chain *s, const double *cmds, long n, double *out);   n samples
    void pk_step_many(pk_chain *const *s, long n, const double *cmds, double *out);
                                                  one sample of n chains, cmds (n, 4)
    void pk_tanh_array(long n, const double *x, double *y);   the step's tanh, for checks

``cmd`` is [gear, torque_cmd N·m, decel_cmd m/s², steer_cmd deg]; ``out`` is
[torque N·m, brake_pressure bar, steer deg, vx m/s, yaw_rate rad/s, ax m/s², ay m/s²,
engaged gear] (:data:`OUTPUTS`); ``pk_start`` is :meth:`RealtimeChain.start`.
Matrix-vector products loop over the input outer and the output inner, with the weights
stored transposed, so each output is summed over the input in order (never reassociated);
blocks of outputs are summed in vector registers (GCC/Clang vector extensions: 64-byte
vectors for AVX-512, 32 for AVX, else 16), so every build gives the plain loop's bits.
``pk_step_many`` steps several chains of the same weights (a grid's or a vector
environment's plants) with each NSS layer applied to all of them before the next, two
chains summed against each weight load; per chain it is ``pk_step`` bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from parknss.actuators.spec import CHANNELS
from parknss.actuators.steppers import (
    GRUStepper,
    Lag1Stepper,
    Lag2Stepper,
    LSTMStepper,
    MonoLagStepper,
    NARXStepper,
    StaticStepper,
    Stepper,
)
from parknss.chain.realtime import RealtimeChain
from parknss.errors import CheckpointError
from parknss.nss.nets import NumpyLayers
from parknss.signals import DT, kmh_to_ms

OUTPUTS: tuple[str, ...] = (
    "torque", "brake_pressure", "steer", "vx", "yaw_rate", "ax", "ay", "gear",
)
HEADER = "pk_chain.h"
SOURCE = "pk_chain.c"


@dataclass(frozen=True)
class CSource:
    """The generated files: ``header`` (pk_chain.h) and ``source`` (pk_chain.c) text."""

    header: str
    source: str

    def files(self) -> dict[str, str]:
        return {HEADER: self.header, SOURCE: self.source}


def _num(v: float) -> str:
    v = float(v)
    if math.isinf(v):
        return "HUGE_VAL" if v > 0 else "(-HUGE_VAL)"
    if math.isnan(v):
        raise CheckpointError("chain holds a NaN weight or scaling; cannot generate C")
    return repr(v)


def _array(name: str, values) -> str:
    flat = np.asarray(values, dtype=np.float64).ravel().tolist()
    if not flat:
        return f"static const double {name}[1] = {{0.0}};\n"
    body = ",".join(_num(v) for v in flat)
    return f"static const double {name}[{len(flat)}] = {{{body}}};\n"


class _Writer:
    """Collects the weight literals and the code of one chain."""

    def __init__(self) -> None:
        self.data: list[str] = []
        self.max_width = 8

    def mlp(self, name: str, layers: NumpyLayers) -> str:
        """Emit the layers (W transposed) and a pk_layer table; return the table's name."""
        rows = []
        for i, (W, b) in enumerate(layers):
            self.data.append(_array(f"{name}_W{i}", W.T))
            self.data.append(_array(f"{name}_B{i}", b))
            rows.append(f"{{{W.shape[1]}, {W.shape[0]}, {name}_W{i}, {name}_B{i}}}")
            self.max_width = max(self.max_width, W.shape[0], W.shape[1])
        self.data.append(f"static const pk_layer {name}[{len(layers)}] = {{{', '.join(rows)}}};\n")
        return name

    def vec(self, name: str, values) -> str:
        self.data.append(_array(name, values))
        return name


def _features(ch: str, st: Stepper, spec_features: tuple[str, ...]) -> str:
    """C statements filling ``fs`` (scaled features) from vx, yaw, g."""
    if not spec_features:
        return ""
    src = {"speed": "fabs(vx)", "vx": "vx", "yaw_rate": "yaw", "gear": "g"}
    lines = [f"    fs[{i}] = ({src[n]} - {_num(st.f_off[i])}) / {_num(st.f_sc[i])};"
             for i, n in enumerate(spec_features)]
    return "\n".join(lines) + "\n"


def _dot(a: str, b: str, n: int) -> str:
    """A left-to-right sum of n products as one C expression (0.0 when n = 0)."""
    if n == 0:
        return "0.0"
    terms = [f"{a}[{i}] * {b}[{i}]" for i in range(n)]
    return "(" + " + ".join(terms) + ")"


def _target(ch: str, st: StaticStepper, w: _Writer) -> str:
    """C expression of the affine target k·cs + b (+ f·w) of a lag-family stepper."""
    t = f"({_num(st.k)} * cs + {_num(st.b)})"
    if st.n_feat:
        wn = w.vec(f"{ch}_w", st.w)
        t = f"({t} + {_dot('fs', wn, st.n_feat)})"
    return t


def _stepper(ch: str, st: Stepper, feats: tuple[str, ...], w: _Writer) -> tuple[str, str]:
    """(reset body, step body) of one channel's stepper; state lives in s->{ch}."""
    cs = f"    double cs = (c - {_num(st.c_off)}) / {_num(st.c_sc)};\n"
    fs = f"    double fs[{max(st.n_feat, 1)}];\n" + _features(ch, st, feats)
    ys, yo = _num(st.y_sc), _num(st.y_off)
    if isinstance(st, Lag1Stepper):
        lt = _num(st.log_tau)
        if st.n_feat:
            vn = w.vec(f"{ch}_v", st.v)
            lt = f"{lt} + {_dot('fs', vn, st.n_feat)}"
        else:
            lt = f"{lt} + 0.0"
        psi = ""
        if st.psi is not None:
            tab = w.mlp(f"{ch}_psi", st.psi)
            zin = ", ".join(["cs", *[f"fs[{i}]" for i in range(st.n_feat)]])
            psi = (f"    double z[{1 + st.n_feat}] = {{{zin}}}, o[1];\n"
                   f"    pk_mlp({tab}, {len(st.psi)}, z, o);\n    u = u + o[0];\n")
        step = (cs + fs + f"    double lt = {lt};\n"
                f"    double a = exp(-{_num(st.dt)} * exp(-lt));\n"
                f"    double u = {_target(ch, st, w)};\n" + psi +
                f"    double out = s->{ch}.y * {ys} + {yo};\n"
                f"    s->{ch}.y = a * s->{ch}.y + (1.0 - a) * u;\n    return out;\n")
        return f"    s->{ch}.y = (y0 - {yo}) / {ys};\n", step
    if isinstance(st, Lag2Stepper):
        (a00, a01), (a10, a11) = st.A
        b0, b1 = st.Bv
        step = (cs + fs + f"    double t = {_target(ch, st, w)};\n"
                f"    double p = s->{ch}.pos, r = s->{ch}.rate;\n"
                f"    double out = p * {ys} + {yo};\n"
                f"    s->{ch}.pos = {_num(a00)} * p + {_num(a01)} * r + {_num(b0)} * t;\n"
                f"    s->{ch}.rate = {_num(a10)} * p + {_num(a11)} * r + {_num(b1)} * t;\n"
                "    return out;\n")
        return f"    s->{ch}.pos = (y0 - {yo}) / {ys};\n    s->{ch}.rate = 0.0;\n", step
    if isinstance(st, StaticStepper):
        step = cs + fs + f"    return {_target(ch, st, w)} * {ys} + {yo};\n"
        return "    (void)y0;\n", step
    if isinstance(st, NARXStepper):
        n, nf = st.n, st.n_feat
        tab = w.mlp(f"{ch}_net", st.net)
        sw = w.vec(f"{ch}_skip", st.skip_w)
        reset = (f"    for (int i = 0; i < {2 * n}; ++i) s->{ch}.buf[i] = "
                 f"(c0 - {_num(st.c_off)}) / {_num(st.c_sc)};\n    s->{ch}.i = 0;\n")
        step = (cs + fs + f"    int i = s->{ch}.i;\n"
                f"    s->{ch}.buf[i] = s->{ch}.buf[i + {n}] = cs;\n"
                f"    i = s->{ch}.i = (i + 1) % {n};\n"
                f"    double z[{n + nf}], o[1], sk = 0.0;\n"
                f"    for (int j = 0; j < {n}; ++j) z[j] = s->{ch}.buf[i + j];\n"
                f"    for (int j = 0; j < {nf}; ++j) z[{n} + j] = fs[j];\n"
                f"    pk_mlp({tab}, {len(st.net)}, z, o);\n"
                f"    for (int j = 0; j < {n + nf}; ++j) sk += {sw}[j] * z[j];\n"
                f"    return (o[0] + sk + {_num(st.skip_b)}) * {ys} + {yo};\n")
        return reset, step
    if isinstance(st, MonoLagStepper):
        return _monolag(ch, st, w)
    if isinstance(st, GRUStepper):
        H, nf = st.H, st.n_feat
        lstm = isinstance(st, LSTMStepper)
        wi, bi = w.vec(f"{ch}_Wi", st.Wi.T), w.vec(f"{ch}_bi", st.bi)
        wh, bh = w.vec(f"{ch}_Wh", st.Wh.T), w.vec(f"{ch}_bh", st.bh)
        wo = w.vec(f"{ch}_Wo", st.Wo)
        G = (4 if lstm else 3) * H
        head = (cs + fs + f"    double x[{1 + nf}], gi[{G}], gh[{G}], y = 0.0;\n"
                f"    x[0] = cs;\n    for (int j = 0; j < {nf}; ++j) x[1 + j] = fs[j];\n"
                f"    pk_matvec({wi}, {1 + nf}, {G}, x, gi);\n"
                f"    pk_matvec({wh}, {H}, {G}, s->{ch}.h, gh);\n"
                f"    for (int j = 0; j < {G}; ++j) {{ gi[j] += {bi}[j]; gh[j] += {bh}[j]; }}\n")
        if lstm:
            body = (f"    for (int j = 0; j < {H}; ++j) {{\n"
                    f"        double gj[4];\n"
                    f"        for (int q = 0; q < 4; ++q)\n"
                    f"            gj[q] = gi[q * {H} + j] + gh[q * {H} + j];\n"
                    "        double ig = pk_sigmoid(gj[0]), fg = pk_sigmoid(gj[1]);\n"
                    "        double gg = pk_tanh(gj[2]), og = pk_sigmoid(gj[3]);\n"
                    f"        s->{ch}.c[j] = fg * s->{ch}.c[j] + ig * gg;\n"
                    f"        s->{ch}.h[j] = og * pk_tanh(s->{ch}.c[j]);\n    }}\n")
            reset = (f"    for (int j = 0; j < {H}; ++j) s->{ch}.h[j] = s->{ch}.c[j] = 0.0;\n"
                     "    (void)y0;\n")
        else:
            body = (f"    for (int j = 0; j < {H}; ++j) {{\n"
                    f"        double r = pk_sigmoid(gi[j] + gh[j]);\n"
                    f"        double z = pk_sigmoid(gi[{H} + j] + gh[{H} + j]);\n"
                    f"        double n = pk_tanh(gi[{2 * H} + j] + r * gh[{2 * H} + j]);\n"
                    f"        s->{ch}.h[j] = (1.0 - z) * n + z * s->{ch}.h[j];\n    }}\n")
            reset = f"    for (int j = 0; j < {H}; ++j) s->{ch}.h[j] = 0.0;\n    (void)y0;\n"
        tail = (f"    for (int j = 0; j < {H}; ++j) y += {wo}[j] * s->{ch}.h[j];\n"
                f"    return (y + {_num(st.bo)}) * {ys} + {yo};\n")
        return reset, head + body + tail
    raise CheckpointError(f"no C template for the {type(st).__name__} stepper")


def _monolag_map(ch: str, st: MonoLagStepper, kn: str, wn: str, r: str) -> str:
    """C statements setting ``m`` to the static map m(r) = b + sum_k w_k sp(beta (r - knot_k))
    / beta, with sp(x) = max(x, 0) + log1p(e^-|x|) (NumPy's logaddexp(x, 0))."""
    beta = _num(st.beta)
    return (f"    double m = 0.0;\n"
            f"    for (int k = 0; k < {len(st.knots)}; ++k) {{\n"
            f"        double x = {beta} * ({r} - {kn}[k]);\n"
            f"        m += (fmax(x, 0.0) + log1p(exp(-fabs(x)))) / {beta} * {wn}[k];\n"
            f"    }}\n    m = {_num(st.b)} + m;\n")


def _monolag(ch: str, st: MonoLagStepper, w: _Writer) -> tuple[str, str]:
    """(reset, step) of the monotone brake (:class:`MonoLagStepper`): the static map's last
    n values in a doubled ring buffer, the delay kernel over them, the hold floor and its
    gate filter (when the spec has the speed feature), the critically damped lag."""
    n, ys, yo = st.n, _num(st.y_sc), _num(st.y_off)
    kn, wn = w.vec(f"{ch}_knots", st.knots), w.vec(f"{ch}_mw", st.w)
    lam = w.vec(f"{ch}_lam", st.lam)
    r = f"{_num(st.d)} * (c - {_num(st.c_off)}) / {_num(st.c_sc)}"
    reset = (f"    double r = {_num(st.d)} * (c0 - {_num(st.c_off)}) / {_num(st.c_sc)};\n"
             + _monolag_map(ch, st, kn, wn, "r")
             + f"    for (int i = 0; i < {2 * n}; ++i) s->{ch}.buf[i] = m;\n"
             f"    s->{ch}.i = 0;\n    s->{ch}.gf = 0.0;\n"
             f"    s->{ch}.pos = (y0 - {yo}) / {ys};\n    s->{ch}.rate = 0.0;\n")
    hold = ""
    if st.hold:
        beta = _num(st.beta)
        hold = (f"    double fl = {_num(st.b)} + {_num(st.H)} * s->{ch}.gf;\n"
                "    if (fl > t) t = fl;\n"
                f"    double gate = (1.0 / (1.0 + exp(-{beta} * (r - {_num(st.r_h)})))) *\n"
                f"        (1.0 / (1.0 + exp(-({_num(st.v_h)} - fabs(vx)) / {_num(st.v_w)})));\n"
                f"    if (gate > s->{ch}.gf)\n"
                f"        s->{ch}.gf = {_num(st.a_on)} * s->{ch}.gf"
                f" + {_num(1.0 - st.a_on)} * gate;\n")
        if st.ramp:
            hold += (f"    else s->{ch}.gf = fmax(gate, s->{ch}.gf - {_num(st.off)});\n")
        else:
            hold += (f"    else s->{ch}.gf = {_num(st.off)} * s->{ch}.gf"
                     f" + {_num(1.0 - st.off)} * gate;\n")
    (a00, a01), (a10, a11) = st.A
    b0, b1 = st.Bv
    step = (f"    double r = {r};\n" + _monolag_map(ch, st, kn, wn, "r")
            + f"    int i = s->{ch}.i;\n"
            f"    s->{ch}.buf[i] = s->{ch}.buf[i + {n}] = m;\n"
            f"    i = s->{ch}.i = (i + 1) % {n};\n"
            f"    double t = 0.0;\n"
            f"    for (int j = 0; j < {n}; ++j) t += s->{ch}.buf[i + j] * {lam}[j];\n"
            + hold
            + f"    double p = s->{ch}.pos, q = s->{ch}.rate;\n"
            f"    double out = p * {ys} + {yo};\n"
            f"    s->{ch}.pos = {_num(a00)} * p + {_num(a01)} * q + {_num(b0)} * t;\n"
            f"    s->{ch}.rate = {_num(a10)} * p + {_num(a11)} * q + {_num(b1)} * t;\n"
            "    return out;\n")
    return reset, step


def _state_struct(rt: RealtimeChain) -> str:
    """The per-channel state fields of pk_chain."""
    fields = []
    for ch in CHANNELS:
        st = rt.steppers[ch]
        f = ["double y", "double pos", "double rate"]
        if isinstance(st, NARXStepper | MonoLagStepper):
            f += [f"double buf[{2 * st.n}]", "int i", "double gf"]
        if isinstance(st, GRUStepper):
            f += [f"double h[{st.H}]", f"double c[{st.H}]"]
        fields.append("    struct { " + "; ".join(f) + f"; }} {ch};")
    return "\n".join(fields)


_RUNTIME = r"""
/* ---------------------------------------------------------------- vector arithmetic
   GCC/Clang vector extensions: 64-byte vectors when the build targets AVX-512, 32 with
   AVX, else 16 (SSE2, NEON). Only IEEE basic operations (+ - * /, comparisons, bit
   masks), never contracted (C99) nor reassociated, so every build gives the same bits. */
#if defined(__AVX512F__)
#define PK_VB 64
#elif defined(__AVX__)
#define PK_VB 32
#else
#define PK_VB 16
#endif
#define PK_VW (PK_VB / 8)
typedef double pk_vec __attribute__((vector_size(PK_VB), aligned(8)));
typedef long long pk_ivec __attribute__((vector_size(PK_VB), aligned(8)));
#define PK_SPLAT(v) ((pk_vec){0} + (v))
#define PK_ISPLAT(v) ((pk_ivec){0} + (v))
#define PK_SELECT(m, a, b) ((pk_vec)(((m) & (pk_ivec)(a)) | (~(m) & (pk_ivec)(b))))

/* e^y for 0 <= y <= 40 (or NaN): y = n ln2 + r, |r| <= ln2/2 (Cody-Waite, ln2 in two
   parts), e^r by its Taylor series to r^13 (truncation < 1e-17 relative), 2^n by the
   exponent bits. */
static inline pk_vec pk_exp_v(pk_vec y) {
    const double shift = 6755399441055744.0;  /* 1.5 * 2^52: t - shift rounds to n */
    pk_vec t = y * 1.4426950408889634 + shift;
    pk_vec n = t - shift;
    pk_vec r = y - n * 6.93147180369123816490e-01;
    r = r - n * 1.90821492927058770002e-10;
    pk_vec p = PK_SPLAT(1.0 / 6227020800.0);
    p = p * r + 1.0 / 479001600.0;
    p = p * r + 1.0 / 39916800.0;
    p = p * r + 1.0 / 3628800.0;
    p = p * r + 1.0 / 362880.0;
    p = p * r + 1.0 / 40320.0;
    p = p * r + 1.0 / 5040.0;
    p = p * r + 1.0 / 720.0;
    p = p * r + 1.0 / 120.0;
    p = p * r + 1.0 / 24.0;
    p = p * r + 1.0 / 6.0;
    p = p * r + 0.5;
    p = p * r + 1.0;
    p = p * r + 1.0;
    pk_ivec e = ((pk_ivec)t - 0x4338000000000000LL + 1023) << 52;
    return p * (pk_vec)e;
}

/* tanh from basic operations only (no libm: the same bits on every machine and build),
   within 1.4 ulp of the exact value (glibc's within 2, NumPy's SIMD one 1.2; the three
   differ in the last bit or two). |x| < 0.625: x + x·z·P(z)/Q(z), z = x², the
   rational approximation of Cephes' tanh; else 1 - 2/(e^{2|x|} + 1) with 2|x| capped at
   40 (tanh is 1 to double precision from |x| = 19.1); the sign of x copied last (odd,
   -0 kept, NaN passed). */
static inline pk_vec pk_tanh_small(pk_vec a, pk_vec z) {
    pk_vec num = (z * -9.64399179425052238628e-1 - 9.92877231001918586564e1) * z
                 - 1.61468768441708447952e3;
    pk_vec den = ((z + 1.12811678491632931402e2) * z + 2.23548839060100448583e3) * z
                 + 4.84406305325125486048e3;
    return a + a * z * (num / den);
}

static inline pk_vec pk_tanh_big(pk_vec a) {
    pk_vec y = PK_SELECT((pk_ivec)(a > PK_SPLAT(20.0)), PK_SPLAT(40.0), a * 2.0);
    return 1.0 - 2.0 / (pk_exp_v(y) + 1.0);
}

/* (a vector whose lanes all take one branch computes that branch only: same bits) */
static inline pk_vec pk_tanh_v(pk_vec x) {
    const pk_ivec sgn = PK_ISPLAT(-0x7fffffffffffffffLL - 1);  /* the sign bit */
    pk_ivec xi = (pk_ivec)x;
    pk_vec a = (pk_vec)(xi & ~sgn), z = a * a, r;
    pk_ivec m = (pk_ivec)(a < PK_SPLAT(0.625));
    long long any = 0, all = -1;
    for (int k = 0; k < PK_VW; ++k) { any |= m[k]; all &= m[k]; }
    if (all) r = pk_tanh_small(a, z);
    else if (!any) r = pk_tanh_big(a);
    else r = PK_SELECT(m, pk_tanh_small(a, z), pk_tanh_big(a));
    return (pk_vec)((pk_ivec)r | (xi & sgn));
}

/* y[0:n] = tanh(y[0:n]), whole vectors then a zero-padded last one (same lanes' bits) */
static void pk_tanh_n(double *y, int n) {
    int j = 0;
    for (; j + PK_VW <= n; j += PK_VW) *(pk_vec *)(y + j) = pk_tanh_v(*(const pk_vec *)(y + j));
    if (j < n) {
        pk_vec t = {0};
        for (int k = 0; j + k < n; ++k) t[k] = y[j + k];
        t = pk_tanh_v(t);
        for (int k = 0; j + k < n; ++k) y[j + k] = t[k];
    }
}

static double pk_tanh(double x) { pk_vec t = {0}; t[0] = x; return pk_tanh_v(t)[0]; }
static double pk_sigmoid(double x) { return 1.0 / (1.0 + exp(-x)); }

/* ---------------------------------------------------------------- matrix-vector
   y (n_out) = W x with W stored transposed (n_in, n_out): every output summed over the
   input in order from 0.0 (no sum reassociated), so each kernel below gives the plain
   loop's bits. Blocks of outputs are summed in vector registers over the whole input
   before they are stored; pk_matvec2 sums two chains' inputs against each weight load
   (pk_step_many). */
#define PK_NV 8
#define PK_BLK (PK_NV * PK_VW)
#define PK_NV2 4
#define PK_BLK2 (PK_NV2 * PK_VW)
/* y[j], j0 <= j < j1, of y = W x (W transposed, rows of n_out) */
static void pk_matvec_part(const double *wt, int n_in, int n_out, int j0, int j1,
                           const double *x, double *y) {
    for (; j0 + PK_BLK <= j1; j0 += PK_BLK) {
        pk_vec acc[PK_NV];
        for (int v = 0; v < PK_NV; ++v) acc[v] = (pk_vec){0};
        for (int i = 0; i < n_in; ++i) {
            const double xi = x[i];
            const pk_vec *w = (const pk_vec *)(wt + (long)i * n_out + j0);
            for (int v = 0; v < PK_NV; ++v) acc[v] += w[v] * xi;
        }
        for (int v = 0; v < PK_NV; ++v) ((pk_vec *)(y + j0))[v] = acc[v];
    }
    for (; j0 + PK_VW <= j1; j0 += PK_VW) {
        pk_vec acc = {0};
        for (int i = 0; i < n_in; ++i)
            acc += *(const pk_vec *)(wt + (long)i * n_out + j0) * x[i];
        *(pk_vec *)(y + j0) = acc;
    }
    for (int j = j0; j < j1; ++j) y[j] = 0.0;
    for (int i = 0; i < n_in; ++i) {
        const double xi = x[i];
        const double *w = wt + (long)i * n_out;
        for (int j = j0; j < j1; ++j) y[j] += w[j] * xi;
    }
}

static void pk_matvec(const double *wt, int n_in, int n_out, const double *x, double *y) {
    pk_matvec_part(wt, n_in, n_out, 0, n_out, x, y);
}

/* pk_matvec of two inputs x, x + xs into y, y + ys, each weight load used for both */
static void pk_matvec2(const double *wt, int n_in, int n_out, const double *x, int xs,
                       double *y, int ys) {
    int j0 = 0;
    for (; j0 + PK_BLK2 <= n_out; j0 += PK_BLK2) {
        pk_vec a0[PK_NV2], a1[PK_NV2];
        for (int v = 0; v < PK_NV2; ++v) a0[v] = a1[v] = (pk_vec){0};
        for (int i = 0; i < n_in; ++i) {
            const double x0 = x[i], x1 = x[xs + i];
            const pk_vec *w = (const pk_vec *)(wt + (long)i * n_out + j0);
            for (int v = 0; v < PK_NV2; ++v) { a0[v] += w[v] * x0; a1[v] += w[v] * x1; }
        }
        for (int v = 0; v < PK_NV2; ++v) {
            ((pk_vec *)(y + j0))[v] = a0[v];
            ((pk_vec *)(y + ys + j0))[v] = a1[v];
        }
    }
    pk_matvec_part(wt, n_in, n_out, j0, n_out, x, y);
    pk_matvec_part(wt, n_in, n_out, j0, n_out, x + xs, y + ys);
}

/* The tanh perceptron of nb inputs z (nb, n_z) at once, layer by layer: out (nb, n_o). */
#define PK_BATCH 16
static void pk_mlp_many(const pk_layer *L, int n, int nb, const double *z, int n_z,
                        double *out, int n_o) {
    double a[PK_BATCH * PK_MAXW], b[PK_BATCH * PK_MAXW];
    const double *h = z;
    int hs = n_z;
    for (int l = 0; l < n; ++l) {
        int last = l == n - 1, ys = last ? n_o : PK_MAXW, q = 0;
        double *y = last ? out : ((l % 2) ? b : a);
        for (; q + 2 <= nb; q += 2)
            pk_matvec2(L[l].wt, L[l].n_in, L[l].n_out, h + q * hs, hs, y + q * ys, ys);
        if (q < nb) pk_matvec(L[l].wt, L[l].n_in, L[l].n_out, h + q * hs, y + q * ys);
        for (q = 0; q < nb; ++q) {
            double *yq = y + q * ys;
            for (int j = 0; j < L[l].n_out; ++j) yq[j] += L[l].b[j];
            if (!last) pk_tanh_n(yq, L[l].n_out);
        }
        h = y;
        hs = ys;
    }
}

/* The tanh perceptron: tanh(W h + b) per hidden layer, a linear head. */
static void pk_mlp(const pk_layer *L, int n, const double *z, double *out) {
    double a[PK_MAXW], b[PK_MAXW];
    const double *h = z;
    for (int l = 0; l < n; ++l) {
        double *y = (l == n - 1) ? out : ((l % 2) ? b : a);
        pk_matvec(L[l].wt, L[l].n_in, L[l].n_out, h, y);
        for (int j = 0; j < L[l].n_out; ++j) y[j] += L[l].b[j];
        if (l < n - 1) pk_tanh_n(y, L[l].n_out);
        h = y;
    }
}
"""


def chain_c_source(rt: RealtimeChain, name: str = "parknss chain") -> CSource:
    """The C files of ``rt`` (a full chain: every channel modelled); see the module doc."""
    if not rt.full:
        raise CheckpointError("C generation needs a chain with all three submodels")
    nss, env = rt.nss, rt.env.env
    w = _Writer()
    st_tab, out_tab = w.mlp("NSS_F", nss.state), w.mlp("NSS_G", nss.output)
    funcs = []
    for ch in CHANNELS:
        reset, step = _stepper(ch, rt.steppers[ch], rt.specs[ch].features, w)
        funcs.append(f"static void {ch}_reset(pk_chain *s, double c0, double y0) {{\n"
                     f"    (void)c0; (void)y0;\n{reset}}}\n"
                     f"static double {ch}_step(pk_chain *s, double c, double vx, double yaw, "
                     f"double g) {{\n    (void)vx; (void)yaw; (void)g;\n{step}}}\n")
    rule = rt.shift
    if math.isfinite(env.stop_latch_bar):
        raise CheckpointError("the native engine does not implement the brake-stop latch")
    consts = {
        "DT": DT, "NSS_DT": nss.dt, "WHEELBASE": nss.L, "RATIO": nss.ratio,
        "DEG2RAD": math.pi / 180.0,
        "STEER_STEP": env.steer_rate_dps * DT, "STEER_LOCK": env.steer_lock,
        "TORQUE_FLOOR": env.torque_floor, "PRESSURE_FLOOR": env.pressure_floor,
        "SHIFT_SPEED": rule.max_speed if rule else math.inf,
        "LATCH_BAR": env.hold_latch_bar, "LATCH_SPEED": kmh_to_ms(env.hold_latch_kmh),
    }
    vecs = {
        "CMD_LO": env.cmd_lo, "CMD_HI": env.cmd_hi, "IN_OFF": nss.in_off, "IN_SC": nss.in_sc,
        "IN_LO": nss.in_lo, "IN_HI": nss.in_hi, "ST_OFF": nss.st_off, "ST_SC": nss.st_sc,
        "ST_LO": nss.st_lo, "ST_HI": nss.st_hi, "OUT_OFF": nss.out_off, "OUT_SC": nss.out_sc,
    }
    for k, v in vecs.items():
        w.vec(k, v)
    header = _HEADER.format(name=name, nout=len(OUTPUTS), fields=_state_struct(rt))
    body = "".join(f"static const double {k} = {_num(v)};\n" for k, v in consts.items())
    source = _SOURCE.format(
        name=name, maxw=w.max_width, consts=body, data="".join(w.data), runtime=_RUNTIME,
        funcs="\n".join(funcs), st_tab=st_tab, n_st=len(nss.state), out_tab=out_tab,
        n_out=len(nss.output), residual=int(nss.residual), shift=int(rule is not None),
        n_shift=rule.n_shift if rule else 0,
    )
    return CSource(header, source)


_HEADER = """/* {name}: the chain's 10 ms step, generated by parknss (parknss.chain.ccode). */
#ifndef PK_CHAIN_H
#define PK_CHAIN_H
#include <stddef.h>
#define PK_NOUT {nout}

typedef struct {{
    double last[3], gear_req, steer_prev;   /* input and output envelopes */
    double gear; int shifting, count;       /* the gear rule */
    long refused, waited, shifts;
    double x0[2], x[2], vx_now, yaw_prev;   /* the NSS */
    int started;
{fields}
}} pk_chain;

size_t pk_size(void);
void pk_start(pk_chain *s, const double x0[2], const double y0[3], const double cmd0[4]);
void pk_step(pk_chain *s, const double cmd[4], double out[PK_NOUT]);
void pk_step_many(pk_chain *const *s, long n, const double *cmds, double *out);
void pk_run(pk_chain *s, const double *cmds, long n, double *out);
void pk_tanh_array(long n, const double *x, double *y);
#endif
"""

_SOURCE = """/* {name}: the chain's 10 ms step, generated by parknss (parknss.chain.ccode).
   Weights and scalings are the artefact's, as exact double literals. Do not edit. */
#include <math.h>
#include <string.h>
#include "pk_chain.h"

#define PK_MAXW {maxw}
typedef struct {{ int n_in, n_out; const double *wt, *b; }} pk_layer;

{consts}
{data}
{runtime}
/* ---------------------------------------------------------------- the envelopes */
static double pk_command(pk_chain *s, double gear, const double *in, double *c) {{
    if (isfinite(gear)) s->gear_req = gear;
    for (int i = 0; i < 3; ++i) {{
        double v = in[i];
        if (isnan(v)) v = s->last[i];
        if (v < CMD_LO[i] || v > CMD_HI[i]) v = v < CMD_LO[i] ? CMD_LO[i] : CMD_HI[i];
        s->last[i] = v;
        c[i] = v;
    }}
    return s->gear_req;
}}

static void pk_output(pk_chain *s, double *y) {{
    if (y[0] < TORQUE_FLOOR) y[0] = TORQUE_FLOOR;
    if (y[1] < PRESSURE_FLOOR) y[1] = PRESSURE_FLOOR;
    double lo = s->steer_prev - STEER_STEP, hi = s->steer_prev + STEER_STEP, st = y[2];
    if (st < lo || st > hi) st = st < lo ? lo : hi;
    if (fabs(st) > STEER_LOCK) st = copysign(STEER_LOCK, st);
    s->steer_prev = st;
    y[2] = st;
}}

static void pk_env_reset(pk_chain *s, double steer, double gear) {{
    s->last[0] = 0.0; s->last[1] = 0.0; s->last[2] = steer;
    s->gear_req = gear;
    s->steer_prev = steer;
}}

/* ---------------------------------------------------------------- the gear rule */
static double pk_shift(pk_chain *s, double request, double vx) {{
    if (!{shift}) return request;
    if (request == s->gear) {{ s->shifting = 0; s->count = 0; }}
    else if (fabs(vx) > SHIFT_SPEED) {{ s->shifting = 0; s->count = 0; s->refused += 1; }}
    else {{
        s->shifting = 1; s->waited += 1; s->count += 1;
        if (s->count >= {n_shift}) {{ s->gear = request; s->shifting = 0; s->count = 0;
                                       s->shifts += 1; }}
    }}
    return s->gear;
}}

/* ---------------------------------------------------------------- the submodels */
{funcs}
/* ---------------------------------------------------------------- the NSS */
static void pk_scale_u(const double *u, double *us) {{
    for (int i = 0; i < 4; ++i) {{
        double v = u[i] < IN_LO[i] ? IN_LO[i] : u[i];
        v = v > IN_HI[i] ? IN_HI[i] : v;
        us[i] = (v - IN_OFF[i]) / IN_SC[i];
    }}
}}

static double pk_yaw_ref(double vx_s, double steer_s) {{
    double vx = vx_s * ST_SC[0] + ST_OFF[0];
    double steer = steer_s * IN_SC[3] + IN_OFF[3];
    return vx / WHEELBASE * tan(steer / RATIO * DEG2RAD);
}}

/* (scaled reconstructed yaw, physical yaw) at state x and scaled steering */
static double pk_yaw(const double *x, double steer_s, double *phys) {{
    double ys = x[1];
    if ({residual}) ys = (pk_yaw_ref(x[0], steer_s) - ST_OFF[1]) / ST_SC[1] + x[1];
    *phys = ys * ST_SC[1] + ST_OFF[1];
    return ys;
}}

static void pk_set_state(pk_chain *s, const double x0[2], const double *us) {{
    double x0s[2];
    for (int i = 0; i < 2; ++i) {{
        double v = x0[i] > ST_LO[i] ? x0[i] : ST_LO[i];
        v = v < ST_HI[i] ? v : ST_HI[i];
        x0s[i] = (v - ST_OFF[i]) / ST_SC[i];
    }}
    s->x[0] = x0s[0];
    s->x[1] = x0s[1];
    if ({residual}) s->x[1] = x0s[1] - (pk_yaw_ref(x0s[0], us[3]) - ST_OFF[1]) / ST_SC[1];
}}

static void pk_initial(pk_chain *s, const double *us) {{ pk_set_state(s, s->x0, us); }}

/* ---------------------------------------------------------------- the interface */
size_t pk_size(void) {{ return sizeof(pk_chain); }}

void pk_start(pk_chain *s, const double x0[2], const double y0[3], const double cmd0[4]) {{
    memset(s, 0, sizeof(*s));
    double c[3], g0 = isfinite(cmd0[0]) ? cmd0[0] : 0.0;
    pk_env_reset(s, y0[2], g0);
    double g = pk_command(s, g0, cmd0 + 1, c);
    pk_env_reset(s, y0[2], g);
    s->gear = g;
    drive_reset(s, c[0], y0[0]);
    brake_reset(s, c[1], y0[1]);
    steering_reset(s, c[2], y0[2]);
    s->x0[0] = x0[0]; s->x0[1] = x0[1];
    s->started = 0;
    s->yaw_prev = x0[1];
    s->vx_now = x0[0];
}}

/* One step in three phases, so that pk_step_many can run the two NSS networks of a
   batch of chains layer by layer (each layer's weights read once for the batch):
   pk_pre (commands, gear rule, submodels, envelopes: the networks' inputs), the
   networks, pk_post (outputs, Euler step, latch). Per chain the arithmetic is pk_step's. */
typedef struct {{ double y[3], us[4], g, yaw_phys; }} pk_ctx;

static void pk_pre(pk_chain *s, const double cmd[4], pk_ctx *t, double h[5], double z[6]) {{
    double c[3], u[4], *y = t->y, *us = t->us;
    double request = pk_command(s, cmd[0], cmd + 1, c);
    double vx = s->vx_now, yaw = s->yaw_prev;
    double g = pk_shift(s, request, vx);
    if ({shift} && s->shifting) c[0] = 0.0;
    y[0] = drive_step(s, c[0], vx, yaw, g);
    y[1] = brake_step(s, c[1], vx, yaw, g);
    y[2] = steering_step(s, c[2], vx, yaw, g);
    pk_output(s, y);
    u[0] = g; u[1] = y[0]; u[2] = y[1]; u[3] = y[2];
    pk_scale_u(u, us);
    if (!s->started) {{ pk_initial(s, us); s->started = 1; }}
    double ys = pk_yaw(s->x, us[3], &t->yaw_phys);
    h[0] = s->x[0]; h[1] = ys; h[2] = us[1]; h[3] = us[2]; h[4] = us[3];
    z[0] = s->x[0]; z[1] = s->x[1];
    for (int i = 0; i < 4; ++i) z[2 + i] = us[i];
    t->g = g;
}}

static void pk_post(pk_chain *s, const pk_ctx *t, const double o[2], const double f[2],
                    double out[PK_NOUT]) {{
    const double *y = t->y, *us = t->us;
    out[0] = y[0]; out[1] = y[1]; out[2] = y[2];
    out[3] = s->x[0] * ST_SC[0] + ST_OFF[0];
    out[4] = t->yaw_phys;
    out[5] = o[0] * OUT_SC[0] + OUT_OFF[0];
    out[6] = o[1] * OUT_SC[1] + OUT_OFF[1];
    out[7] = t->g;
    s->x[0] = s->x[0] + NSS_DT * f[0];
    s->x[1] = s->x[1] + NSS_DT * f[1];
    if ({shift} && y[1] >= LATCH_BAR && fabs(s->x[0] * ST_SC[0] + ST_OFF[0]) < LATCH_SPEED) {{
        static const double rest[2] = {{0.0, 0.0}};  /* the brake-hold latch */
        pk_set_state(s, rest, us);
    }}
    s->vx_now = s->x[0] * ST_SC[0] + ST_OFF[0];
    pk_yaw(s->x, us[3], &s->yaw_prev);
}}

void pk_step_many(pk_chain *const *s, long n, const double *cmds, double *out) {{
    pk_ctx t[PK_BATCH];
    double h[PK_BATCH * 5], z[PK_BATCH * 6], o[PK_BATCH * 2], f[PK_BATCH * 2];
    for (long k0 = 0; k0 < n; k0 += PK_BATCH) {{
        int nb = (int)(n - k0 < PK_BATCH ? n - k0 : PK_BATCH);
        for (int q = 0; q < nb; ++q)
            pk_pre(s[k0 + q], cmds + 4 * (k0 + q), &t[q], h + 5 * q, z + 6 * q);
        pk_mlp_many({out_tab}, {n_out}, nb, h, 5, o, 2);
        pk_mlp_many({st_tab}, {n_st}, nb, z, 6, f, 2);
        for (int q = 0; q < nb; ++q)
            pk_post(s[k0 + q], &t[q], o + 2 * q, f + 2 * q, out + PK_NOUT * (k0 + q));
    }}
}}

void pk_step(pk_chain *s, const double cmd[4], double out[PK_NOUT]) {{
    pk_step_many(&s, 1, cmd, out);
}}

void pk_run(pk_chain *s, const double *cmds, long n, double *out) {{
    for (long k = 0; k < n; ++k) pk_step(s, cmds + 4 * k, out + PK_NOUT * k);
}}

void pk_tanh_array(long n, const double *x, double *y) {{
    if (y != x) memmove(y, x, (size_t)(n > 0 ? n : 0) * sizeof(double));
    for (long k = 0; k < n; k += 4096) pk_tanh_n(y + k, (int)(n - k < 4096 ? n - k : 4096));
}}
"""
