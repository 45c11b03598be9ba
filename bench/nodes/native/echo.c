/* echo: the native loop's transports, codec and E2E without a plant or controller core.
 *
 * Echo mode (default): each valid PhaseSamples (length, E2E CRC, DBC ranges)
 * is answered by one PwmDuty with the same step, duty_a = (i_a + 64 A) / 128 A
 * (so a reader sees the sample was decoded), duty_b = duty_c = 0.5, enable 0,
 * packed by the C code `bench codegen` writes and protected by its E2E CRC.
 * Frames with another identifier are ignored; PhaseSamples that fail the
 * checks are counted as rejected and not answered.
 *
 * Ping mode (-P N): the other side.  Sends N PhaseSamples (steps 0, 1, ...,
 * mod 1024) one at a time, waits for the PwmDuty of the same step, and prints
 * the round-trip times (median, p99, max, in us) and the unanswered count.
 *
 * Usage: echo [-u GROUP] [-p PORT] [-s IFACE] [-n N] [-t IDLE_S] [-P N] [-w WAIT_MS]
 *   -u  udp_multicast group (default python-can's IPv6 group); -p its port (43113)
 *   -s  SocketCAN interface instead (vcan0, can0; CAN FD enabled)
 *   -n  echo: exit after N answers (default: no limit)
 *   -t  exit after this many seconds without a PhaseSamples (default 10)
 *   -P  ping mode, N round trips; -w the wait for each answer (ms, default 100)
 * Prints READY when listening, and a summary line at the end:
 *   echo: answered=A rejected=R ignored=I malformed=M send_errors=E
 *   ping: sent=S answered=A send_errors=E rtt_us median=.. p99=.. max=..
 * No allocation after the bus is open.
 */
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "bench_dbc.h"
#include "bench_e2e.h"
#include "bn.h"

#define STEP_MASK 1023u     /* PhaseSamples.step and PwmDuty.step: 10 bits */
#define PING_MAX 1000000    /* round trips kept for the statistics */
#define DEFAULT_GROUP "ff15:7079:7468:6f6e:6465:6d6f:6d63:6173"

static volatile sig_atomic_t stop;
static uint32_t rtt_ns[PING_MAX];

static void on_signal(int sig)
{
    (void)sig;
    stop = 1;
}

static int cmp_u32(const void *a, const void *b)
{
    uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return (x > y) - (x < y);
}

/* A PwmDuty answering sample s (valid CRC); its length. */
static uint8_t duty_frame(bn_frame_t *out, const struct bench_dbc_phase_samples_t *s)
{
    struct bench_dbc_pwm_duty_t d;
    double i_a = bench_dbc_phase_samples_i_a_decode(s->i_a);
    double da = (i_a + 64.0) / 128.0;
    bench_dbc_pwm_duty_init(&d);
    d.duty_a = bench_dbc_pwm_duty_duty_a_encode(da < 0.0 ? 0.0 : (da > 1.0 ? 1.0 : da));
    d.duty_b = bench_dbc_pwm_duty_duty_b_encode(0.5);
    d.duty_c = bench_dbc_pwm_duty_duty_c_encode(0.5);
    d.enable = 0u;
    d.step = s->step;
    memset(out, 0, sizeof *out);
    out->id = BENCH_DBC_PWM_DUTY_FRAME_ID;
    out->len = (uint8_t)bench_dbc_pwm_duty_pack(out->data, &d, sizeof out->data);
    bench_e2e_protect(BENCH_E2E_PWM_DUTY_DATA_ID, out->data, out->len,
                      BENCH_E2E_PWM_DUTY_CRC_INDEX);
    return out->len;
}

/* A decoded, checked PhaseSamples: 1, or 0 when the frame fails a check. */
static int sample_of(const bn_frame_t *f, struct bench_dbc_phase_samples_t *s)
{
    return f->len == BENCH_DBC_PHASE_SAMPLES_LENGTH &&
           bench_e2e_check(BENCH_E2E_PHASE_SAMPLES_DATA_ID, f->data, f->len,
                           BENCH_E2E_PHASE_SAMPLES_CRC_INDEX) &&
           bench_dbc_phase_samples_unpack(s, f->data, f->len) == 0 &&
           bench_dbc_phase_samples_u_dc_is_in_range(s->u_dc) &&
           bench_dbc_phase_samples_status_is_in_range(s->status);
}

static int run_echo(bn_bus_t *bus, long limit, double idle_s)
{
    unsigned long answered = 0, rejected = 0, ignored = 0, send_errors = 0;
    int64_t idle_ns = (int64_t)(idle_s * 1e9);
    int64_t last = bn_now_ns();
    bn_frame_t in, out;
    struct bench_dbc_phase_samples_t s;
    while (!stop && (limit <= 0 || (long)answered < limit)) {
        int r = bn_recv_until(bus, &in, last + idle_ns);
        if (r < 0) {
            fprintf(stderr, "echo: receive: %s\n", strerror(-r));
            return 1;
        }
        if (r == 0) {
            if (bn_now_ns() - last >= idle_ns) {
                break;
            }
            continue;
        }
        if (in.id != BENCH_DBC_PHASE_SAMPLES_FRAME_ID || (in.flags & (BN_EXT | BN_RTR | BN_ERR))) {
            ignored++;
            continue;
        }
        last = bn_now_ns();
        if (!sample_of(&in, &s)) {
            rejected++;
            continue;
        }
        duty_frame(&out, &s);
        if (bn_send(bus, &out) == 0) {
            answered++;
        } else {
            send_errors++;
        }
    }
    printf("echo: answered=%lu rejected=%lu ignored=%lu malformed=%llu send_errors=%lu\n",
           answered, rejected, ignored, (unsigned long long)bus->rx_malformed, send_errors);
    return 0;
}

