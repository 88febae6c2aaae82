"""The FMI 2.0 co-simulation wrapper around the generated chain step (C text).

One instance holds a ``pk_chain`` (:mod:`parknss.chain.ccode`), the four inputs, the
initial-state parameters and the rear-axle pose. ``fmi2ExitInitializationMode`` starts the
chain (:meth:`~parknss.chain.realtime.RealtimeChain.start`) from the parameters, the
inputs at that moment filling the command histories and giving the first engaged gear.
``fmi2DoStep`` accepts any communication step that is a whole number n >= 1 of 10 ms
(within 1e-9 s) and runs n chain samples under the inputs held over the step; the outputs
after it are those of the last sample. ``gear`` and ``gear_engaged`` are FMI Integers
(-1, 0, 1; another value is an fmi2Error), every other variable a Real with its unit.

**The identified domain.** Each sample checks the commands against the chain's input
domain (the envelope's clamp, :class:`~parknss.actuators.envelopes.Envelope`) and the
predicted vx and yaw rate against the range of the data the NSS was identified on (its
normaliser's clip range, widened by ``domain_margin`` of its span on each side,
:class:`parknss.export.config.FmuConfig`). Outside it the output ``in_domain`` is 0 and
``domain_exits`` counts the samples so far; the first sample of every excursion logs one
fmi2Warning line naming the variable, its value, the range and what the chain does there
(a command: clamped; a state: extrapolated). The pose moves as the closed loop moves the chain
plant (:class:`parknss.sim.plants.ChainPlant`): along the exact arc
(:func:`parknss.vehicle.arc_step`) at the mean of the previous and this sample's vx and
yaw rate. The FMI headers are FMPy's (``fmpy/c-code``), never copied here.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Var:
    """One FMI variable: value reference, name, causality, description, unit (a name of
    :data:`UNITS`; None: dimensionless), FMI type ("Real" or "Integer"), start value."""

    vr: int
    name: str
    causality: str
    description: str
    start: float | None = None
    unit: str | None = None
    type: str = "Real"


UNITS: dict[str, tuple[dict[str, int], float]] = {
    "N.m": ({"kg": 1, "m": 2, "s": -2}, 1.0),
    "bar": ({"kg": 1, "m": -1, "s": -2}, 1.0e5),
    "deg": ({"rad": 1}, 0.017453292519943295),
    "m/s": ({"m": 1, "s": -1}, 1.0),
    "m/s2": ({"m": 1, "s": -2}, 1.0),
    "rad/s": ({"rad": 1, "s": -1}, 1.0),
    "m": ({"m": 1}, 1.0),
    "rad": ({"rad": 1}, 1.0),
}
"""The FMI unit definitions: SI base-unit exponents and the factor to SI."""


INPUTS: tuple[Var, ...] = (
    Var(0, "gear", "input", "gear request: -1 reverse, 0 neutral/park, 1 drive", 0,
        type="Integer"),
    Var(1, "torque_cmd", "input", "motor torque command (NaN: hold)", 0.0, "N.m"),
    Var(2, "decel_cmd", "input", "deceleration command a_x* (<= 0; NaN: hold)", 0.0, "m/s2"),
    Var(3, "steer_cmd", "input", "steering-wheel angle request (NaN: hold)", 0.0, "deg"),
)
OUTPUTS: tuple[Var, ...] = (
    Var(10, "torque", "output", "motor torque actual", unit="N.m"),
    Var(11, "brake_pressure", "output", "master-cylinder pressure", unit="bar"),
    Var(12, "steer", "output", "steering-wheel angle actual", unit="deg"),
    Var(13, "vx", "output", "longitudinal velocity (signed)", unit="m/s"),
    Var(14, "yaw_rate", "output", "yaw rate", unit="rad/s"),
    Var(15, "ax", "output", "longitudinal acceleration (IMU)", unit="m/s2"),
    Var(16, "ay", "output", "lateral acceleration (IMU)", unit="m/s2"),
    Var(17, "gear_engaged", "output", "engaged gear (the shift-by-wire rule)", type="Integer"),
    Var(18, "x", "output", "rear-axle position x", unit="m"),
    Var(19, "y", "output", "rear-axle position y", unit="m"),
    Var(20, "heading", "output", "heading (not wrapped)", unit="rad"),
    Var(21, "in_domain", "output", "1 while the commands and vx, yaw rate are inside the "
        "identified domain, else 0", type="Integer"),
    Var(22, "domain_exits", "output", "samples so far outside the identified domain",
        type="Integer"),
)
PARAMETERS: tuple[Var, ...] = (
    Var(30, "vx0", "parameter", "initial longitudinal velocity", 0.0, "m/s"),
    Var(31, "yaw_rate0", "parameter", "initial yaw rate", 0.0, "rad/s"),
    Var(32, "torque0", "parameter", "initial motor torque", 0.0, "N.m"),
    Var(33, "brake_pressure0", "parameter", "initial brake pressure", 0.0, "bar"),
    Var(34, "steer0", "parameter", "initial steering-wheel angle", 0.0, "deg"),
    Var(35, "x0", "parameter", "initial rear-axle x", 0.0, "m"),
    Var(36, "y0", "parameter", "initial rear-axle y", 0.0, "m"),
    Var(37, "heading0", "parameter", "initial heading", 0.0, "rad"),
)
VARIABLES: tuple[Var, ...] = (*INPUTS, *OUTPUTS, *PARAMETERS)


INTEGER_VRS: tuple[int, ...] = tuple(v.vr for v in VARIABLES if v.type == "Integer")


@dataclass(frozen=True)
class Domain:
    """The identified domain the wrapper checks (see the module doc): command bounds
    [torque_cmd N.m, decel_cmd m/s², steer_cmd deg] and state bounds [vx m/s, yaw rad/s]."""

    cmd_lo: tuple[float, float, float]
    cmd_hi: tuple[float, float, float]
    state_lo: tuple[float, float]
    state_hi: tuple[float, float]


def _c(x: float) -> str:
    return repr(float(x)) if abs(x) != float("inf") else ("HUGE_VAL" if x > 0 else "-HUGE_VAL")


def wrapper_source(guid: str, domain: Domain) -> str:
    """The C of the FMI 2.0 co-simulation interface for the chain with ``guid``."""
    lo = [*domain.cmd_lo, *domain.state_lo]
    hi = [*domain.cmd_hi, *domain.state_hi]
    ints = " || ".join(f"vr == {v}" for v in INTEGER_VRS)
    return (_WRAPPER.replace("@GUID@", guid)
            .replace("@DOM_LO@", ", ".join(_c(x) for x in lo))
            .replace("@DOM_HI@", ", ".join(_c(x) for x in hi))
            .replace("@IS_INT@", ints))


_WRAPPER = r"""/* FMI 2.0 co-simulation wrapper of the parknss chain (parknss.export). */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"
#include "pk_chain.h"

