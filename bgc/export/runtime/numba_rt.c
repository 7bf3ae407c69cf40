/* What bgc's Radau (bgc/export/radau.py: numba code compiled to an object) needs from
   numba's run time, for an FMU that has no Python: numpy arrays' allocator (NRT's
   MemInfo: the layout of numba/core/runtime/nrt.h, whose `data` field the compiled code
   reads at offset 24), LAPACK's getrf as numba's helper calls it (column-major, 1-based
   pivots: the dense Newton matrices) and nextafter. */

#include <complex.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

typedef struct {
    size_t refct;
    void (*dtor)(void *data, size_t size, void *info);
    void *dtor_info;
    void *data;
    size_t size;
    void *external_allocator;
} NRT_MemInfo;

NRT_MemInfo *NRT_MemInfo_alloc_aligned(size_t size, unsigned align)
{
    size_t head = sizeof(NRT_MemInfo);
    char *raw;
    NRT_MemInfo *mi;
    if (align < sizeof(void *)) align = sizeof(void *);
    raw = (char *)malloc(head + size + 2 * (size_t)align);
    if (!raw) return NULL;
    mi = (NRT_MemInfo *)raw;
    mi->refct = 1;
    mi->dtor = NULL;
    mi->dtor_info = NULL;
    mi->data = (void *)(((uintptr_t)(raw + head) + align - 1) & ~(uintptr_t)(align - 1));
    mi->size = size;
    mi->external_allocator = NULL;
    return mi;
}

void NRT_MemInfo_call_dtor(NRT_MemInfo *mi)
{
    if (mi->dtor) mi->dtor(mi->data, mi->size, mi->dtor_info);
    free(mi);
}

double numba_nextafter(double a, double b) { return nextafter(a, b); }

/* LU with partial pivoting of the m x n column-major matrix a (leading dimension lda),
   as LAPACK's dgetrf/zgetrf ('d', 'z'): unit L below the diagonal, U on and above,
   ipiv 1-based; > 0: U(info, info) is exactly zero (the factors are complete). */
#define BGC_GETRF(NAME, T, ABS)                                                         \
static int NAME(int64_t m, int64_t n, T *a, int64_t lda, int32_t *ipiv)                \
{                                                                                       \
    int info = 0;                                                                       \
    int64_t k = m < n ? m : n;                                                          \
    for (int64_t j = 0; j < k; j++) {                                                   \
        int64_t p = j;                                                                  \
        double big = ABS(a[j + j * lda]);                                               \
        for (int64_t i = j + 1; i < m; i++) {                                           \
            double v = ABS(a[i + j * lda]);                                             \
            if (v > big) { big = v; p = i; }                                            \
        }                                                                               \
        ipiv[j] = (int32_t)(p + 1);                                                     \
        if (a[p + j * lda] == 0) { if (!info) info = (int)(j + 1); continue; }          \
        if (p != j)                                                                     \
            for (int64_t c = 0; c < n; c++) {                                           \
                T s = a[j + c * lda]; a[j + c * lda] = a[p + c * lda]; a[p + c * lda] = s; \
            }                                                                           \
        T piv = a[j + j * lda];                                                         \
        for (int64_t i = j + 1; i < m; i++) a[i + j * lda] /= piv;                      \
        for (int64_t c = j + 1; c < n; c++) {                                           \
            T f = a[j + c * lda];                                                       \
            if (f != 0)                                                                 \
                for (int64_t i = j + 1; i < m; i++) a[i + c * lda] -= a[i + j * lda] * f; \
        }                                                                               \
    }                                                                                   \
    return info;                                                                        \
}

static double abs_real(double v) { return fabs(v); }
static double abs_cplx(double complex v) { return fabs(creal(v)) + fabs(cimag(v)); }
BGC_GETRF(getrf_real, double, abs_real)
BGC_GETRF(getrf_cplx, double complex, abs_cplx)

int numba_xxgetrf(char kind, int64_t m, int64_t n, void *a, int64_t lda, int32_t *ipiv)
{
    if (kind == 'd') return getrf_real(m, n, (double *)a, lda, ipiv);
    if (kind == 'z') return getrf_cplx(m, n, (double complex *)a, lda, ipiv);
    return -1;
}
