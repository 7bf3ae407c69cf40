/* FMI 2.0 Model Exchange and Co-Simulation for a bgc model (the model file, generated
   from templates/model.c.j2, defines bgc_the_model).

   Value references: states 0..n-1, their derivatives n..2n-1, outputs 2n..2n+ny-1,
   parameters after them, inputs last (each an entry of the parameter array).
   Model Exchange: derivatives from the rhs kernel, the exact Jacobian (the jac kernel)
   in fmi2GetDirectionalDerivative for derivatives against states (central differences
   otherwise), time events at the signals' breakpoints, event indicators from the
   model's switching functions. Co-Simulation: bgc's Radau (radau.py), the run split at
   the breakpoints as bgc simulate splits it. */

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bgc_fmu.h"
#include "fmi2Functions.h"

enum { ST_INSTANTIATED, ST_INIT, ST_RUN, ST_TERMINATED, ST_ERROR };

typedef struct {
    const bgc_model *m;
    fmi2CallbackFunctions cb;
    char *name;
    fmi2Type type;
    int logging, state;
    double t, t_start, rtol, atol, h_next, t_stop, t_int, t_prev, h_max;
    double *x_int, *x_prev;
    int going;                          /* the integrator goes on from (t_int, x_int) */
    double *x, *p, *w, *dx, *y, *ind, *J, *v, *nominal;
    int fresh;                          /* dx and y computed at (t, x, p) */
    /* co-simulation: bgc's Radau and what it keeps across calls */
    double *mass, *index2, *diag, *carry, *Q, *y_old, *kept;
    void *lu_cplx;
    int32_t *piv;
    int64_t stats[5];
} Instance;

static const bgc_model *M = &bgc_the_model;

static void logf_(Instance *c, fmi2Status status, const char *category, const char *fmt, ...)
{
    char text[1024];
    va_list ap;
    if (!c || !c->cb.logger) return;
    if (status == fmi2OK && !c->logging) return;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    c->cb.logger(c->cb.componentEnvironment, c->name, status, category, "%s", text);
}

