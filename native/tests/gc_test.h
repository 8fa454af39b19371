/* Minimal C test harness: GC_CHECK records a failure and goes on; main() ends with
 * gc_test_summary(), which prints "N passed, N failed" and returns the exit code. */
#ifndef GC_TEST_H
#define GC_TEST_H
#include <stdio.h>
#include <math.h>

static int gc_test_passed = 0, gc_test_failed = 0;

#define GC_CHECK(cond, ...)                                                  \
    do {                                                                     \
        if (cond) {                                                          \
            ++gc_test_passed;                                                \
        } else {                                                             \
            ++gc_test_failed;                                                \
            fprintf(stderr, "%s:%d: check failed: %s: ", __FILE__, __LINE__, #cond); \
            fprintf(stderr, __VA_ARGS__);                                    \
            fputc('\n', stderr);                                             \
        }                                                                    \
    } while (0)

#define GC_CHECK_NEAR(a, b, tol, what)                                       \
    GC_CHECK(fabs((double)(a) - (double)(b)) <= (tol), "%s: %.12g vs %.12g (tol %.3g)", \
             what, (double)(a), (double)(b), (double)(tol))

static inline int gc_test_summary(const char *name) {
    printf("%s: %d passed, %d failed\n", name, gc_test_passed, gc_test_failed);
    return gc_test_failed ? 1 : 0;
}
#endif