#define GUID "@GUID@"
#define DT_STEP 0.01
#define N_VR 40

/* the identified domain: torque_cmd, decel_cmd, steer_cmd, vx, yaw rate */
static const double DOM_LO[5] = {@DOM_LO@};
static const double DOM_HI[5] = {@DOM_HI@};
static const char *DOM_NAME[5] = {"torque_cmd", "decel_cmd", "steer_cmd", "vx", "yaw_rate"};
static const char *DOM_UNIT[5] = {"N.m", "m/s2", "deg", "m/s", "rad/s"};

typedef struct {
    pk_chain chain;
    fmi2CallbackFunctions cb;
    char name[256];
    fmi2Boolean logging;
    double v[N_VR];        /* every variable by value reference */
    double prev_vx, prev_yaw;
    long samples;          /* samples run since the start */
    int outside[5];        /* inside an excursion of each domain variable */
    int initialised;
} Instance;

static void logmsg(Instance *c, fmi2Status st, const char *cat, const char *fmt, ...) {
    char buf[512];
    va_list ap;
    if (!c || !c->cb.logger) return;
    if (st == fmi2OK && !c->logging) return;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    c->cb.logger(c->cb.componentEnvironment, c->name, st, cat, "%s", buf);
}

static int known(fmi2ValueReference vr) {
    return vr <= 3 || (vr >= 10 && vr <= 22) || (vr >= 30 && vr <= 37);
}

static int is_integer(fmi2ValueReference vr) { return @IS_INT@; }

static void defaults(Instance *c) {
    memset(c->v, 0, sizeof c->v);
    memset(c->outside, 0, sizeof c->outside);
    c->samples = 0;
    c->initialised = 0;
}