static fmi2Status fail(Instance *c, const char *fmt, ...)
{
    char text[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    logf_(c, fmi2Error, "logStatusError", "%s", text);
    return fmi2Error;
}

/* value references */
#define VR_DX (M->n)
#define VR_Y (2 * M->n)
#define VR_P (2 * M->n + M->ny)
#define VR_IN (2 * M->n + M->ny + M->np)
#define VR_END (2 * M->n + M->ny + M->np + M->nin)

static void evaluate(Instance *c)
{
    if (c->fresh) return;
    M->rhs(c->t, c->x, c->p, c->w, c->dx);
    M->out(c->t, c->x, c->p, c->w, c->y);
    c->fresh = 1;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn)
{
    (void)fmuResourceLocation; (void)visible;
    if (!functions || !instanceName) return NULL;
    Instance *c = calloc(1, sizeof(Instance));
    if (!c) return NULL;
    c->cb = *functions;
    c->name = malloc(strlen(instanceName) + 1);
    if (c->name) strcpy(c->name, instanceName);
    c->type = fmuType;
    c->logging = loggingOn;
    if (!fmuGUID || strcmp(fmuGUID, M->guid) != 0) {
        fail(c, "this FMU's GUID is %s, not %s", M->guid, fmuGUID ? fmuGUID : "(null)");
        free(c->name);
        free(c);
        return NULL;
    }
    int n = M->n;
    size_t nn = (size_t)n * n;
    c->x = calloc(n + 1, sizeof(double));
    c->dx = calloc(n + 1, sizeof(double));
    c->nominal = calloc(n + 1, sizeof(double));
    c->x_int = calloc(n + 1, sizeof(double));
    c->x_prev = calloc(n + 1, sizeof(double));
    c->v = calloc(2 * n + 2, sizeof(double));
    c->p = calloc(M->np + 1, sizeof(double));
    c->y = calloc(M->ny + 1, sizeof(double));
    c->ind = calloc(M->ni + 1, sizeof(double));
    c->w = calloc(M->n_work + 1, sizeof(double));
    c->J = calloc(nn + 1, sizeof(double));
    c->diag = calloc(n + 1, sizeof(double));
    c->carry = calloc(2 * nn + 1, sizeof(double));
    c->Q = calloc(3 * n + 1, sizeof(double));
    c->y_old = calloc(n + 1, sizeof(double));
    c->kept = calloc(11, sizeof(double));
    c->lu_cplx = calloc(2 * nn + 1, sizeof(double));
    c->piv = calloc(2 * n + 1, sizeof(int32_t));
    if (M->n_algebraic > 0) {
        c->mass = calloc(nn + 1, sizeof(double));
        c->index2 = calloc(n + 1, sizeof(double));
    }
    if (!c->x || !c->dx || !c->nominal || !c->x_int || !c->x_prev || !c->v || !c->p || !c->y || !c->ind || !c->w || !c->J ||
        !c->diag || !c->carry || !c->Q || !c->y_old || !c->kept || !c->lu_cplx || !c->piv ||
        (M->n_algebraic > 0 && (!c->mass || !c->index2))) {
        fail(c, "out of memory");
        return NULL;
    }
    if (M->n_algebraic > 0) {           /* M = diag(1 - index2) */
        for (int i = 0; i < n; i++) c->mass[(size_t)i * n + i] = 1.0;
        for (int k = 0; k < M->n_algebraic; k++) {
            int i = M->algebraic[k];
            c->mass[(size_t)i * n + i] = 0.0;
            c->index2[i] = 1.0;
        }
    }
    memcpy(c->p, M->p0, sizeof(double) * M->np);
    c->rtol = M->rtol;
    c->atol = M->atol;
    c->t_stop = INFINITY;
    c->state = ST_INSTANTIATED;
    return c;
}

void fmi2FreeInstance(fmi2Component comp)
{
    Instance *c = comp;
    if (!c) return;
    free(c->x); free(c->dx); free(c->nominal); free(c->x_int); free(c->x_prev); free(c->v); free(c->p); free(c->y); free(c->ind); free(c->w);
    free(c->J); free(c->diag); free(c->carry); free(c->Q); free(c->y_old); free(c->kept);
    free(c->lu_cplx); free(c->piv); free(c->mass); free(c->index2); free(c->name);
    free(c);
}

fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean loggingOn, size_t n,
                               const fmi2String categories[])
{
    Instance *c = comp;
    (void)n; (void)categories;
    if (!c) return fmi2Error;
    c->logging = loggingOn;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean toleranceDefined,
                               fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    Instance *c = comp;
    if (!c) return fmi2Error;
    if (c->state != ST_INSTANTIATED) return fail(c, "fmi2SetupExperiment after initialization");
    if (toleranceDefined) {
        if (!(tolerance > 0.0) || !(tolerance < 1.0))
            return fail(c, "tolerance %g is not in (0, 1)", tolerance);
        /* the model's ratio of absolute to relative tolerance kept */
        c->atol = M->atol * (tolerance / M->rtol);
        c->rtol = tolerance;
    }
    c->t = c->t_start = startTime;
    c->t_stop = stopTimeDefined ? stopTime : INFINITY;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component comp)
{
    Instance *c = comp;
    if (!c || c->state != ST_INSTANTIATED) return fmi2Error;
    c->state = ST_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component comp)
{
    Instance *c = comp;
    char why[1024];
    if (!c || c->state != ST_INIT) return fmi2Error;
    if (bgc_start(M, c->t, c->x, c->p, c->w, why, sizeof why)) {
        c->state = ST_ERROR;
        return fail(c, "%s: %s", M->name, why);
    }
    /* nominal magnitudes (CVode's absolute tolerances are rtol times these): the state's
       at the start, at least the model's atol / rtol */
    for (int i = 0; i < M->n; i++) c->nominal[i] = fmax(fabs(c->x[i]), M->atol / M->rtol);
    c->fresh = 0;
    c->going = 0;
    c->state = ST_RUN;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component comp)
{
    Instance *c = comp;
    if (!c) return fmi2Error;
    c->state = ST_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component comp)
{
    Instance *c = comp;
    if (!c) return fmi2Error;
    memcpy(c->p, M->p0, sizeof(double) * M->np);
    memset(c->x, 0, sizeof(double) * M->n);
    c->t = c->t_start = 0.0;
    c->rtol = M->rtol;
    c->atol = M->atol;
    c->t_stop = INFINITY;
    c->fresh = 0;
    c->going = 0;
    c->state = ST_INSTANTIATED;
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[])
{
    Instance *c = comp;
    if (!c) return fmi2Error;
    if (nvr > 0 && (!vr || !value)) return fail(c, "fmi2GetReal: NULL arguments");
    int need = 0;
    for (size_t k = 0; k < nvr; k++)
        if (vr[k] >= (fmi2ValueReference)VR_DX && vr[k] < (fmi2ValueReference)VR_P) need = 1;
    if (need && c->state == ST_INSTANTIATED)
        return fail(c, "derivatives and outputs are known from initialization on");
    if (need) evaluate(c);
    for (size_t k = 0; k < nvr; k++) {
        int r = (int)vr[k];
        if (r < 0 || r >= VR_END) return fail(c, "unknown value reference %u", vr[k]);
        value[k] = r < VR_DX ? c->x[r] : r < VR_Y ? c->dx[r - VR_DX]
                 : r < VR_P ? c->y[r - VR_Y] : r < VR_IN ? c->p[r - VR_P]
                 : c->p[M->inputs[r - VR_IN]];
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[])
{
    Instance *c = comp;
    if (!c) return fmi2Error;
    if (nvr > 0 && (!vr || !value)) return fail(c, "fmi2SetReal: NULL arguments");
    for (size_t k = 0; k < nvr; k++) {
        int r = (int)vr[k];
        if (r >= VR_P && r < VR_IN) {
            if (!isfinite(value[k]))
                return fail(c, "parameter %s: %g is not finite", M->param_names[r - VR_P],
                            value[k]);
            if (c->p[r - VR_P] != value[k]) c->going = 0;   /* changed: a fresh start */
            c->p[r - VR_P] = value[k];
        } else if (r >= VR_IN && r < VR_END) {
            if (c->p[M->inputs[r - VR_IN]] != value[k]) c->going = 0;
            c->p[M->inputs[r - VR_IN]] = value[k];
        } else {
            return fail(c, "value reference %u cannot be set (a state, derivative or "
                        "output: bgc computes it)", vr[k]);
        }
    }
    c->fresh = 0;
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[])
{
    (void)vr; (void)value;
    return nvr ? fail(c, "this FMU has no Integer variables") : fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Boolean value[])
{
    (void)vr; (void)value;
    return nvr ? fail(c, "this FMU has no Boolean variables") : fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[])
{
    (void)vr; (void)value;
    return nvr ? fail(c, "this FMU has no String variables") : fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[])
{
    (void)vr; (void)value;
    return nvr ? fail(c, "this FMU has no Integer variables") : fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[])
{
    (void)vr; (void)value;
    return nvr ? fail(c, "this FMU has no Boolean variables") : fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[])
{
    (void)vr; (void)value;
    return nvr ? fail(c, "this FMU has no String variables") : fmi2OK;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s)
{
    (void)s;
    return fail(c, "canGetAndSetFMUstate is false");
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s)
{
    (void)s;
    return fail(c, "canGetAndSetFMUstate is false");
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s)
{
    (void)s;
    return fail(c, "canGetAndSetFMUstate is false");
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *size)
{
    (void)s; (void)size;
    return fail(c, "canSerializeFMUstate is false");
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t size)
{
    (void)s; (void)b; (void)size;
    return fail(c, "canSerializeFMUstate is false");
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t size,
                                   fmi2FMUstate *s)
{
    (void)s; (void)b; (void)size;
    return fail(c, "canSerializeFMUstate is false");
}

/* d(unknowns)/d(knowns) . dv: exact for derivatives against states (the Jacobian
   kernel), by central differences otherwise (outputs, parameters, inputs) */
static double *slot(Instance *c, int r)
{
    if (r < VR_DX) return &c->x[r];
    if (r >= VR_P && r < VR_IN) return &c->p[r - VR_P];
    if (r >= VR_IN && r < VR_END) return &c->p[M->inputs[r - VR_IN]];
    return NULL;
}

static void unknowns(Instance *c, const fmi2ValueReference vu[], size_t nu, double *out)
{
    M->rhs(c->t, c->x, c->p, c->w, c->dx);
    M->out(c->t, c->x, c->p, c->w, c->y);
    for (size_t k = 0; k < nu; k++) {
        int r = (int)vu[k];
        out[k] = r < VR_Y ? c->dx[r - VR_DX] : c->y[r - VR_Y];
    }
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component comp,
                                        const fmi2ValueReference vUnknown_ref[], size_t nu,
                                        const fmi2ValueReference vKnown_ref[], size_t nk,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    Instance *c = comp;
    if (!c) return fmi2Error;
    if (c->state == ST_INSTANTIATED) return fail(c, "directional derivatives from initialization on");
    int exact = 1;
    for (size_t k = 0; k < nu; k++) {
        int r = (int)vUnknown_ref[k];
        if (r < VR_DX || r >= VR_P)
            return fail(c, "value reference %u is not a derivative or an output", vUnknown_ref[k]);
        if (r >= VR_Y) exact = 0;
    }
    for (size_t k = 0; k < nk; k++) {
        int r = (int)vKnown_ref[k];
        if (!slot(c, r)) return fail(c, "value reference %u is not a state, parameter or input",
                                     vKnown_ref[k]);
        if (r >= VR_DX) exact = 0;
    }
    int n = M->n;
    if (exact) {
        M->jac(c->t, c->x, c->p, c->w, c->J);
        for (size_t i = 0; i < nu; i++) {
            int row = (int)vUnknown_ref[i] - VR_DX;
            double s = 0.0;
            for (size_t k = 0; k < nk; k++) s += c->J[(size_t)row * n + vKnown_ref[k]] * dvKnown[k];
            dvUnknown[i] = s;
        }
        c->fresh = 0;
        return fmi2OK;
    }
    double norm = 0.0, *a = malloc(sizeof(double) * (nu + 1)), *b = malloc(sizeof(double) * (nu + 1));
    double *keep = malloc(sizeof(double) * (nk + 1));
    if (!a || !b || !keep) { free(a); free(b); free(keep); return fail(c, "out of memory"); }
    for (size_t k = 0; k < nk; k++) {
        keep[k] = *slot(c, (int)vKnown_ref[k]);
        norm = fmax(norm, fabs(keep[k]));
    }
    double h = 1e-6 * fmax(1.0, norm);
    for (size_t k = 0; k < nk; k++) *slot(c, (int)vKnown_ref[k]) = keep[k] + h * dvKnown[k];
    unknowns(c, vUnknown_ref, nu, a);
    for (size_t k = 0; k < nk; k++) *slot(c, (int)vKnown_ref[k]) = keep[k] - h * dvKnown[k];
    unknowns(c, vUnknown_ref, nu, b);
    for (size_t k = 0; k < nk; k++) *slot(c, (int)vKnown_ref[k]) = keep[k];
    for (size_t i = 0; i < nu; i++) dvUnknown[i] = (a[i] - b[i]) / (2.0 * h);
    free(a); free(b); free(keep);
    c->fresh = 0;
    return fmi2OK;
}

/* ---- Model Exchange ---- */

static double next_breakpoint(double t)
{
    for (int k = 0; k < M->n_breakpoints; k++)
        if (M->breakpoints[k] > t) return M->breakpoints[k];
    return INFINITY;
}

fmi2Status fmi2EnterEventMode(fmi2Component c) { return c ? fmi2OK : fmi2Error; }

fmi2Status fmi2NewDiscreteStates(fmi2Component comp, fmi2EventInfo *info)
{
    Instance *c = comp;
    if (!c || !info) return fmi2Error;
    double next = next_breakpoint(c->t);
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False;
    info->nextEventTimeDefined = isfinite(next) ? fmi2True : fmi2False;
    info->nextEventTime = isfinite(next) ? next : 0.0;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { return c ? fmi2OK : fmi2Error; }

fmi2Status fmi2CompletedIntegratorStep(fmi2Component comp,
                                       fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode,
                                       fmi2Boolean *terminateSimulation)
{
    Instance *c = comp;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!c || !enterEventMode || !terminateSimulation) return fmi2Error;
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    if (M->ng > 0) {                    /* the Cardan singularity */
        double g[64], *gv = M->ng <= 64 ? g : malloc(sizeof(double) * M->ng);
        if (!gv) return fail(c, "out of memory");
        M->guard(c->t, c->x, c->p, c->w, gv);
        for (int k = 0; k < M->ng; k++)
            if (!(gv[k] > BGC_GUARD_TOLERANCE)) {
                *terminateSimulation = fmi2True;
                fail(c, "%s reached at t = %g: XYZ Cardan angles cannot pass b = +-90 deg",
                     M->guard_names[k], c->t);
                if (gv != g) free(gv);
                return fmi2Error;
            }
        if (gv != g) free(gv);
    }
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component comp, fmi2Real time)
{
    Instance *c = comp;
    if (!c) return fmi2Error;
    c->t = time;
    c->fresh = 0;
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component comp, const fmi2Real x[], size_t nx)
{
    Instance *c = comp;
    if (!c) return fmi2Error;
    if ((int)nx != M->n || (nx && !x)) return fail(c, "expected %d states, got %zu", M->n, nx);
    memcpy(c->x, x, sizeof(double) * nx);
    c->fresh = 0;
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component comp, fmi2Real dx[], size_t nx)
{
    Instance *c = comp;
    if (!c) return fmi2Error;
    if ((int)nx != M->n || (nx && !dx)) return fail(c, "expected %d derivatives, got %zu", M->n, nx);
    evaluate(c);
    memcpy(dx, c->dx, sizeof(double) * nx);
    return fmi2OK;
}

fmi2Status fmi2GetEventIndicators(fmi2Component comp, fmi2Real ind[], size_t ni)
{
    Instance *c = comp;
    if (!c) return fmi2Error;
    if ((int)ni != M->ni || (ni && !ind))
        return fail(c, "expected %d event indicators, got %zu", M->ni, ni);
    if (ni) M->ind(c->t, c->x, c->p, c->w, ind);
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component comp, fmi2Real x[], size_t nx)
{
    Instance *c = comp;
    if (!c) return fmi2Error;
    if ((int)nx != M->n || (nx && !x)) return fail(c, "expected %d states, got %zu", M->n, nx);
    memcpy(x, c->x, sizeof(double) * nx);
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component comp, fmi2Real nominal[], size_t nx)
{
    Instance *c = comp;
    if (!c) return fmi2Error;
    if (c->state != ST_RUN)
        for (int i = 0; i < M->n; i++) c->nominal[i] = M->atol / M->rtol;
    if ((int)nx != M->n || (nx && !nominal)) return fail(c, "expected %d states, got %zu", M->n, nx);
    for (size_t i = 0; i < nx; i++) nominal[i] = c->nominal[i];
    return fmi2OK;
}

/* ---- Co-Simulation ---- */

/* one call of bgc's Radau from the integrator's (t_int, x_int) towards t1: one step
   (max_steps 1: it pauses after it, keeping its Jacobian, factors and step size for the
   next call) or up to t1 (max_steps 0); the status, t_int and x_int moved */
static fmi2Status radau(Instance *c, double t1, int64_t max_steps, int *status)
{
    int64_t ret = 0;
    void *exc = NULL;
    double out[3];
    int32_t st = bgc_radau5_step(
        &ret, &exc, (int64_t)(intptr_t)M->rhs_entry, (int64_t)(intptr_t)M->jac_entry,
        (int64_t)(intptr_t)M->guard_entry, M->ng, M->n, M->np, c->x_int, c->p,
        M->n_algebraic > 0, c->mass, c->index2, M->sparse, M->perm, M->lptr, M->lidx,
        M->uptr, M->uidx, M->n_l, M->n_u, c->t_int, t1, c->rtol, c->atol, c->h_max,
        c->h_next, max_steps, c->stats, c->diag, out, c->J, c->carry, c->lu_cplx, c->piv,
        c->piv + M->n, c->Q, c->y_old, c->kept);
    if (st != 0) return fail(c, "bgc's Radau raised an internal error at t = %g", c->t_int);
    *status = (int)ret;
    double t = out[0];
    if (*status == BGC_REACHED || *status == BGC_PAUSED) {
        c->t_int = t;
        c->h_next = out[1];
        return fmi2OK;
    }
    memcpy(c->x, c->x_int, sizeof(double) * M->n);
    c->t = t;
    if (*status == BGC_GUARD)
        return fail(c, "%s reached at t = %.6g: XYZ Cardan angles cannot pass b = +-90 deg",
                    M->guard_names[(int)out[2]], t);
    if (*status == BGC_NOT_FINITE)
        return fail(c, "Radau failed at t = %.6g: the state became non-finite", t);
    if (*status == BGC_SINGULAR)
        return fail(c, "Radau failed at t = %.6g: the Newton matrix is singular at every "
                    "step size", t);
    int worst = 0;
    for (int i = 1; i < M->n; i++)
        if (c->diag[i] > c->diag[worst]) worst = i;
    return fail(c, "Radau failed at t = %.6g: the step size collapsed to %.3g s (the error "
                "of %s dominates)", t, out[1], M->state_names[worst]);
}

/* a fresh start of the integrator at the communication point (t, x), as a segment of
   bgc simulate starts: the first step estimated */
static void restart(Instance *c)
{
    memcpy(c->x_int, c->x, sizeof(double) * M->n);
    c->t_int = c->t_prev = c->t;
    memset(c->kept, 0, sizeof(double) * 11);
    c->h_next = 0.0;
    c->h_max = M->max_step(c->p);
    if (!(c->h_max > 0.0)) c->h_max = INFINITY;
    c->going = 1;
}

/* The co-simulation step: the integrator runs on its own steps, as in bgc simulate, and
   the state at the communication point comes from its last step's collocation
   polynomial (the dense output bgc simulate's output times take); it lands exactly on
   every breakpoint and starts afresh there. A parameter or input set between steps
   restarts it from the communication point. */
static fmi2Status advance(Instance *c, double target)
{
    int n = M->n, status;
    if (!c->going) restart(c);
    for (;;) {
        if (c->t_int >= target) {       /* x(target) on the last step's polynomial */
            double h = c->t_int - c->t_prev;
            double s = h > 0.0 ? (target - c->t_prev) / h : 1.0;
            for (int i = 0; i < n; i++)
                c->x[i] = c->t_int == target ? c->x_int[i] : c->x_prev[i] + s * (
                    c->Q[3 * i] + s * (c->Q[3 * i + 1] + s * c->Q[3 * i + 2]));
            c->t = target;
            c->fresh = 0;
            return fmi2OK;
        }
        double e = next_breakpoint(c->t_int);
        if (e <= target) {              /* land on the breakpoint, go on afresh from it */
            if (radau(c, e, 0, &status) != fmi2OK) return fmi2Error;
            memcpy(c->x, c->x_int, sizeof(double) * n);
            c->t = e;
            restart(c);
            continue;
        }
        memcpy(c->x_prev, c->x_int, sizeof(double) * n);
        c->t_prev = c->t_int;
        if (radau(c, isfinite(c->t_stop) && c->t_stop > target && c->t_stop < e ?
                  c->t_stop : e, 1, &status) != fmi2OK)
            return fmi2Error;
        if (status == BGC_REACHED && c->t_int == e)
            c->h_next = 0.0;            /* on a breakpoint: the next step starts afresh */
    }
}

fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    Instance *c = comp;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!c) return fmi2Error;
    if (c->state != ST_RUN) return fail(c, "fmi2DoStep before initialization or after an error");
    if (!(communicationStepSize > 0.0)) return fail(c, "communication step %g is not > 0",
                                                    communicationStepSize);
    if (fabs(currentCommunicationPoint - c->t) > 1e-9 * fmax(1.0, fabs(c->t)))
        return fail(c, "fmi2DoStep at t = %.17g, but the FMU is at t = %.17g",
                    currentCommunicationPoint, c->t);
    fmi2Status s = advance(c, currentCommunicationPoint + communicationStepSize);
    if (s != fmi2OK) c->state = ST_ERROR;
    return s;
}

fmi2Status fmi2CancelStep(fmi2Component c) { return fail(c, "fmi2DoStep never runs asynchronously"); }

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                       size_t nvr, const fmi2Integer order[],
                                       const fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    return fail(c, "canInterpolateInputs is false");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[],
                                        fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    return fail(c, "maxOutputDerivativeOrder is 0");
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    (void)s;
    if (!c || !value) return fmi2Error;
    *value = fmi2OK;
    return fmi2OK;
}

fmi2Status fmi2GetRealStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Real *value)
{
    Instance *c = comp;
    if (!c || !value || s != fmi2LastSuccessfulTime) return fmi2Discard;
    *value = c->t;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    (void)c; (void)s; (void)value;
    return fmi2Discard;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Boolean *value)
{
    Instance *c = comp;
    if (!c || !value || s != fmi2Terminated) return fmi2Discard;
    *value = c->state == ST_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    (void)c; (void)s; (void)value;
    return fmi2Discard;
}
