/* GJK+EPA benchmark: graspcore against libccd on the same hulls.
 *
 * For each hull size (8, 32, 128 vertices) a fixed set of random pairs is built:
 * vertices on random ellipsoids (so every point is a hull vertex), random poses,
 * half of the pairs overlapping and half separated. Each method answers every
 * pair; the methods are interleaved inside each round and the time per query is
 * the best of several rounds.
 *
 * What is compared:
 *   ours penetration  gc_penetration: the same task as ccdGJKPenetration. GJK stops
 *                     at the first separating axis (separated pairs get "separated"
 *                     and a lower bound, no distance); overlapping pairs get GJK + EPA
 *                     depth/normal/witness points (identical to gc_collide's).
 *   ours distance     gc_collide: separated pairs get the exact distance and witness
 *                     points (GJK run to convergence), overlapping ones GJK + EPA.
 *                     libccd 2.1 has no distance query, so its rows against libccd
 *                     are informative only (more work than libccd does).
 *   libccd            ccdGJKPenetration: GJK intersection test, then EPA when
 *                     overlapping; separated pairs only get the boolean "no contact".
 *                     Support callback = gc_hull_support on the same gcHull (SoA SSE2
 *                     scan up to 128 vertices), direction rotated into the local frame,
 *                     point rotated back: the same support work as ours.
 *   libccd-brute      same, with a plain scalar loop over the vertex array as support.
 *   libccd-MPR        ccdMPRPenetration (different algorithm, approximate depth).
 * The libccd column of the summary is the faster of libccd and libccd-brute.
 * libccd runs with its default tolerances (epa_tolerance 1e-4 absolute); ours uses
 * 1e-9 relative to the pair's size, i.e. tighter. */
#define _POSIX_C_SOURCE 199309L
#include "geometry/geometry.h"

#include <ccd/ccd.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define NUM_PAIRS 1000
#define ROUNDS 15

static uint64_t rng_state = 12345;
static double rng_uniform(void) {
    uint64_t z = (rng_state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    z ^= z >> 31;
    return (double)(z >> 11) * (1.0 / 9007199254740992.0);
}
static double rng_range(double lo, double hi) { return lo + (hi - lo) * rng_uniform(); }

static gcQuat random_quat(void) {
    gcQuat q = {rng_range(-1, 1), rng_range(-1, 1), rng_range(-1, 1), rng_range(-1, 1)};
    if (q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z < 1e-6) q.w = 1;
    return gc_quat_normalize(q);
}

static void random_ellipsoid_hull(gcHull *h, int n) {
    double *p = (double *)malloc(sizeof(double) * 3 * (size_t)n);
    double ax = rng_range(0.3, 1.0), ay = rng_range(0.3, 1.0), az = rng_range(0.3, 1.0);
    for (;;) {
        for (int i = 0; i < n; ++i) {
            gcVec3 v;
            do v = gc_v3(rng_range(-1, 1), rng_range(-1, 1), rng_range(-1, 1));
            while (gc_len2(v) > 1 || gc_len2(v) < 1e-2);
            v = gc_normalize(v);
            p[3 * i] = ax * v.x;
            p[3 * i + 1] = ay * v.y;
            p[3 * i + 2] = az * v.z;
        }
        if (gc_hull_build(p, n, 0, 0, h) == GC_OK && h->num_vertices == n) break;
        gc_hull_free(h);
    }
    free(p);
}

typedef struct Shape {
    const gcHull *hull;
    gcTransform t;
} Shape;

typedef struct Pair {
    gcHull a, b;
    Shape sa, sb;
    int overlapping;
} Pair;

/* libccd callbacks over the same hull data. */
static void ccd_support_ours(const void *obj, const ccd_vec3_t *dir, ccd_vec3_t *out) {
    const Shape *s = (const Shape *)obj;
    gcVec3 d = gc_mat3_tmul_vec(&s->t.R, gc_v3(dir->v[0], dir->v[1], dir->v[2]));
    gcVec3 w = gc_transform_point(&s->t, gc_hull_support(s->hull, d));
    out->v[0] = w.x;
    out->v[1] = w.y;
    out->v[2] = w.z;
}
static void ccd_support_brute(const void *obj, const ccd_vec3_t *dir, ccd_vec3_t *out) {
    const Shape *s = (const Shape *)obj;
    gcVec3 d = gc_mat3_tmul_vec(&s->t.R, gc_v3(dir->v[0], dir->v[1], dir->v[2]));
    const gcVec3 *v = s->hull->vertices;
    int best = 0;
    double best_dot = gc_dot(v[0], d);
    for (int i = 1; i < s->hull->num_vertices; ++i) {
        double x = gc_dot(v[i], d);
        if (x > best_dot) { best_dot = x; best = i; }
    }
    gcVec3 w = gc_transform_point(&s->t, v[best]);
    out->v[0] = w.x;
    out->v[1] = w.y;
    out->v[2] = w.z;
}
static void ccd_center(const void *obj, ccd_vec3_t *out) {
    const Shape *s = (const Shape *)obj;
    gcVec3 c = gc_transform_point(&s->t, s->hull->centroid);
    out->v[0] = c.x;
    out->v[1] = c.y;
    out->v[2] = c.z;
}

static double now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e9 + ts.tv_nsec;
}

