/* The FMU's C layer: what the generated model file (templates/model.c.j2) describes and
   what the runtime files (start.c, fmi2.c, linalg.c, numba_rt.c) share. */
#ifndef BGC_FMU_H
#define BGC_FMU_H

#include <stdint.h>

/* a kernel of the model (bgc/codegen/kernels.py): f(t, x, p, w, out), w its workspace */
typedef void (*bgc_kernel)(double t, const double *x, const double *p, double *w,
                           double *out);

typedef struct {
    const char *name, *guid;
    int n, np, ny, ng, nc, ni, nin;     /* states, parameters, outputs, guards,
                                           constraints, event indicators, inputs */
    int n_work, n_eval;                 /* the kernels' workspaces (Jacobian, others) */
    bgc_kernel rhs, jac, out, guard, con, ind;
    /* the C entry points bgc's Radau calls: f(t, x, p, out) */
    void (*rhs_entry)(double, double *, double *, double *);
    void (*jac_entry)(double, double *, double *, double *);
    void (*guard_entry)(double, double *, double *, double *);
    void (*initial_state)(const double *p, double *x);
    double (*max_step)(const double *p);
    const double *p0;
    const char *const *state_names, *const *param_names, *const *output_names,
        *const *guard_names, *const *constraint_names;
    const int *has_position, *imposed, *pose;
    int n_pose;
    const int *algebraic;
    int n_algebraic;
    int static_loads;                   /* parasitic: joint loads set at t = 0 */
    const int *loads, *excitation;      /* their parameters, the excitation's */
    int n_loads, n_excitation;
    int rank_param;                     /* lagrange__rank's index, -1: none */
    const double *breakpoints;
    int n_breakpoints;
    int sparse;                         /* the Newton matrices' plan (radau5.System) */
    const int64_t *perm, *lptr, *lidx, *uptr, *uidx;
    int n_l, n_u;
    double rtol, atol, t_end;           /* the model's settings */
    const int *inputs;                  /* each input's parameter index */
} bgc_model;

extern const bgc_model bgc_the_model;

int bgc_svd(int m, int n, const double *A, int row_major, double *U, double *s, double *V);
int bgc_lstsq(int m, int n, const double *A, const double *b, double *x, double rcond,
              int *rank);
int bgc_rank(int m, int n, const double *A, double tol, double *conditioning);
void bgc_dgesdd(const char *jobz, const int32_t *m, const int32_t *n, double *a,
                const int32_t *lda, double *s, double *u, const int32_t *ldu, double *vt,
                const int32_t *ldvt, double *work, const int32_t *lwork, int32_t *iwork,
                int32_t *info);

/* the start of a run (start.c): x from the parameters, the joint loads (parasitic) or
   the projection onto the constraints and their rank (lagrange, zcp); 0 on success,
   else a message in `why` */
int bgc_start(const bgc_model *m, double t0, double *x, double *p, double *w, char *why,
              int why_size);

/* bgc's Radau IIA (radau.py: numba's calling convention) */
int32_t bgc_radau5_step(int64_t *ret, void *excinfo, int64_t rhs, int64_t jac,
                        int64_t guards, int64_t n_guards, int64_t n, int64_t n_p, double *x,
                        double *p, int64_t dae, double *mass, double *index2, int64_t sparse,
                        const int64_t *perm, const int64_t *lptr, const int64_t *lidx,
                        const int64_t *uptr, const int64_t *uidx, int64_t n_l, int64_t n_u,
                        double t0, double t1, double rtol, double atol, double max_step,
                        double h_start, int64_t max_steps, int64_t *stats, double *diag,
                        double *out, double *J, double *lu, void *lu_cplx, int32_t *piv,
                        int32_t *piv_cplx, double *Q, double *y_old, double *kept);

/* its statuses (bgc/solvers/native.py) */
enum { BGC_REACHED, BGC_STEP_TOO_SMALL, BGC_GUARD, BGC_NOT_FINITE, BGC_SINGULAR,
       BGC_PAUSED };

#define BGC_GUARD_TOLERANCE 1e-3
#define BGC_RANK_TOL 1e-9

#endif
