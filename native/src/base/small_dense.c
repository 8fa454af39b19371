/* Small dense matrices (no world types): the inverse of a 3x3, the Cholesky factor of a 6x6
 * and its solve, and a body-frame tensor turned into world axes. */
#include "small_dense.h"

#include <math.h>

#include <string.h>

/* Inverse of a symmetric positive-definite 3x3 (inertia); 0 when singular. */
int gc_invert_mat3(const gcMat3 *a, gcMat3 *out) {
    const double(*m)[3] = a->m;
    double c00 = m[1][1] * m[2][2] - m[1][2] * m[2][1];
    double c01 = m[1][2] * m[2][0] - m[1][0] * m[2][2];
    double c02 = m[1][0] * m[2][1] - m[1][1] * m[2][0];
    double det = m[0][0] * c00 + m[0][1] * c01 + m[0][2] * c02;
    if (!(fabs(det) > 0.0) || !isfinite(det)) return 0;
    double inv = 1.0 / det;
    out->m[0][0] = c00 * inv;
    out->m[0][1] = (m[0][2] * m[2][1] - m[0][1] * m[2][2]) * inv;
    out->m[0][2] = (m[0][1] * m[1][2] - m[0][2] * m[1][1]) * inv;
    out->m[1][0] = c01 * inv;
    out->m[1][1] = (m[0][0] * m[2][2] - m[0][2] * m[2][0]) * inv;
    out->m[1][2] = (m[0][2] * m[1][0] - m[0][0] * m[1][2]) * inv;
    out->m[2][0] = c02 * inv;
    out->m[2][1] = (m[0][1] * m[2][0] - m[0][0] * m[2][1]) * inv;
    out->m[2][2] = (m[0][0] * m[1][1] - m[0][1] * m[1][0]) * inv;
    return 1;
}

/* Cholesky factor of a 6x6 symmetric positive-definite matrix (lower); 0 on failure. */
int gc_cholesky6(const double A[6][6], double L[6][6]) {
    memset(L, 0, sizeof(double) * 36);
    for (int i = 0; i < 6; ++i) {
        for (int j = 0; j <= i; ++j) {
            double s = A[i][j];
            for (int k = 0; k < j; ++k) s -= L[i][k] * L[j][k];
            if (i == j) {
                if (!(s > 0.0)) return 0;
                L[i][i] = sqrt(s);
            } else {
                L[i][j] = s / L[j][j];
            }
        }
    }
    return 1;
}

void gc_cholesky_solve6(const double L[6][6], const double b[6], double x[6]) {
    double y[6];
    for (int i = 0; i < 6; ++i) {
        double s = b[i];
        for (int k = 0; k < i; ++k) s -= L[i][k] * y[k];
        y[i] = s / L[i][i];
    }
    for (int i = 5; i >= 0; --i) {
        double s = y[i];
        for (int k = i + 1; k < 6; ++k) s -= L[k][i] * x[k];
        x[i] = s / L[i][i];
    }
}

/* R A R^T: a body-frame tensor in world axes. */
gcMat3 gc_to_world(const gcMat3 *R, const gcMat3 *A) {
    gcMat3 RA = gc_mat3_mul(R, A);
    gcMat3 Rt = gc_mat3_transpose(R);
    return gc_mat3_mul(&RA, &Rt);
}

/* |det| of the d x d matrix a (row-major, destroyed), partial pivoting. */
double gc_abs_det(double *a, int d) {
    double det = 1.0;
    for (int c = 0; c < d; ++c) {
        int piv = c;
        for (int r = c + 1; r < d; ++r)
            if (fabs(a[r * d + c]) > fabs(a[piv * d + c])) piv = r;
        double p = a[piv * d + c];
        if (p == 0.0) return 0.0;
        if (piv != c)
            for (int k = 0; k < d; ++k) {
                double t = a[c * d + k];
                a[c * d + k] = a[piv * d + k];
                a[piv * d + k] = t;
            }
        det *= p;
        for (int r = c + 1; r < d; ++r) {
            double m = a[r * d + c] / p;
            for (int k = c + 1; k < d; ++k) a[r * d + k] -= m * a[c * d + k];
        }
    }
    return fabs(det);
}