/* in_domain / domain_exits, one warning line at the start of each excursion */
static void check_domain(Instance *c, const double val[5]) {
    int inside = 1;
    for (int i = 0; i < 5; ++i) {
        int out = !isnan(val[i]) && (val[i] < DOM_LO[i] || val[i] > DOM_HI[i]);
        if (out && !c->outside[i])
            logmsg(c, fmi2Warning, "domain",
                   "t = %.2f s: %s = %g %s outside the identified domain [%g, %g]: %s",
                   c->samples * DT_STEP, DOM_NAME[i], val[i], DOM_UNIT[i], DOM_LO[i],
                   DOM_HI[i], i < 3 ? "clamped to it" : "the chain extrapolates");
        c->outside[i] = out;
        inside = inside && !out;
    }
    c->v[21] = inside;
    if (!inside) c->v[22] += 1.0;
}

static void arc_step(double *x, double *y, double *h, double ds, double dh) {
    double half = 0.5 * dh;
    double chord = ds * (fabs(half) > 1e-12 ? sin(half) / half : 1.0 - half * half / 6.0);
    double ang = *h + half;
    *x = *x + chord * cos(ang);
    *y = *y + chord * sin(ang);
    *h = *h + dh;
}

static void start(Instance *c) {
    double x0[2] = {c->v[30], c->v[31]}, y0[3] = {c->v[32], c->v[33], c->v[34]};
    double cmd0[4] = {c->v[0], c->v[1], c->v[2], c->v[3]};
    pk_start(&c->chain, x0, y0, cmd0);
    c->v[10] = y0[0]; c->v[11] = y0[1]; c->v[12] = y0[2];
    c->v[13] = x0[0]; c->v[14] = x0[1]; c->v[15] = 0.0; c->v[16] = 0.0;
    c->v[17] = c->chain.gear;
    c->v[18] = c->v[35]; c->v[19] = c->v[36]; c->v[20] = c->v[37];
    c->v[21] = 1.0; c->v[22] = 0.0;
    c->prev_vx = x0[0];
    c->prev_yaw = x0[1];
    c->initialised = 1;
}

