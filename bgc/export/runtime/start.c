/* The start of a run, natively, as bgc.simulate.prepare makes it in Python
   (bgc/solvers/consistent.py): the initial state from the parameters; for a model that
   starts at rest under method parasitic, the joint loads (consistent.static_loads); under
   lagrange and zcp, the state projected onto the constraints (consistent.project:
   Gauss-Newton on the poses, least squares on the other states, central differences of
   the constraints kernel) and the rank of the constraint rows set in lagrange__rank. */

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bgc_fmu.h"

static double max_abs(const double *v, int n)
{
    double m = 0.0;
    for (int i = 0; i < n; i++)
        if (fabs(v[i]) > m || v[i] != v[i]) m = v[i] != v[i] ? NAN : fabs(v[i]);
    return m;
}

static int static_loads(const bgc_model *m, const double *x, double *p, double *w,
                        char *why, int size)
{
    int n = m->n, L = m->n_loads;
    double *q = malloc(sizeof(double) * m->np), *f0 = malloc(sizeof(double) * n);
    double *f = malloc(sizeof(double) * n), *M = malloc(sizeof(double) * (size_t)n * L);
    double *sol = malloc(sizeof(double) * (L ? L : 1));
    int status = -1;
    if (!q || !f0 || !f || !M || !sol) { snprintf(why, size, "out of memory"); goto done; }
    memcpy(q, p, sizeof(double) * m->np);
    for (int k = 0; k < L; k++) q[m->loads[k]] = 0.0;
    for (int k = 0; k < m->n_excitation; k++) q[m->excitation[k]] = 0.0;
    m->rhs(0.0, x, q, w, f0);
    for (int k = 0; k < L; k++) {
        q[m->loads[k]] = 1.0;
        m->rhs(0.0, x, q, w, f);
        q[m->loads[k]] = 0.0;
        for (int i = 0; i < n; i++) M[(size_t)i * L + k] = f[i] - f0[i];
    }
    for (int i = 0; i < n; i++) f0[i] = -f0[i];
    if (bgc_lstsq(n, L, M, f0, sol, BGC_RANK_TOL, NULL)) {
        snprintf(why, size, "out of memory");
        goto done;
    }
    for (int k = 0; k < L; k++) q[m->loads[k]] = sol[k];
    m->rhs(0.0, x, q, w, f);
    int worst = 0;
    for (int i = 0; i < n; i++)
        if (fabs(f[i]) > fabs(f[worst]) || f[i] != f[i]) worst = i;
    double scale = max_abs(f0, n);
    if (!(fabs(f[worst]) <= 1e-6 * (scale > 1.0 ? scale : 1.0))) {
        snprintf(why, size, "the initial state (t = 0) is not a static equilibrium: with "
                 "the parasitic springs' best static loads d%s/dt is still %.3g",
                 m->state_names[worst], f[worst]);
        goto done;
    }
    for (int k = 0; k < L; k++) p[m->loads[k]] = sol[k];
    status = 0;
done:
    free(q); free(f0); free(f); free(M); free(sol);
    return status;
}

/* the constraints kernel: g (nc), then dg/dt (nc) */
static void constraints(const bgc_model *m, const double *x, const double *p, double *w,
                        double *c)
{
    m->con(0.0, x, p, w, c);
}

/* central differences of c[rows] w.r.t. x[cols] into J (rows x cols, row-major), as
   consistent._jacobian */
static void jacobian(const bgc_model *m, double *x, const double *p, double *w,
                     const int *rows, int nr, const int *cols, int nk, double *J,
                     double *cp, double *cm)
{
    for (int k = 0; k < nk; k++) {
        int j = cols[k];
        double xj = x[j], h = 1e-7 * (fabs(xj) > 1.0 ? fabs(xj) : 1.0);
        x[j] = xj + h;
        constraints(m, x, p, w, cp);
        x[j] = xj - h;
        constraints(m, x, p, w, cm);
        x[j] = xj;
        for (int i = 0; i < nr; i++)
            J[(size_t)i * nk + k] = (cp[rows[i]] - cm[rows[i]]) / (2.0 * h);
    }
}

