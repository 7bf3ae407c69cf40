/* Dense linear algebra an FMU needs without LAPACK: the singular value decomposition
   by one-sided Jacobi rotations (Hestenes; Demmel & Veselic: accurate to round-off in
   every singular value, which a rank decision needs), least squares through it (the
   minimum-norm solution keeping the singular values above rcond times the largest, as
   numpy's lstsq), and LAPACK's dgesdd for the kernels of a redundant constraint
   block. */

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "bgc_fmu.h"

#define JACOBI_SWEEPS 80

/* W: `cols` columns of length `rows` (column after column), rows >= cols; on return
   its columns are U's (unit, or zero where the singular value is), s the singular
   values (descending) and V (cols x cols, column after column) the right vectors. */
static void jacobi(int rows, int cols, double *W, double *V, double *s)
{
    memset(V, 0, sizeof(double) * (size_t)cols * cols);
    for (int j = 0; j < cols; j++) V[j * cols + j] = 1.0;
    for (int sweep = 0; sweep < JACOBI_SWEEPS; sweep++) {
        int rotated = 0;
        for (int p = 0; p < cols - 1; p++) {
            double *wp = W + (size_t)p * rows, *vp = V + (size_t)p * cols;
            for (int q = p + 1; q < cols; q++) {
                double *wq = W + (size_t)q * rows, *vq = V + (size_t)q * cols;
                double a = 0.0, b = 0.0, g = 0.0;
                for (int i = 0; i < rows; i++) {
                    a += wp[i] * wp[i];
                    b += wq[i] * wq[i];
                    g += wp[i] * wq[i];
                }
                if (g == 0.0 || fabs(g) <= 1e-15 * sqrt(a) * sqrt(b)) continue;
                rotated = 1;
                double zeta = (b - a) / (2.0 * g);
                double t = copysign(1.0, zeta) / (fabs(zeta) + sqrt(1.0 + zeta * zeta));
                double c = 1.0 / sqrt(1.0 + t * t), sn = c * t;
                for (int i = 0; i < rows; i++) {
                    double x = wp[i], y = wq[i];
                    wp[i] = c * x - sn * y;
                    wq[i] = sn * x + c * y;
                }
                for (int i = 0; i < cols; i++) {
                    double x = vp[i], y = vq[i];
                    vp[i] = c * x - sn * y;
                    vq[i] = sn * x + c * y;
                }
            }
        }
        if (!rotated) break;
    }
    for (int j = 0; j < cols; j++) {
        double *w = W + (size_t)j * rows, norm = 0.0;
        for (int i = 0; i < rows; i++) norm += w[i] * w[i];
        norm = sqrt(norm);
        s[j] = norm;
        if (norm > 0.0)
            for (int i = 0; i < rows; i++) w[i] /= norm;
    }
    /* descending, by selection (the vectors swapped along) */
    for (int j = 0; j < cols; j++) {
        int k = j;
        for (int i = j + 1; i < cols; i++)
            if (s[i] > s[k]) k = i;
        if (k == j) continue;
        double t = s[j]; s[j] = s[k]; s[k] = t;
        for (int i = 0; i < rows; i++) {
            t = W[(size_t)j * rows + i]; W[(size_t)j * rows + i] = W[(size_t)k * rows + i];
            W[(size_t)k * rows + i] = t;
        }
        for (int i = 0; i < cols; i++) {
            t = V[(size_t)j * cols + i]; V[(size_t)j * cols + i] = V[(size_t)k * cols + i];
            V[(size_t)k * cols + i] = t;
        }
    }
}