static volatile double sink;

enum { OURS_PEN, OURS, CCD_GJK, CCD_GJK_BRUTE, CCD_MPR, NUM_METHODS };

static void run_one(int method, Pair *p, ccd_t *ccd, double *depth_out, int *hit_out) {
    if (method == OURS_PEN) {
        gcContact c;
        int separated;
        gc_penetration(&p->a, &p->sa.t, &p->b, &p->sb.t, &c, &separated);
        *hit_out = !separated;
        *depth_out = separated ? 0 : -c.distance;
        return;
    }
    if (method == OURS) {
        gcContact c;
        gc_collide(&p->a, &p->sa.t, &p->b, &p->sb.t, &c);
        *depth_out = -c.distance;
        *hit_out = c.distance < 0;
        return;
    }
    ccd_real_t depth = 0;
    ccd_vec3_t dir, pos;
    int r;
    if (method == CCD_MPR) r = ccdMPRPenetration(&p->sa, &p->sb, ccd, &depth, &dir, &pos);
    else r = ccdGJKPenetration(&p->sa, &p->sb, ccd, &depth, &dir, &pos);
    *hit_out = r == 0;
    *depth_out = r == 0 ? depth : 0;
}

/* Mean ns per query over the selected pairs (only: -1 all, 0 separated, 1 overlapping). */
static double time_once(int method, Pair *pairs, int n, ccd_t *ccd, int only) {
    double acc = 0;
    int count = 0;
    double t0 = now_ns();
    for (int i = 0; i < n; ++i) {
        if (only >= 0 && pairs[i].overlapping != only) continue;
        double d;
        int hit;
        run_one(method, &pairs[i], ccd, &d, &hit);
        acc += d + hit;
        ++count;
    }
    double t = (now_ns() - t0) / count;
    sink += acc;
    return t;
}

/* Usage: bench_gjk                      the tables (Markdown on stdout)
 *        bench_gjk profile <m> <size> [ov]  run method m (0 ours penetration, 1 ours
 *                                         distance, 2 libccd, 3 libccd-brute, 4 MPR)
 *                                         for ~3 s on one size, for perf; ov = 0/1 keeps
 *                                         only separated/overlapping pairs. */