static int project(const bgc_model *m, double *x, double *p, double *w, char *why,
                   int size)
{
    int nc = m->nc, n = m->n, np_ = 0, nm = 0, n_other = 0, status = -1, it = 0;
    int *pos = malloc(sizeof(int) * nc), *rates = malloc(sizeof(int) * nc);
    int *other = malloc(sizeof(int) * n), *is_pose = calloc(n, sizeof(int));
    double *c = malloc(sizeof(double) * 2 * nc), *cp = malloc(sizeof(double) * 2 * nc);
    double *cm = malloc(sizeof(double) * 2 * nc);
    double *J = malloc(sizeof(double) * (size_t)nc * n), *b = malloc(sizeof(double) * nc);
    double *dx = malloc(sizeof(double) * n);
    if (!pos || !rates || !other || !is_pose || !c || !cp || !cm || !J || !b || !dx) {
        snprintf(why, size, "out of memory");
        goto done;
    }
    for (int i = 0; i < nc; i++) {
        if (m->has_position[i]) pos[np_++] = i;
        if (!m->imposed[i]) rates[nm++] = nc + i;
    }
    for (int k = 0; k < m->n_pose; k++) is_pose[m->pose[k]] = 1;
    for (int j = 0; j < n; j++)
        if (!is_pose[j]) other[n_other++] = j;
    double scale = 1.0;
    for (int k = 0; k < m->n_pose; k++)
        if (fabs(x[m->pose[k]]) > scale) scale = fabs(x[m->pose[k]]);
    int stalled = 0;
    double gmax = 0.0;
    for (it = 1; it <= 50; it++) {
        constraints(m, x, p, w, c);
        gmax = 0.0;
        for (int i = 0; i < np_; i++) {
            b[i] = -c[pos[i]];
            if (fabs(b[i]) > gmax || b[i] != b[i]) gmax = b[i] != b[i] ? NAN : fabs(b[i]);
        }
        if (!np_ || gmax <= 1e-12 * scale) { it--; break; }
        jacobian(m, x, p, w, pos, np_, m->pose, m->n_pose, J, cp, cm);
        bgc_lstsq(np_, m->n_pose, J, b, dx, BGC_RANK_TOL, NULL);
        double step = 0.0;
        for (int k = 0; k < m->n_pose; k++) {
            x[m->pose[k]] += dx[k];
            if (fabs(dx[k]) > step) step = fabs(dx[k]);
        }
        if (step <= 1e-14 * scale) { stalled = gmax > 1e-9 * scale; break; }
    }
    if (it > 50) stalled = 1;
    if (stalled || gmax != gmax) {
        constraints(m, x, p, w, c);
        int worst = pos[0];
        for (int i = 0; i < np_; i++)
            if (fabs(c[pos[i]]) > fabs(c[worst])) worst = pos[i];
        snprintf(why, size, "the initial positions (t = 0) cannot be made consistent with "
                 "the joints: after %d Newton iterations joint direction %s is still open "
                 "by %.3g", it, m->constraint_names[worst], fabs(c[worst]));
        goto done;
    }
    /* the velocities: the rows zcp does not impose, by least squares (twice: round-off) */
    jacobian(m, x, p, w, rates, nm, other, n_other, J, cp, cm);
    for (int rep = 0; nm > 0 && rep < 2; rep++) {
        constraints(m, x, p, w, c);
        for (int i = 0; i < nm; i++) b[i] = -c[rates[i]];
        bgc_lstsq(nm, n_other, J, b, dx, BGC_RANK_TOL, NULL);
        for (int k = 0; k < n_other; k++) x[other[k]] += dx[k];
    }
    constraints(m, x, p, w, c);
    /* the rank of the measured rows, equilibrated (consistent.equilibration): columns to
       unit length, then rows */
    for (int k = 0; k < n_other; k++) {
        double s = 0.0;
        for (int i = 0; i < nm; i++) s += J[(size_t)i * n_other + k] * J[(size_t)i * n_other + k];
        s = s > 0.0 ? 1.0 / sqrt(s) : 1.0;
        for (int i = 0; i < nm; i++) J[(size_t)i * n_other + k] *= s;
    }
    for (int i = 0; i < nm; i++) {
        double s = 0.0;
        for (int k = 0; k < n_other; k++) s += J[(size_t)i * n_other + k] * J[(size_t)i * n_other + k];
        s = s > 0.0 ? 1.0 / sqrt(s) : 1.0;
        for (int k = 0; k < n_other; k++) J[(size_t)i * n_other + k] *= s;
    }
    int rank = (nc - nm) + bgc_rank(nm, n_other, J, BGC_RANK_TOL, NULL);
    double rmax = 0.0, vmax = 0.0;
    int worst = 0;
    for (int i = 0; i < nc; i++)
        if (fabs(c[nc + i]) > rmax || c[nc + i] != c[nc + i]) {
            rmax = c[nc + i] != c[nc + i] ? NAN : fabs(c[nc + i]);
            worst = i;
        }
    for (int k = 0; k < n_other; k++)
        if (fabs(x[other[k]]) > vmax) vmax = fabs(x[other[k]]);
    if (!(rmax <= 1e-8 * (vmax > 1.0 ? vmax : 1.0))) {
        snprintf(why, size, "the initial velocities (t = 0) cannot be made consistent: "
                 "joint direction %s still moves at %.3g after projection",
                 m->constraint_names[worst], rmax);
        goto done;
    }
    if (m->rank_param >= 0) p[m->rank_param] = rank;
    status = 0;
done:
    free(pos); free(rates); free(other); free(is_pose); free(c); free(cp); free(cm);
    free(J); free(b); free(dx);
    return status;
}