int bgc_svd(int m, int n, const double *A, int row_major, double *U, double *s, double *V)
{
    /* A = U diag(s) V^T, k = min(m, n): U (m x k) and V (n x k) column after column. */
    int k = m < n ? m : n;
    if (k == 0) return 0;
    double *W = malloc(sizeof(double) * (size_t)m * n);
    double *R = malloc(sizeof(double) * (size_t)k * k);
    if (!W || !R) { free(W); free(R); return -1; }
    for (int i = 0; i < m; i++)
        for (int j = 0; j < n; j++) {
            double a = row_major ? A[(size_t)i * n + j] : A[i + (size_t)j * m];
            if (m >= n) W[(size_t)j * m + i] = a;      /* columns of A */
            else W[(size_t)i * n + j] = a;             /* columns of A^T */
        }
    if (m >= n) {
        jacobi(m, n, W, R, s);
        memcpy(U, W, sizeof(double) * (size_t)m * n);
        memcpy(V, R, sizeof(double) * (size_t)n * n);
    } else {                    /* A^T = U' S V'^T: A = V' S U'^T */
        jacobi(n, m, W, R, s);
        memcpy(V, W, sizeof(double) * (size_t)n * m);
        memcpy(U, R, sizeof(double) * (size_t)m * m);
    }
    free(W);
    free(R);
    return 0;
}

int bgc_lstsq(int m, int n, const double *A, const double *b, double *x, double rcond,
              int *rank)
{
    /* The minimum-norm least-squares solution of A x = b (A row-major, m x n) keeping the
       singular values above rcond times the largest; its rank in *rank. */
    int k = m < n ? m : n;
    memset(x, 0, sizeof(double) * (size_t)n);
    if (rank) *rank = 0;
    if (k == 0) return 0;
    double *U = malloc(sizeof(double) * (size_t)m * k), *s = malloc(sizeof(double) * k);
    double *V = malloc(sizeof(double) * (size_t)n * k);
    int ok = U && s && V && bgc_svd(m, n, A, 1, U, s, V) == 0;
    if (ok) {
        int r = 0;
        for (int q = 0; q < k; q++) {
            if (!(s[q] > rcond * s[0])) break;
            double c = 0.0;
            for (int i = 0; i < m; i++) c += U[(size_t)q * m + i] * b[i];
            c /= s[q];
            for (int j = 0; j < n; j++) x[j] += c * V[(size_t)q * n + j];
            r++;
        }
        if (rank) *rank = r;
    }
    free(U);
    free(s);
    free(V);
    return ok ? 0 : -1;
}

int bgc_rank(int m, int n, const double *A, double tol, double *conditioning)
{
    /* The number of singular values of A (row-major) above tol times the largest. */
    int k = m < n ? m : n, r = 0;
    if (k == 0) return 0;
    double *U = malloc(sizeof(double) * (size_t)m * k), *s = malloc(sizeof(double) * k);
    double *V = malloc(sizeof(double) * (size_t)n * k);
    if (U && s && V && bgc_svd(m, n, A, 1, U, s, V) == 0) {
        while (r < k && s[r] > tol * (s[0] > 1e-300 ? s[0] : 1e-300)) r++;
        if (conditioning) *conditioning = r > 0 && s[0] > 0 ? s[r - 1] / s[0] : 1.0;
    }
    free(U);
    free(s);
    free(V);
    return r;
}

void bgc_dgesdd(const char *jobz, const int32_t *m, const int32_t *n, double *a,
                const int32_t *lda, double *s, double *u, const int32_t *ldu, double *vt,
                const int32_t *ldvt, double *work, const int32_t *lwork, int32_t *iwork,
                int32_t *info)
{
    /* dgesdd with jobz 'A' of a square matrix, as the kernels' least squares calls it
       (kernels._lstsq_ir, which reads only the singular vectors of the singular values
       it keeps: those of zero singular values are left zero, not completed to a basis).
       `work` holds 2 n^2 doubles at least (the kernels give 7 n^2 + 12 n). */
    int N = *n;
    (void)jobz; (void)lwork; (void)iwork;
    if (*m != N) { *info = -2; return; }
    double *W = work, *V = work + (size_t)N * N;
    for (int j = 0; j < N; j++)
        for (int i = 0; i < N; i++) W[(size_t)j * N + i] = a[i + (size_t)j * *lda];
    jacobi(N, N, W, V, s);
    for (int k = 0; k < N; k++)
        for (int i = 0; i < N; i++) {
            u[i + (size_t)k * *ldu] = W[(size_t)k * N + i];
            vt[k + (size_t)i * *ldvt] = V[(size_t)k * N + i];
        }
    *info = 0;
}