static void sample(Instance *c) {
    double cmd[4] = {c->v[0], c->v[1], c->v[2], c->v[3]}, out[PK_NOUT];
    pk_step(&c->chain, cmd, out);
    for (int i = 0; i < 8; ++i) c->v[10 + i] = out[i];
    double mv = 0.5 * (c->prev_vx + out[3]), mw = 0.5 * (c->prev_yaw + out[4]);
    c->prev_vx = out[3];
    c->prev_yaw = out[4];
    arc_step(&c->v[18], &c->v[19], &c->v[20], mv * DT_STEP, mw * DT_STEP);
    double dom[5] = {cmd[1], cmd[2], cmd[3], out[3], out[4]};
    check_domain(c, dom);
    c->samples += 1;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cats[]) {
    (void)n; (void)cats;
    ((Instance *)c)->logging = on;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid,
                              fmi2String location, const fmi2CallbackFunctions *cb,
                              fmi2Boolean visible, fmi2Boolean logging) {
    (void)location; (void)visible;
    if (!cb) return NULL;
    if (type != fmi2CoSimulation || !guid || strcmp(guid, GUID) != 0) {
        if (cb->logger) cb->logger(cb->componentEnvironment, name, fmi2Error, "error",
                                   "parknss chain: co-simulation only, GUID " GUID);
        return NULL;
    }
    Instance *c = (Instance *)calloc(1, sizeof(Instance));
    if (!c) return NULL;
    c->cb = *cb;
    c->logging = logging;
    snprintf(c->name, sizeof c->name, "%s", name ? name : "parknss_chain");
    defaults(c);
    return c;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDef, fmi2Real tol,
                               fmi2Real t0, fmi2Boolean stopDef, fmi2Real t1) {
    (void)c; (void)tolDef; (void)tol; (void)t0; (void)stopDef; (void)t1;
    return fmi2OK;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { start((Instance *)c); return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { defaults((Instance *)c); return fmi2OK; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    Instance *s = (Instance *)c;
    for (size_t i = 0; i < n; ++i) {
        if (!known(vr[i]) || is_integer(vr[i])) {
            logmsg(s, fmi2Error, "error", "no Real with value reference %u", vr[i]);
            return fmi2Error;
        }
        v[i] = s->v[vr[i]];
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                       const fmi2Real v[]) {
    Instance *s = (Instance *)c;
    for (size_t i = 0; i < n; ++i) {
        fmi2ValueReference r = vr[i];
        if (is_integer(r)) {
            logmsg(s, fmi2Error, "error", "value reference %u is an Integer", r);
            return fmi2Error;
        }
        if (r <= 3 || (r >= 30 && r <= 37 && !s->initialised)) { s->v[r] = v[i]; continue; }
        logmsg(s, fmi2Error, "error", "value reference %u cannot be set now", r);
        return fmi2Error;
    }
    return fmi2OK;
}

static fmi2Status none(fmi2Component c, const char *what) {
    logmsg((Instance *)c, fmi2Error, "error", "%s: not supported", what);
    return fmi2Error;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                          fmi2Integer v[]) {
    Instance *s = (Instance *)c;
    for (size_t i = 0; i < n; ++i) {
        if (!is_integer(vr[i])) {
            logmsg(s, fmi2Error, "error", "no Integer with value reference %u", vr[i]);
            return fmi2Error;
        }
        v[i] = (fmi2Integer)lround(s->v[vr[i]]);
    }
    return fmi2OK;
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                          fmi2Boolean v[]) {
    (void)vr; (void)v; return n ? none(c, "booleans") : fmi2OK; }
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                         fmi2String v[]) {
    (void)vr; (void)v; return n ? none(c, "strings") : fmi2OK; }
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                          const fmi2Integer v[]) {
    Instance *s = (Instance *)c;
    for (size_t i = 0; i < n; ++i) {
        if (vr[i] != 0) {
            logmsg(s, fmi2Error, "error", "Integer value reference %u cannot be set", vr[i]);
            return fmi2Error;
        }
        if (v[i] < -1 || v[i] > 1) {
            logmsg(s, fmi2Error, "error", "gear %d: expected -1, 0 or 1", (int)v[i]);
            return fmi2Error;
        }
        s->v[0] = (double)v[i];
    }
    return fmi2OK;
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                          const fmi2Boolean v[]) {
    (void)vr; (void)v; return n ? none(c, "booleans") : fmi2OK; }
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                         const fmi2String v[]) {
    (void)vr; (void)v; return n ? none(c, "strings") : fmi2OK; }

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) {
    (void)s; return none(c, "FMU state"); }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) {
    (void)s; return none(c, "FMU state"); }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) {
    (void)s; return none(c, "FMU state"); }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) {
    (void)s; (void)n; return none(c, "FMU state"); }
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) {
    (void)s; (void)b; (void)n; return none(c, "FMU state"); }
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) {
    (void)s; (void)b; (void)n; return none(c, "FMU state"); }
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz,
                                        const fmi2Real dv[], fmi2Real dz[]) {
    (void)u; (void)nu; (void)z; (void)nz; (void)dv; (void)dz;
    return none(c, "directional derivatives"); }
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer o[], const fmi2Real v[]) {
    (void)vr; (void)n; (void)o; (void)v; return none(c, "input derivatives"); }
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer o[], fmi2Real v[]) {
    (void)vr; (void)n; (void)o; (void)v; return none(c, "output derivatives"); }

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noPrior) {
    Instance *s = (Instance *)c;
    (void)t; (void)noPrior;
    if (!s->initialised) start(s);
    long n = lround(h / DT_STEP);
    if (n < 1 || fabs(h - n * DT_STEP) > 1e-9) {
        logmsg(s, fmi2Error, "error",
               "communication step %g s is not a whole number of 10 ms steps", h);
        return fmi2Error;
    }
    for (long k = 0; k < n; ++k) sample(s);
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind k, fmi2Status *v) {
    (void)k; (void)v; return none(c, "status"); }
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *v) {
    (void)k; (void)v; return none(c, "status"); }
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind k, fmi2Integer *v) {
    (void)k; (void)v; return none(c, "status"); }
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v) {
    (void)k; (void)v; return none(c, "status"); }
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind k, fmi2String *v) {
    (void)k; (void)v; return none(c, "status"); }
"""
