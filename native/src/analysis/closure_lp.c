/* The closure linear program (gc_closure_lp): the largest margin t by which the origin lies inside
 * the convex hull of the points, by a capped two-phase simplex method on a dense tableau. */
#include "analysis_internal.h"

/* Largest t with sum_i lambda_i x_i = 0, sum_i lambda_i = 1, lambda_i >= t (lambda_i >= -1 too,
 * which only matters when t < 0). With lambda_i = mu_i + tau - 1 (mu, tau >= 0) it is the
 * standard form  sum mu_i x_i + tau S = S,  sum mu_i + n tau = 1 + n,  maximise tau,  S = sum x_i,
 * solved by the two-phase simplex method on a dense tableau of d + 1 rows (artificial variables
 * first, then tau). Dantzig's rule, switching to Bland's (no cycling) after a run of degenerate
 * pivots; capped. The points are scaled by 1 / the largest norm (t does not change). */
static void lp_pivot(double *T, int rows, int cols, int r, int c) {
    double *pr = T + (size_t)r * cols;
    double inv = 1.0 / pr[c];
    for (int k = 0; k < cols; ++k) pr[k] *= inv;
    pr[c] = 1.0;
    for (int q = 0; q <= rows; ++q) {
        if (q == r) continue;
        double *pq = T + (size_t)q * cols, m = pq[c];
        if (m == 0.0) continue;
        for (int k = 0; k < cols; ++k) pq[k] -= m * pr[k];
        pq[c] = 0.0;
    }
}

/* Minimises the objective row (row `rows`) over the columns [0, allowed). 1 when optimal, 0 when
 * the cap was reached; -1 unbounded (cannot happen here: tau <= (1 + n) / n). */
static int lp_minimise(double *T, int *basis, int rows, int cols, int allowed, int cap, int bland) {
    const double cost_eps = 1e-12, pivot_eps = 1e-11;
    double *obj = T + (size_t)rows * cols;
    int rhs = cols - 1, degenerate_run = 0;
    for (int it = 0; it < cap; ++it) {
        int enter = -1;
        double most = -cost_eps;
        for (int j = 0; j < allowed; ++j) {
            if (obj[j] < most) {
                enter = j;
                if (bland) break;
                most = obj[j];
            }
        }
        if (enter < 0) return 1;
        int leave = -1;
        double ratio = INFINITY;
        for (int r = 0; r < rows; ++r) {
            double a = T[(size_t)r * cols + enter];
            if (a <= pivot_eps) continue;
            double q = T[(size_t)r * cols + rhs] / a;
            if (q < ratio || (q == ratio && basis[r] < basis[leave])) ratio = q, leave = r;
        }
        if (leave < 0) return -1;
        /* Near-degenerate pivots (a step of rounding size) count as degenerate: Dantzig's rule
         * can cycle through them numerically (an antipodal pair tilted by 1e-10 did). Past
         * rows + allowed pivots in all, Bland's rule from then on too. */
        degenerate_run = ratio <= 1e-13 ? degenerate_run + 1 : 0;
        if (degenerate_run > 2 * rows || it > rows + allowed) bland = 1;
        lp_pivot(T, rows, cols, leave, enter);
        basis[leave] = enter;
    }
    return 0;
}

/* The tableau's constraint rows for the points (scaled by inv), objective row and artificial
 * columns zero. */
static void lp_fill(double *T, const double *points, int n, int d, int cols, double inv) {
    int rows = d + 1, tau = n, rhs = cols - 1;
    memset(T, 0, sizeof(double) * (size_t)(rows + 1) * (size_t)cols);
    for (int i = 0; i < n; ++i) {
        for (int k = 0; k < d; ++k) {
            double x = points[(size_t)i * d + k] * inv;
            T[(size_t)k * cols + i] = x;
            T[(size_t)k * cols + tau] += x;
            T[(size_t)k * cols + rhs] += x;
        }
        T[(size_t)d * cols + i] = 1.0;
    }
    T[(size_t)d * cols + tau] = n;
    T[(size_t)d * cols + rhs] = 1.0 + n;
}

/* Makes the columns warm[0 .. rows) basic (Gauss-Jordan, largest pivot per column). 1 when they
 * form a basis whose solution is feasible (right-hand sides >= 0 up to rounding). */
static int lp_warm_basis(double *T, int *basis, int rows, int cols, const int *warm) {
    int rhs = cols - 1;
    for (int r = 0; r < rows; ++r) basis[r] = -1;
    for (int k = 0; k < rows; ++k) {
        int c = warm[k], pick = -1;
        double big = 1e-9;
        for (int r = 0; r < rows; ++r)
            if (basis[r] < 0 && fabs(T[(size_t)r * cols + c]) > big) big = fabs(T[(size_t)r * cols + c]), pick = r;
        if (pick < 0) return 0;
        lp_pivot(T, rows, cols, pick, c);
        basis[pick] = c;
    }
    for (int r = 0; r < rows; ++r) {
        double *v = &T[(size_t)r * cols + rhs];
        if (*v < -1e-9) return 0;
        if (*v < 0.0) *v = 0.0;
    }
    return 1;
}

