/* The period clock of the native node loop, and its real-time settings.
 *
 * Deadline k (k = 1, 2, ...) is t0 + k T on CLOCK_MONOTONIC, never a sum of
 * sleeps: bn_clock_wait sleeps with clock_nanosleep(TIMER_ABSTIME) to
 * deadline - busy_tail, then spins to the deadline (the tail absorbs the
 * wake-up latency of the sleep at the price of that much CPU).  A period whose
 * work ends after its deadline is missed and the next period starts at once;
 * the schedule stays where it is (the loop catches up), unless the wake-up is
 * more than stall_ns late: then the whole periods that passed are skipped, as
 * the Python clock does (bench/nodes/_clock.py, default_stall_s gives the value).
 */
#include <errno.h>
#include <sched.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>

#include "bn.h"

static struct timespec ts_of(int64_t ns)
{
    struct timespec ts = {(time_t)(ns / 1000000000), (long)(ns % 1000000000)};
    return ts;
}

void bn_clock_init(bn_clock_t *c, int64_t period_ns, int64_t busy_tail_ns, int64_t stall_ns,
                   uint32_t *busy, size_t busy_cap)
{
    memset(c, 0, sizeof *c);
    c->period_ns = period_ns;
    c->busy_tail_ns = busy_tail_ns < 0 ? 0 : busy_tail_ns;
    c->stall_ns = stall_ns <= 0 ? INT64_MAX : stall_ns;
    c->busy = busy;
    c->busy_cap = busy ? busy_cap : 0;
    c->st.period_ns = period_ns;
    c->st.late_min_ns = INT64_MAX;
}

void bn_clock_start(bn_clock_t *c)
{
    c->t0_ns = bn_now_ns();
    c->woke_ns = c->t0_ns;
    c->n = 0;
}

int64_t bn_clock_deadline(const bn_clock_t *c)
{
    return c->t0_ns + (int64_t)(c->n + 1) * c->period_ns;
}

int64_t bn_clock_wait(bn_clock_t *c)
{
    int64_t deadline = bn_clock_deadline(c);
    int64_t now = bn_now_ns();
    int64_t busy = now - c->woke_ns;
    bn_stats_t *st = &c->st;
    if (st->periods < c->busy_cap) {
        c->busy[st->periods] = busy > (int64_t)UINT32_MAX ? UINT32_MAX : (uint32_t)busy;
    }
    if (busy > st->busy_max_ns) {
        st->busy_max_ns = busy;
    }
    if (now > deadline) {
        st->missed++;
        int64_t behind = now - deadline;
        if (behind > c->stall_ns) {
            int64_t skip = behind / c->period_ns;
            c->t0_ns += skip * c->period_ns;
            st->skipped += (uint64_t)skip;
            st->stalls++;
        }
    } else {
        int64_t wake = deadline - c->busy_tail_ns;
        if (wake > now) {
            struct timespec ts = ts_of(wake);
            while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR) {
            }
        }
        do {
            now = bn_now_ns();
        } while (now < deadline);
    }
    int64_t late = now - deadline;
    c->woke_ns = now;
    c->n++;
    st->periods++;
    if (late > st->late_max_ns) {
        st->late_max_ns = late;
    }
    if (late < st->late_min_ns) {
        st->late_min_ns = late;
    }
    if (2 * late > c->period_ns) {
        st->late_half++;
    }
    st->wall_ns = now - c->t0_ns + (int64_t)st->skipped * c->period_ns;
    return late;
}

static int cmp_u32(const void *a, const void *b)
{
    uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return (x > y) - (x < y);
}

void bn_clock_stats(bn_clock_t *c, bn_stats_t *out)
{
    size_t n = c->st.periods < c->busy_cap ? (size_t)c->st.periods : c->busy_cap;
    *out = c->st;
    if (out->late_min_ns == INT64_MAX) {
        out->late_min_ns = 0;
    }
    out->busy_median_ns = 0;
    if (n > 0) {
        qsort(c->busy, n, sizeof c->busy[0], cmp_u32);
        out->busy_median_ns =
            n % 2 ? c->busy[n / 2] : ((int64_t)c->busy[n / 2 - 1] + c->busy[n / 2]) / 2;
    }
}

/* Touch a stack region once so that the loop's stack pages are resident
 * (mlockall(MCL_FUTURE) locks them; this faults them in before the loop). */
static void prefault_stack(void)
{
    volatile uint8_t stack[64 * 1024];
    for (size_t i = 0; i < sizeof stack; i += 4096) {
        stack[i] = 0;
    }
}

void bn_rt_apply(int priority, bool lock, int cpu, bn_rt_t *out)
{
    memset(out, 0, sizeof *out);
    out->priority = priority;
    out->cpu = -1;
    if (lock) {
        if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0) {
            out->memory_locked = 1;
            prefault_stack();
        } else {
            out->err_mlock = errno;
        }
    }
    if (cpu >= 0) {
        cpu_set_t set;
        CPU_ZERO(&set);
        CPU_SET(cpu, &set);
        if (sched_setaffinity(0, sizeof set, &set) == 0) {
            out->cpu = cpu;
        } else {
            out->err_cpu = errno;
        }
    }
    if (priority > 0) {
        struct sched_param sp;
        memset(&sp, 0, sizeof sp);
        sp.sched_priority = priority;
        if (sched_setscheduler(0, SCHED_FIFO, &sp) == 0) {
            out->fifo = 1;
        } else {
            out->err_sched = errno;
        }
    }
}

static void spin_ns(int64_t ns)
{
    int64_t end = bn_now_ns() + ns;
    while (bn_now_ns() < end) {
    }
}

int bn_timing_run(const bn_timing_cfg_t *cfg, uint32_t *busy, bn_stats_t *out)
{
    bn_clock_t c;
    bn_rt_t rt;
    struct sched_param old_param;
    cpu_set_t old_set;
    int old_policy = sched_getscheduler(0);
    if (cfg->period_ns <= 0 || old_policy < 0 || sched_getparam(0, &old_param) != 0 ||
        sched_getaffinity(0, sizeof old_set, &old_set) != 0) {
        return cfg->period_ns <= 0 ? -EINVAL : -errno;
    }
    bn_rt_apply(cfg->rt_priority, cfg->lock_memory != 0, cfg->cpu, &rt);
    bn_clock_init(&c, cfg->period_ns, cfg->busy_tail_ns, cfg->stall_ns, busy, (size_t)cfg->periods);
    bn_clock_start(&c);
    for (uint64_t k = 0; k < cfg->periods; k++) {
        if (cfg->work_ns > 0) {
            spin_ns(cfg->work_ns);
        }
        bn_clock_wait(&c);
    }
    /* the caller's thread gets its old settings back */
    if (rt.fifo) {
        sched_setscheduler(0, old_policy, &old_param);
    }
    if (rt.cpu >= 0) {
        sched_setaffinity(0, sizeof old_set, &old_set);
    }
    if (rt.memory_locked) {
        munlockall();
    }
    bn_clock_stats(&c, out);
    out->rt = rt;
    return 0;
}