static int run_ping(bn_bus_t *bus, long n, double wait_ms)
{
    long answered = 0, kept = 0, send_errors = 0;
    int last_err = 0;
    int64_t wait_ns = (int64_t)(wait_ms * 1e6);
    bn_frame_t in, out;
    struct bench_dbc_phase_samples_t s;
    for (long k = 0; k < n && !stop; k++) {
        bench_dbc_phase_samples_init(&s);
        s.i_a = bench_dbc_phase_samples_i_a_encode((double)(k % 100) * 0.5);
        s.u_dc = bench_dbc_phase_samples_u_dc_encode(300.0);
        s.status = BENCH_DBC_PHASE_SAMPLES_STATUS_RUNNING_CHOICE;
        s.step = (uint16_t)((unsigned long)k & STEP_MASK);
        memset(&out, 0, sizeof out);
        out.id = BENCH_DBC_PHASE_SAMPLES_FRAME_ID;
        out.len = (uint8_t)bench_dbc_phase_samples_pack(out.data, &s, sizeof out.data);
        bench_e2e_protect(BENCH_E2E_PHASE_SAMPLES_DATA_ID, out.data, out.len,
                          BENCH_E2E_PHASE_SAMPLES_CRC_INDEX);
        int64_t t0 = bn_now_ns();
        int err = bn_send(bus, &out);
        if (err != 0) {
            send_errors++;
            last_err = -err;
            continue;
        }
        int64_t deadline = t0 + wait_ns;
        for (;;) {
            int r = bn_recv_until(bus, &in, deadline);
            if (r <= 0) {
                break;
            }
            struct bench_dbc_pwm_duty_t d;
            if (in.id == BENCH_DBC_PWM_DUTY_FRAME_ID && in.len == BENCH_DBC_PWM_DUTY_LENGTH &&
                bench_e2e_check(BENCH_E2E_PWM_DUTY_DATA_ID, in.data, in.len,
                                BENCH_E2E_PWM_DUTY_CRC_INDEX) &&
                bench_dbc_pwm_duty_unpack(&d, in.data, in.len) == 0 && d.step == s.step) {
                int64_t rtt = bn_now_ns() - t0;
                answered++;
                if (kept < PING_MAX) {
                    rtt_ns[kept++] = (uint32_t)(rtt > (int64_t)UINT32_MAX ? UINT32_MAX : rtt);
                }
                break;
            }
        }
    }
    double med = 0.0, p99 = 0.0, max = 0.0;
    if (kept > 0) {
        qsort(rtt_ns, (size_t)kept, sizeof rtt_ns[0], cmp_u32);
        med = rtt_ns[kept / 2] * 1e-3;
        p99 = rtt_ns[(kept * 99) / 100] * 1e-3;
        max = rtt_ns[kept - 1] * 1e-3;
    }
    printf("ping: sent=%ld answered=%ld send_errors=%ld rtt_us median=%.1f p99=%.1f max=%.1f\n",
           n - send_errors, answered, send_errors, med, p99, max);
    if (send_errors) {
        fprintf(stderr, "ping: last send error: %s\n", strerror(last_err));
    }
    return answered == n ? 0 : 1;
}

int main(int argc, char **argv)
{
    const char *group = DEFAULT_GROUP, *iface = NULL;
    long port = 43113, limit = 0, ping = 0;
    double idle_s = 10.0, wait_ms = 100.0;
    int opt;
    while ((opt = getopt(argc, argv, "u:p:s:n:t:P:w:")) != -1) {
        switch (opt) {
        case 'u': group = optarg; break;
        case 'p': port = strtol(optarg, NULL, 10); break;
        case 's': iface = optarg; break;
        case 'n': limit = strtol(optarg, NULL, 10); break;
        case 't': idle_s = strtod(optarg, NULL); break;
        case 'P': ping = strtol(optarg, NULL, 10); break;
        case 'w': wait_ms = strtod(optarg, NULL); break;
        default:
            fprintf(stderr, "usage: echo [-u GROUP] [-p PORT] [-s IFACE] [-n N] [-t IDLE_S] "
                            "[-P N] [-w WAIT_MS]\n");
            return 2;
        }
    }
    if (port <= 0 || port > 65535) {
        fprintf(stderr, "echo: -p %ld: not a UDP port\n", port);
        return 2;
    }
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal; /* no SA_RESTART: a signal ends the wait */
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    static bn_bus_t bus;
    int r = iface ? bn_can_open(&bus, iface, true)
                  : bn_udp_open(&bus, group, (uint16_t)port, 4 << 20);
    if (r != 0) {
        fprintf(stderr, "echo: %s %s: %s\n", iface ? "socketcan" : "udp_multicast",
                iface ? iface : group, strerror(-r));
        return 2;
    }
    printf("READY\n");
    fflush(stdout);
    r = ping > 0 ? run_ping(&bus, ping, wait_ms) : run_echo(&bus, limit, idle_s);
    fflush(stdout);
    bn_close(&bus);
    return r;
}
