/* The bare-loop baseline of bench/bench_jitter.py: the haptic loop's wait and nothing else.
 *
 * One thread sleeps to absolute CLOCK_MONOTONIC deadlines (clock_nanosleep TIMER_ABSTIME) at
 * the haptic rate, set up as the runtime's haptic thread sets itself up (native/src/runtime_threads.c,
 * haptic_thread_setup: SCHED_FIFO at the given priority, else normal priority with a 0.1 ms
 * time slice; timer slack 1 ns; its stack pre-faulted and locked), does no work, and measures
 * its periods exactly as the runtime does: period
 * error = |wake-up - previous wake-up - nominal period| in 1 us bins, p50/p99 as the upper
 * edge of their bin (capped at the maximum), "late" = error larger than one period, and the
 * latest wake-up after a deadline. Deadlines already missed are skipped, as in the runtime.
 * bench_jitter.py runs it under the same Python CPU load as the runtime, so that the two
 * can be compared within one run on one machine.
 *
 *     jitter_baseline [--seconds 60] [--rate 1000] [--priority 80] [--timer-slack-ns 1]
 *                     [--slice-us 100]
 *
 * --priority 0 stays at normal priority; --timer-slack-ns 0 keeps the thread's default slack;
 * --slice-us 0 keeps the default time slice at normal priority.
 * Prints one JSON object on stdout. Build: cc -O2 -std=c11 jitter_baseline.c -o jitter_baseline */
#define _GNU_SOURCE

#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <sched.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#define NS_PER_S 1000000000LL
#define BINS 20000
#define STACK_PREFAULT (64 * 1024)

static uint32_t hist[BINS];

/* struct sched_attr (SCHED_ATTR_SIZE_VER0); glibc 2.36 has no sched_setattr wrapper. */
struct sched_attr_v0 {
    uint32_t size, policy;
    uint64_t flags;
    int32_t nice;
    uint32_t priority;
    uint64_t runtime, deadline, period;
};

/* A shorter EEVDF time slice at normal priority (Linux >= 6.12); 1 when the kernel took it. */
static int request_slice(uint64_t ns) {
    struct sched_attr_v0 a;
    memset(&a, 0, sizeof a);
    if (syscall(SYS_sched_getattr, 0, &a, sizeof a, 0) != 0 || a.policy != SCHED_OTHER) return 0;
    a.size = sizeof a;
    a.flags &= 1;
    a.runtime = ns;
    a.deadline = a.period = 0;
    if (syscall(SYS_sched_setattr, 0, &a, 0) != 0) return 0;
    memset(&a, 0, sizeof a);
    return syscall(SYS_sched_getattr, 0, &a, sizeof a, 0) == 0 && a.runtime == ns;
}

static int64_t now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * NS_PER_S + ts.tv_nsec;
}

static void sleep_until_ns(int64_t t) {
    struct timespec ts = {(time_t)(t / NS_PER_S), (long)(t % NS_PER_S)};
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR) {
    }
}

static double percentile_us(uint64_t total, double q) {
    if (total == 0) return 0.0;
    uint64_t target = (uint64_t)ceil(q * (double)total), sum = 0;
    if (target < 1) target = 1;
    for (int i = 0; i < BINS; ++i) {
        sum += hist[i];
        if (sum >= target) return (double)(i + 1);
    }
    return (double)BINS;
}

/* Touches the next STACK_PREFAULT bytes of this thread's stack, so that later calls do not
 * fault them in. noinline: the array must live below the caller's frame. */
__attribute__((noinline)) static void prefault_stack(void) {
    volatile unsigned char pad[STACK_PREFAULT];
    for (size_t i = 0; i < sizeof pad; i += 4096) pad[i] = 0;
    pad[sizeof pad - 1] = 0;
}