/* gc_closure_lp; warm (d + 1 column indices, or NULL) is an optimal basis of an earlier LP over
 * the same number of points, tried first (a nearby problem's basis is often still optimal or a
 * pivot or two away), and holds this one's on return (warm[0] -1 when there is none). */
gcStatus gc_closure_lp_warm(gcGraspWorkspace *ws, const double *points, int n, int d, int *warm, double *t_max) {
    *t_max = -INFINITY;
    if (d < 1 || d > D) return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "d: %d, expected 1 to %d", d, D);
    int start[D + 1], has_warm = warm && warm[0] >= 0;
    if (has_warm) memcpy(start, warm, sizeof(int) * (size_t)(d + 1));
    if (warm) warm[0] = -1;
    if (n < 1) return GC_OK;
    int rows = d + 1, tau = n, art = n + 1, cols = n + 1 + rows + 1, rhs = cols - 1;
    size_t need = (size_t)(rows + 1) * (size_t)cols;
    if (need > (size_t)ws->cap_lp) {
        if (!gc_grasp_grow((void **)&ws->lp, need, sizeof(double)) || !gc_grasp_grow((void **)&ws->lp_basis, D + 1, sizeof(int)))
            return gc_grasp_set_error(ws, GC_ERR_NO_MEMORY, "workspace: out of memory for the closure LP");
        ws->cap_lp = (int)need;
    }
    double *T = ws->lp;
    int *basis = ws->lp_basis;
    double scale = 0.0;
    for (int i = 0; i < n; ++i) scale = fmax(scale, dotd(points + (size_t)i * d, points + (size_t)i * d, d));
    if (!(scale > 0.0)) return GC_OK;
    double inv = 1.0 / sqrt(scale);
    int cap = 50 * (n + rows) + 100, res;
    double *obj = T + (size_t)rows * cols;
    lp_fill(T, points, n, d, cols, inv);
    if (!has_warm || !lp_warm_basis(T, basis, rows, cols, start)) {
        /* Phase 1: artificial a_r in row r (rows with a negative right-hand side negated first).
         * It cannot be unbounded in exact arithmetic (the artificials' sum is >= 0); a stop on
         * "unbounded" is rounding, short of a feasible point, and would read as "t < -1" (three
         * fingers at 120 degrees tilted by 1e-3, mu 10, t* 0.04, did): phase 1 again with
         * Bland's rule from the start, which takes another path. */
        for (int attempt = 0; attempt < 2; ++attempt) {
            if (has_warm || attempt) lp_fill(T, points, n, d, cols, inv);
            for (int r = 0; r < rows; ++r) {
                double *pr = T + (size_t)r * cols;
                if (pr[rhs] < 0.0)
                    for (int k = 0; k < cols; ++k) pr[k] = -pr[k];
                pr[art + r] = 1.0;
                basis[r] = art + r;
                for (int k = 0; k < art; ++k) obj[k] -= pr[k];
                obj[rhs] -= pr[rhs];
            }
            res = lp_minimise(T, basis, rows, cols, art + rows, cap, attempt);
            if (res != -1) break;
        }
        if (res == 0)
            return gc_grasp_set_error(ws, GC_ERR_DEGENERATE, "points: the closure LP did not converge in %d pivots", cap);
        if (-obj[rhs] > 1e-9 * (1.0 + n)) return GC_OK;   /* infeasible: t < -1, the origin is far outside */
        /* Artificials still basic (at zero) leave for any structural column; a row with none is
         * redundant and is emptied. */
        for (int r = 0; r < rows; ++r) {
            if (basis[r] < art) continue;
            double *pr = T + (size_t)r * cols;
            int c = -1;
            double big = 1e-9;
            for (int j = 0; j < art; ++j)
                if (fabs(pr[j]) > big) big = fabs(pr[j]), c = j;
            if (c >= 0) {
                lp_pivot(T, rows, cols, r, c);
                basis[r] = c;
            } else {
                for (int k = 0; k < cols; ++k) pr[k] = 0.0;
            }
        }
    }
    /* Phase 2: minimise -tau, artificials barred. */
    for (int k = 0; k < cols; ++k) obj[k] = 0.0;
    obj[tau] = -1.0;
    for (int r = 0; r < rows; ++r)
        if (basis[r] == tau) {
            const double *pr = T + (size_t)r * cols;
            for (int k = 0; k < cols; ++k) obj[k] += pr[k];
            obj[tau] = 0.0;
        }
    res = lp_minimise(T, basis, rows, cols, art, cap, 0);
    if (res == 0) return gc_grasp_set_error(ws, GC_ERR_DEGENERATE, "points: the closure LP did not converge in %d pivots", cap);
    double tau_value = 0.0;
    int structural = 1;
    for (int r = 0; r < rows; ++r) {
        if (basis[r] == tau) tau_value = T[(size_t)r * cols + rhs];
        structural = structural && basis[r] < art;
    }
    *t_max = tau_value - 1.0;
    if (warm && structural) memcpy(warm, basis, sizeof(int) * (size_t)rows);
    return GC_OK;
}

gcStatus gc_closure_lp(gcGraspWorkspace *ws, const double *points, int n, int d, double *t_max) {
    return gc_closure_lp_warm(ws, points, n, d, NULL, t_max);
}
