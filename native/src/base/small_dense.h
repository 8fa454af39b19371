/* Small dense matrices (small_dense.c): no world types, below every file that solves. */
#ifndef GC_SMALL_DENSE_H
#define GC_SMALL_DENSE_H

#include "gc_math.h"

/* Inverse of a 3x3; 0 when singular or not finite. */
int gc_invert_mat3(const gcMat3 *a, gcMat3 *out);
/* 6x6 Cholesky factor (lower; 0 when not positive definite) and its solve. */
int gc_cholesky6(const double A[6][6], double L[6][6]);
void gc_cholesky_solve6(const double L[6][6], const double b[6], double x[6]);
/* R A R^T: a body-frame tensor in world axes. */
gcMat3 gc_to_world(const gcMat3 *R, const gcMat3 *A);
/* |det| of the d x d matrix a (row-major, destroyed), partial pivoting. */
double gc_abs_det(double *a, int d);

#endif