int main(int argc, char **argv) {
    double seconds = 60.0, rate = 1000.0;
    int priority = 80;
    long slack = 1, slice_us = 100;
    for (int i = 1; i < argc; ++i) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!v) {
            fprintf(stderr, "jitter_baseline: %s needs a value\n", a);
            return 2;
        }
        if (!strcmp(a, "--seconds")) seconds = atof(v);
        else if (!strcmp(a, "--rate")) rate = atof(v);
        else if (!strcmp(a, "--priority")) priority = atoi(v);
        else if (!strcmp(a, "--timer-slack-ns")) slack = atol(v);
        else if (!strcmp(a, "--slice-us")) slice_us = atol(v);
        else {
            fprintf(stderr, "jitter_baseline: unknown argument %s\n", a);
            return 2;
        }
        ++i;
    }
    if (!(seconds > 0.0) || !(rate >= 10.0 && rate <= 20000.0) || priority < 0 || priority > 99 || slack < 0 ||
        slice_us < 0) {
        fprintf(stderr, "jitter_baseline: bad arguments\n");
        return 2;
    }

    char note[160] = "";
    int rt = 0;
    if (priority > 0) {
        struct sched_param sp;
        memset(&sp, 0, sizeof sp);
        sp.sched_priority = priority;
        int e = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
        rt = e == 0;
        if (rt)
            snprintf(note, sizeof note, "bare loop at SCHED_FIFO %d", priority);
        else
            snprintf(note, sizeof note, "SCHED_FIFO %d refused (%s): bare loop at normal priority", priority,
                     strerror(e));
    } else {
        snprintf(note, sizeof note, "bare loop at normal priority");
    }
    int slice = 0;
    if (!rt && slice_us > 0) {
        slice = request_slice((uint64_t)slice_us * 1000);
        size_t n = strlen(note);
        snprintf(note + n, sizeof note - n, slice ? ", %g ms slice" : ", default slice", slice_us * 1e-3);
    }
    if (slack > 0) prctl(PR_SET_TIMERSLACK, (unsigned long)slack, 0, 0, 0);
    long slack_now = prctl(PR_GET_TIMERSLACK, 0, 0, 0, 0);
    prefault_stack();
    char stack_probe;
    uintptr_t top = (uintptr_t)&stack_probe & ~(uintptr_t)4095;
    int stack_locked = mlock((void *)(top - STACK_PREFAULT), STACK_PREFAULT) == 0;

    const int64_t period = (int64_t)(1e9 / rate + 0.5);
    const int64_t ticks = (int64_t)(seconds * rate + 0.5);
    int64_t deadline = now_ns() + period, prev = INT64_MIN;
    int64_t err_max = 0, wake_max = 0;
    uint64_t late = 0, overruns = 0, periods = 0;
    struct rusage ru0, ru1;
    getrusage(RUSAGE_THREAD, &ru0);
    for (int64_t k = 0; k < ticks; ++k) {
        sleep_until_ns(deadline);
        int64_t wake = now_ns();
        if (wake - deadline > wake_max) wake_max = wake - deadline;
        if (prev != INT64_MIN) {
            int64_t err = wake - prev - period;
            if (err < 0) err = -err;
            int64_t bin = err / 1000;
            hist[bin < BINS ? bin : BINS - 1]++;
            if (err > err_max) err_max = err;
            if (err > period) late++;
            periods++;
        }
        prev = wake;
        int64_t end = now_ns();
        deadline += period;
        if (end > deadline) { /* as the runtime: skip the deadlines already missed */
            overruns++;
            deadline += ((end - deadline) / period + 1) * period;
        }
    }
    getrusage(RUSAGE_THREAD, &ru1);
    double max_us = (double)err_max * 1e-3;
    printf("{\"priority_note\": \"%s\", \"rt_priority\": %d, \"priority_requested\": %d, "
           "\"timer_slack_ns\": %ld, \"slice_us\": %ld, \"stack_locked\": %d, \"seconds\": %g, \"rate\": %g, "
           "\"periods\": %llu, \"jitter_p50_us\": %g, \"jitter_p99_us\": %g, \"jitter_max_us\": %g, "
           "\"late_periods\": %llu, \"overruns\": %llu, \"wake_max_us\": %g, "
           "\"minor_faults\": %ld, \"major_faults\": %ld, \"involuntary_switches\": %ld}\n",
           note, rt, priority, slack_now, slice ? slice_us : 0, stack_locked, seconds, rate, (unsigned long long)periods,
           fmin(percentile_us(periods, 0.50), max_us), fmin(percentile_us(periods, 0.99), max_us), max_us,
           (unsigned long long)late, (unsigned long long)overruns, (double)wake_max * 1e-3,
           ru1.ru_minflt - ru0.ru_minflt, ru1.ru_majflt - ru0.ru_majflt, ru1.ru_nivcsw - ru0.ru_nivcsw);
    return 0;
}