int main(int argc, char **argv) {
    int profile_method = -1, profile_size = 0, profile_only = -1;
    if (argc >= 4 && !strcmp(argv[1], "profile")) {
        profile_method = atoi(argv[2]);
        profile_size = atoi(argv[3]);
        if (argc >= 5) profile_only = atoi(argv[4]);
        if (profile_method < 0 || profile_method >= NUM_METHODS) return 2;
    }
    static const int sizes[3] = {8, 32, 128};
    static const char *names[NUM_METHODS] = {"ours penetration", "ours distance", "libccd GJK+EPA",
                                             "libccd GJK+EPA (brute support)", "libccd MPR"};
    double ns[3][NUM_METHODS], ns_split[3][NUM_METHODS][2];
    double max_depth_diff[3] = {0}, mean_depth_diff[3] = {0};
    int disagree[3] = {0}, pen_disagree[3] = {0}, ccd_deeper[3] = {0}, ccd_not_separating[3] = {0}, ours_not_separating[3] = {0},
        num_overlapping[3] = {0};
    for (int si = 0; si < 3; ++si) {
        int nv = sizes[si];
        if (profile_method >= 0 && nv != profile_size) continue;
        Pair *pairs = (Pair *)calloc(NUM_PAIRS, sizeof(Pair));
        int want[2] = {NUM_PAIRS / 2, NUM_PAIRS - NUM_PAIRS / 2}, have[2] = {0, 0}, n = 0;
        while (n < NUM_PAIRS) {
            Pair *p = &pairs[n];
            random_ellipsoid_hull(&p->a, nv);
            random_ellipsoid_hull(&p->b, nv);
            p->sa.hull = &p->a;
            p->sb.hull = &p->b;
            p->sa.t.p = gc_v3(rng_range(-1, 1), rng_range(-1, 1), rng_range(-1, 1));
            p->sa.t.R = gc_quat_to_mat3(random_quat());
            gcVec3 dir = gc_normalize(gc_v3(rng_range(-1, 1), rng_range(-1, 1), rng_range(-1, 1)));
            p->sb.t.p = gc_madd(p->sa.t.p, dir, rng_range(0.0, 2.5));
            p->sb.t.R = gc_quat_to_mat3(random_quat());
            gcContact c;
            gc_collide(&p->a, &p->sa.t, &p->b, &p->sb.t, &c);
            int ov = c.distance < 0;
            if (have[ov] >= want[ov]) {
                gc_hull_free(&p->a);
                gc_hull_free(&p->b);
                continue;
            }
            p->overlapping = ov;
            have[ov]++;
            ++n;
        }
        ccd_t ccd_ours, ccd_brute;
        CCD_INIT(&ccd_ours);
        ccd_ours.support1 = ccd_ours.support2 = ccd_support_ours;
        ccd_ours.center1 = ccd_ours.center2 = ccd_center;
        ccd_ours.max_iterations = 100;
        ccd_brute = ccd_ours;
        ccd_brute.support1 = ccd_brute.support2 = ccd_support_brute;
        ccd_t *ccds[NUM_METHODS] = {NULL, NULL, &ccd_ours, &ccd_brute, &ccd_ours};
        if (profile_method >= 0) {
            double t0 = now_ns();
            while (now_ns() - t0 < 3e9) time_once(profile_method, pairs, n, ccds[profile_method], profile_only);
            return 0;
        }
        /* Agreement on the same pairs (overlap decision and depth). */
        double sum_diff = 0;
        int n_ov = 0;
        for (int i = 0; i < n; ++i) {
            double d0, d1;
            int h0, h1;
            run_one(OURS, &pairs[i], NULL, &d0, &h0);
            run_one(CCD_GJK, &pairs[i], &ccd_ours, &d1, &h1);
            if (h0 != h1) disagree[si]++;
            {
                double dp;
                int hp;
                run_one(OURS_PEN, &pairs[i], NULL, &dp, &hp);
                if (hp != h0 || (hp && dp != d0)) pen_disagree[si]++;
            }
            if (h0 && h1) {
                /* Does each answer's translation of B actually separate the pair? */
                num_overlapping[si]++;
                gcContact c, moved;
                gc_collide(&pairs[i].a, &pairs[i].sa.t, &pairs[i].b, &pairs[i].sb.t, &c);
                gcTransform tb = pairs[i].sb.t;
                tb.p = gc_madd(pairs[i].sb.t.p, c.normal, d0 * (1 + 1e-6) + 1e-6);
                gc_collide(&pairs[i].a, &pairs[i].sa.t, &pairs[i].b, &tb, &moved);
                if (!(moved.distance > 0)) ours_not_separating[si]++;
                ccd_real_t depth;
                ccd_vec3_t dir, pos;
                ccdGJKPenetration(&pairs[i].sa, &pairs[i].sb, &ccd_ours, &depth, &dir, &pos);
                tb.p = gc_madd(pairs[i].sb.t.p, gc_v3(dir.v[0], dir.v[1], dir.v[2]), depth * (1 + 1e-6) + 1e-6);
                gc_collide(&pairs[i].a, &pairs[i].sa.t, &pairs[i].b, &tb, &moved);
                if (!(moved.distance > 0)) ccd_not_separating[si]++;
            }
            if (h0 && h1) {
                double diff = fabs(d0 - d1);
                if (d1 > d0 + 1e-9) ccd_deeper[si]++;
                sum_diff += diff;
                n_ov++;
                if (diff > max_depth_diff[si]) max_depth_diff[si] = diff;
            }
        }
        mean_depth_diff[si] = n_ov ? sum_diff / n_ov : 0;
        /* Methods interleaved inside each round and the best round kept: the
         * machine's background load then hits every method alike. */
        for (int m = 0; m < NUM_METHODS; ++m) {
            ns[si][m] = 1e300;
            ns_split[si][m][0] = ns_split[si][m][1] = 1e300;
        }
        for (int round = 0; round < ROUNDS; ++round)
            for (int m = 0; m < NUM_METHODS; ++m) {
                ns[si][m] = fmin(ns[si][m], time_once(m, pairs, n, ccds[m], -1));
                for (int ov = 0; ov < 2; ++ov)
                    ns_split[si][m][ov] = fmin(ns_split[si][m][ov], time_once(m, pairs, n, ccds[m], ov));
            }
        for (int i = 0; i < n; ++i) {
            gc_hull_free(&pairs[i].a);
            gc_hull_free(&pairs[i].b);
        }
        free(pairs);
    }
    printf("## GJK+EPA per query: graspcore vs libccd (%d pairs per size, half overlapping)\n\n", NUM_PAIRS);
    printf("Same task: gc_penetration vs ccdGJKPenetration (separated pairs: stop at the first\n"
           "separating axis; overlapping pairs: GJK + EPA depth, normal, witness points).\n\n");
    printf("| vertices | ours ns/query | libccd ns/query | ratio ours/libccd | overlapping: ours / libccd | separated: ours / libccd |\n");
    printf("|---:|---:|---:|---:|---:|---:|\n");
    for (int si = 0; si < 3; ++si) {
        int c = ns[si][CCD_GJK] <= ns[si][CCD_GJK_BRUTE] ? CCD_GJK : CCD_GJK_BRUTE;
        printf("| %d | %.0f | %.0f | %.2f | %.0f / %.0f | %.0f / %.0f |\n", sizes[si], ns[si][OURS_PEN], ns[si][c],
               ns[si][OURS_PEN] / ns[si][c], ns_split[si][OURS_PEN][1], ns_split[si][c][1], ns_split[si][OURS_PEN][0],
               ns_split[si][c][0]);
    }
    printf("\nInformative only (different task): gc_collide, which also computes the exact distance and\n"
           "witness points of separated pairs, vs ccdGJKPenetration (libccd 2.1 has no distance query).\n\n");
    printf("| vertices | ours distance ns/query | libccd ns/query | ratio ours/libccd | overlapping: ours / libccd | separated: ours / libccd |\n");
    printf("|---:|---:|---:|---:|---:|---:|\n");
    for (int si = 0; si < 3; ++si) {
        int c = ns[si][CCD_GJK] <= ns[si][CCD_GJK_BRUTE] ? CCD_GJK : CCD_GJK_BRUTE;
        printf("| %d | %.0f | %.0f | %.2f | %.0f / %.0f | %.0f / %.0f |\n", sizes[si], ns[si][OURS], ns[si][c],
               ns[si][OURS] / ns[si][c], ns_split[si][OURS][1], ns_split[si][c][1], ns_split[si][OURS][0],
               ns_split[si][c][0]);
    }
    printf("\nlibccd = ccdGJKPenetration (GJK + EPA, default tolerances), the faster of its two support\n"
           "callbacks (gc_hull_support or a plain loop). Times: best of %d interleaved rounds.\n", ROUNDS);
    printf("\n### Details (ns/query: all / overlapping / separated)\n\n| vertices |");
    for (int m = 0; m < NUM_METHODS; ++m) printf(" %s |", names[m]);
    printf(" overlap disagreements ours/libccd | penetration vs distance disagreements | mean / max depth diff |"
           " libccd deeper | answer fails to separate: ours / libccd |\n|---:|");
    for (int m = 0; m < NUM_METHODS; ++m) printf("---:|");
    printf("---:|---:|---:|---:|---:|\n");
    for (int si = 0; si < 3; ++si) {
        printf("| %d |", sizes[si]);
        for (int m = 0; m < NUM_METHODS; ++m)
            printf(" %.0f / %.0f / %.0f |", ns[si][m], ns_split[si][m][1], ns_split[si][m][0]);
        printf(" %d | %d | %.2g / %.2g | %d | %d / %d of %d |\n", disagree[si], pen_disagree[si], mean_depth_diff[si],
               max_depth_diff[si], ccd_deeper[si], ours_not_separating[si], ccd_not_separating[si],
               num_overlapping[si]);
    }
    return sink == 12345.678 ? 1 : 0;
}