int bgc_start(const bgc_model *m, double t0, double *x, double *p, double *w, char *why,
              int size)
{
    m->initial_state(p, x);
    for (int i = 0; i < m->np; i++)
        if (!isfinite(p[i])) {
            snprintf(why, size, "parameter %s is not finite (%g)", m->param_names[i], p[i]);
            return -1;
        }
    for (int i = 0; i < m->n; i++)
        if (!isfinite(x[i])) {
            snprintf(why, size, "initial state %s is not finite (%g)", m->state_names[i],
                     x[i]);
            return -1;
        }
    if (m->static_loads && t0 == 0.0 && m->n_loads > 0 && static_loads(m, x, p, w, why, size))
        return -1;
    if (m->nc > 0 && project(m, x, p, w, why, size)) return -1;
    double *f = malloc(sizeof(double) * (m->n ? m->n : 1));
    if (!f) { snprintf(why, size, "out of memory"); return -1; }
    m->rhs(t0, x, p, w, f);
    for (int i = 0; i < m->n; i++)
        if (!isfinite(f[i])) {
            snprintf(why, size, "d/dt of %s is not finite at the initial state (t = %g): "
                     "check the model's parameters, initial state and laws there",
                     m->state_names[i], t0);
            free(f);
            return -1;
        }
    free(f);
    if (m->ng > 0) {
        double *g = malloc(sizeof(double) * m->ng);
        if (!g) { snprintf(why, size, "out of memory"); return -1; }
        m->guard(t0, x, p, w, g);
        for (int k = 0; k < m->ng; k++)
            if (!(g[k] > BGC_GUARD_TOLERANCE)) {
                snprintf(why, size, "%s at the initial state (margin %.3g)",
                         m->guard_names[k], g[k]);
                free(g);
                return -1;
            }
        free(g);
    }
    return 0;
}
