"""The FMI 2.0 co-simulation wrapper around the generated chain step (C text).

One instance holds a ``pk_chain`` (:mod:`parknss.chain.ccode`), the four inputs, the
initial-state parameters and the rear-axle pose. ``fmi2ExitInitializationMode`` starts the
chain (:meth:`~parknss.chain.realtime.RealtimeChain.start`) from the parameters, the
inputs at that moment filling the command histories and giving the first engaged gear.
``fmi2DoStep`` accepts any communication step that is a whole number n >= 1 of 10 ms
(within 1e-9 s) and runs n chain samples under the inputs held over the step; the outputs
after it are those of the last sample. The pose moves as the closed loop moves the chain
plant (:class:`parknss.sim.plants.ChainPlant`): along the exact arc
(:func:`parknss.vehicle.arc_step`) at the mean of the previous and this sample's vx and
yaw rate. The FMI headers are FMPy's (``fmpy/c-code``), never copied here.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Var:
    """One FMI variable: value reference, name, causality, description (with its unit)."""

    vr: int
    name: str
    causality: str
    description: str
    start: float | None = None


INPUTS: tuple[Var, ...] = (
    Var(0, "gear", "input", "gear request: -1 reverse, 0 neutral/park, 1 drive (NaN: hold)",
        0.0),
    Var(1, "torque_cmd", "input", "motor torque command, N.m", 0.0),
    Var(2, "decel_cmd", "input", "deceleration command a_x* (<= 0), m/s2", 0.0),
    Var(3, "steer_cmd", "input", "steering-wheel angle request, deg", 0.0),
)
OUTPUTS: tuple[Var, ...] = (
    Var(10, "torque", "output", "motor torque actual, N.m"),
    Var(11, "brake_pressure", "output", "master-cylinder pressure, bar"),
    Var(12, "steer", "output", "steering-wheel angle actual, deg"),
    Var(13, "vx", "output", "longitudinal velocity (signed), m/s"),
    Var(14, "yaw_rate", "output", "yaw rate, rad/s"),
    Var(15, "ax", "output", "longitudinal acceleration (IMU), m/s2"),
    Var(16, "ay", "output", "lateral acceleration (IMU), m/s2"),
    Var(17, "gear_engaged", "output", "engaged gear (the shift-by-wire rule)"),
    Var(18, "x", "output", "rear-axle position x, m"),
    Var(19, "y", "output", "rear-axle position y, m"),
    Var(20, "heading", "output", "heading (not wrapped), rad"),
)
PARAMETERS: tuple[Var, ...] = (
    Var(30, "vx0", "parameter", "initial longitudinal velocity, m/s", 0.0),
    Var(31, "yaw_rate0", "parameter", "initial yaw rate, rad/s", 0.0),
    Var(32, "torque0", "parameter", "initial motor torque, N.m", 0.0),
    Var(33, "brake_pressure0", "parameter", "initial brake pressure, bar", 0.0),
    Var(34, "steer0", "parameter", "initial steering-wheel angle, deg", 0.0),
    Var(35, "x0", "parameter", "initial rear-axle x, m", 0.0),
    Var(36, "y0", "parameter", "initial rear-axle y, m", 0.0),
    Var(37, "heading0", "parameter", "initial heading, rad", 0.0),
)
VARIABLES: tuple[Var, ...] = (*INPUTS, *OUTPUTS, *PARAMETERS)


def wrapper_source(guid: str) -> str:
    """The C of the FMI 2.0 co-simulation interface for the chain with ``guid``."""
    return _WRAPPER.replace("@GUID@", guid)


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

typedef struct {
    pk_chain chain;
    fmi2CallbackFunctions cb;
    char name[256];
    fmi2Boolean logging;
    double v[N_VR];        /* every variable by value reference */
    double prev_vx, prev_yaw;
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
    return vr <= 3 || (vr >= 10 && vr <= 20) || (vr >= 30 && vr <= 37);
}

static void defaults(Instance *c) {
    memset(c->v, 0, sizeof c->v);
    c->initialised = 0;
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
        if (!known(vr[i])) { logmsg(s, fmi2Error, "error", "unknown value reference %u", vr[i]);
                             return fmi2Error; }
        v[i] = s->v[vr[i]];
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                       const fmi2Real v[]) {
    Instance *s = (Instance *)c;
    for (size_t i = 0; i < n; ++i) {
        fmi2ValueReference r = vr[i];
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
    (void)vr; (void)v; return n ? none(c, "integers") : fmi2OK; }
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                          fmi2Boolean v[]) {
    (void)vr; (void)v; return n ? none(c, "booleans") : fmi2OK; }
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                         fmi2String v[]) {
    (void)vr; (void)v; return n ? none(c, "strings") : fmi2OK; }
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                          const fmi2Integer v[]) {
    (void)vr; (void)v; return n ? none(c, "integers") : fmi2OK; }
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
