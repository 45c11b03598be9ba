/*
 * Reference external drive controller for the CAN hardware-in-the-loop bench.
 *
 * Two builds (firmware/Makefile):
 *
 *   sensorless (make SCENARIO=FILE ESTIMATOR=NAME): the bench's own controller.  The
 *     core (controller/core/) runs any estimator it has, initialised by
 *     bench_controller_init() of the header `bench codegen --scenario FILE --estimator
 *     NAME` writes (the Python design's values, exact); every period is cc_foc_step()
 *     (start-up, polarity test and speed loop included) and, when the scenario has
 *     it, cc_sup_after().  Only PhaseSamples and BenchCommand are read (never
 *     PositionSensor or PlantTruth); PwmDuty and CtrlTelemetry carry the core's
 *     output, encoded as the bench's codec encodes them, so a lockstep run gives
 *     the bench's in-process trace.  The options -e, -n and -d are not used.
 *
 *   sensored (make): the FOC speed controller below, on the encoder.
 *
 * The sensored build is an FOC speed controller that talks to `bench plant` over SocketCAN
 * using nothing but the DBC (dbc/bench.dbc): the frames are packed and
 * unpacked by the C code `bench codegen` generates (bench_dbc.h/.c, cantools)
 * and protected by the generated E2E helper (bench_e2e.h/.c).  It is meant as
 * the starting point of a real controller's firmware: the control law is in
 * foc.c (no I/O), this file only maps frames to foc_step() and back.  No
 * dynamic allocation.
 *
 * Frames (DBC names; one of each per PWM period k unless noted):
 *   in   PhaseSamples  0x011  i_a, i_b, u_dc sampled at k T_s; step = k mod 1024
 *   in   PositionSensor 0x012 the rotor's mechanical angle as the encoder reads
 *                             it (DBC 2.2): every -e periods, with PhaseSamples;
 *                             the input of this sensored controller.  PlantTruth
 *                             (0x100) is the recorder's and is never read here.
 *   in   BenchCommand  0x020  start/stop/enable/disable, speed_ref; step = the
 *                             period the command applies in (mod 65536), sent ahead
 *   out  PwmDuty       0x010  duties for period k + 1; step = (k + 1) mod 1024, E2E CRC
 *   out  CtrlTelemetry 0x101  CAN FD: theta_hat = the angle used (the encoder's),
 *                             w_hat (electrical, the estimate below), mode;
 *                             step = k; run_id 0 (the run's nonce is in
 *                             PlantTruth, not read), E2E CRC;
 *                             cmd_ack (DBC 2.2): seq of the newest command held
 *                             with no gap, sent again when it moves
 *
 * Period k is computed when PhaseSamples(k) is in and, in a period the sensor
 * reads (k a multiple of -e), PositionSensor(k) too.  The angle at k is the
 * newest reading plus half a count (the encoder floors to a count of -n per
 * revolution) advanced by the estimated speed over the reading's age (its
 * delay -d and the periods since it).  The speed comes from the angle: the
 * difference of two readings over their spacing T_r through a first-order
 * filter of bandwidth SPEED_FILTER_BW (below, with its derivation).
 * A repeated PhaseSamples(k) (the lockstep plant re-sends when a duty is
 * late) gets the same PwmDuty again.  Frames with a bad length, a bad E2E
 * CRC or an out-of-range value are counted and dropped.
 *
 * Sample timeout (both builds; real time only, -r, as the bench's own controller
 * node's rule, bench/nodes/_loops.py controller_loop: in lockstep the plant paces
 * the samples and waits for each duty, so a pause of the plant is no loss, and its
 * own watchdog rounds judge a lost duty): once a valid PhaseSamples came, when
 * none comes for SAMPLE_TIMEOUT whole PWM periods (ceil of -s over the period,
 * counted on the monotonic clock) the drive gates its PWM off: the law is
 * disabled, so every PwmDuty it sends from then on has enable 0 (all legs off),
 * and it says so on stderr once.  It resumes only when a start, enable or reset
 * command is applied (the law then starts again as after any enable; a speed
 * reference alone does not).  When the stop command is due with the sample that
 * did not come (the plant's last one), the program ends as on the stop instead.
 * The timeouts are counted in the summary; one or more make the exit status 1.
 *
 * Usage: ref_controller [-i IFACE] [-e SENSOR_EVERY] [-n COUNTS] [-d DELAY_US] [-t IDLE_S]
 *                       [-r] [-s SAMPLE_TIMEOUT_MS]
 *   -i  SocketCAN interface (default vcan0); CAN FD must be enabled on it
 *   -e  PWM periods between two PositionSensor readings (default 1)
 *   -n  the encoder's counts per mechanical revolution (default 65536)
 *   -d  the age of a reading [us] (default 0)
 *   (bench show SCENARIO --json: position_sensor every, counts, delay_s; the
 *   defaults are the sensor the plant gives a controller under test when the
 *   scenario states none)
 *   -t  exit after this many seconds without a frame (default 30)
 *   -r  real time (the run's `bench run --mode realtime`): the sample timeout is armed
 *   -s  the sample timeout [ms] (default FW_SAMPLE_TIMEOUT_S, the bench controller
 *       node's SAMPLE_TIMEOUT_S, which firmware/Makefile passes; as `bench controller
 *       --sample-timeout-ms`)
 * Prints READY when listening; exits 0 after the stop command, with a summary (1 after a
 * sample timeout, a send error or a failed step of the core).
 */
#include <errno.h>
#include <math.h>
#include <net/if.h>
#include <poll.h>
#include <signal.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <linux/can.h>
#include <linux/can/raw.h>

#include "bench_dbc.h"
#include "bench_e2e.h"
#include "foc.h"
#include "motor_params.h"
#ifdef FW_BENCH_CONTROLLER
#include "bench_controller.h"
#if BENCH_CTL_NEEDS_TRUTH
#error "this estimator reads the plant's true angle (PlantTruth), which a drive has not: build without ESTIMATOR for the encoder's sensored controller"
#endif
#endif

#define TWO_PI 6.28318530717958647692

/* The PWM period [s]: the bench's design's (sensorless) or the encoder build's. */
#ifdef FW_BENCH_CONTROLLER
#define FW_T_S BENCH_CTL_T_S
#else
#define FW_T_S (1.0 / PWM_FREQ_HZ)
#endif

/* The default sample timeout [s]: bench.nodes._loops.SAMPLE_TIMEOUT_S, the bench's own
 * controller node's (firmware/Makefile passes it: one home). */
#ifndef FW_SAMPLE_TIMEOUT_S
#error "FW_SAMPLE_TIMEOUT_S: build with firmware/Makefile (the bench controller node's SAMPLE_TIMEOUT_S)"
#endif

/* Widths of the step counters (DBC: PhaseSamples.step, PositionSensor.step and
 * PwmDuty.step are 10 bits, BenchCommand.step 16 bits, CtrlTelemetry.step 32
 * bits).  Receivers unwrap them against the step they expect. */
#define SAMPLE_STEP_BITS 10
#define COMMAND_STEP_BITS 16

/* Readings that arrived before their sample is computed wait here, by step
 * (two samples are in flight at a lockstep start; a few more on a resend). */
#define READING_RING 16

/* Bandwidth of the speed estimate's filter [rad/s]: 10 alpha_s.  Target: the
 * filter costs the speed loop at most 6 degrees of phase at its crossover
 * alpha_s: atan(1/10) = 5.7 degrees, plus alpha_s T_r / 2 for the half-reading
 * delay of a difference (0.09 degrees at 10 kHz).  Price: the encoder's
 * quantisation.  A reading's error e, uniform over one count q = 2 pi / COUNTS,
 * reaches the estimate through (a / T_r) (1 - z^-1) / (1 - (1 - a) z^-1),
 * a = 1 - exp(-SPEED_FILTER_BW T_r), whose squared impulse response sums to
 * 2 / (2 - a): rms (q / sqrt 12) (a / T_r) sqrt(2 / (2 - a)), at most
 * q a / T_r (about q SPEED_FILTER_BW).  65536 counts at 10 kHz with the
 * default alpha_s (2 pi 5 Hz): 0.009 rad/s rms, at most 0.03 rad/s (0.3 rpm);
 * a 4096-count encoder gives sixteen times that. */
#ifndef SPEED_FILTER_BW
#define SPEED_FILTER_BW (10.0 * ALPHA_S)
#endif

/* BenchCommand.cmd values (DBC VAL_ table). */
enum { CMD_NONE = 0, CMD_START = 1, CMD_STOP = 2, CMD_RESET = 3, CMD_ENABLE = 4, CMD_DISABLE = 5 };

/* CtrlTelemetry.mode values (DBC VAL_ table). */
enum { MODE_DISABLED = 0, MODE_RUN = 3 };

/* BenchCommand.seq counts commands modulo this (DBC 2.2); the bench keeps fewer
 * than half of it beyond the acknowledged one. */
#define SEQ_MOD 16

/* Commands received ahead of their apply step wait here (fixed size). */
#define CMD_QUEUE_LEN 128

/* The control law: the core as the bench builds it (sensorless), or foc.c on the
 * encoder (sensored). */
#ifdef FW_BENCH_CONTROLLER
typedef struct {
    cc_foc_t core;
    cc_sup_t sup;
} law_t;
#else
typedef foc_t law_t;
#endif

/* One period's answer: duties for the next period and the telemetry's values. */
typedef struct {
    double d_a, d_b, d_c;
    bool enable;
    double theta_hat, w_hat, err; /* electrical angle and speed used, error signal */
    long long mode;
} law_out_t;

static void law_enable(law_t *law, bool on)
{
#ifdef FW_BENCH_CONTROLLER
    cc_foc_set_enable(&law->core, on ? 1 : 0);
#else
    foc_enable(law, on);
#endif
}

/* BenchCommand.speed_ref [rpm] as the reference [rad/s] (sensorless: as the bench's
 * controller node converts it) */
static void law_speed_ref(law_t *law, double rpm)
{
#ifdef FW_BENCH_CONTROLLER
    cc_foc_set_speed_ref(&law->core, rpm / BENCH_CTL_RPM_PER_RAD_S);
#else
    foc_set_speed_ref(law, rpm * (TWO_PI / 60.0));
#endif
}

typedef struct {
    int64_t apply_step;
    uint8_t cmd;
    double speed_ref_rpm;
} command_t;

/* The position sensor as the controller knows it (command line). */
typedef struct {
    int every;       /* PWM periods between readings */
    double counts;   /* counts per mechanical revolution */
    double delay_s;  /* age of a reading [s] */
    double a;        /* speed filter coefficient 1 - exp(-SPEED_FILTER_BW T_r) */
} sensor_t;

typedef struct {
    /* sample waiting to be used */
    bool have_sample;
    int64_t sample_k;
    double i_a, i_b, u_dc;
    /* PositionSensor readings by step mod READING_RING (-1: none) */
    int64_t reading_k[READING_RING];
    double reading_theta[READING_RING];
    /* the newest reading used, and the speed estimated from the readings */
    bool have_angle;
    int64_t angle_k;
    double theta_m;
    double w_m_hat;
    /* the next period to compute, and the last answer (for repeats) */
    int64_t next_k;
    struct canfd_frame last_duty;
    bool have_last_duty;
    /* bench commands */
    command_t queue[CMD_QUEUE_LEN];
    int n_queued;
    int last_seq;
    int64_t last_cmd_step;
    /* acknowledgement (DBC 2.2): newest seq held with no gap (-1: none), its
     * step, and the steps of the commands held beyond a gap, by seq (-1: none) */
    int ack_seq;
    int64_t ack_step;
    int64_t beyond[SEQ_MOD];
    struct bench_dbc_ctrl_telemetry_t last_tel;
    bool have_last_tel;
    bool stop;
    int step_error; /* cc_foc_step's error (sensorless), 0: none */
    /* sample timeout: PWM periods without a valid sample that gate the PWM off (0: not
     * armed, lockstep), and whether it is off for that reason (until a start, enable or
     * reset command) */
    int64_t timeout_periods;
    bool faulted;
    /* counters */
    long steps, rejected, repeats, cmd_dropped, send_errors, samples_accepted, sample_timeouts;
} node_t;

static volatile sig_atomic_t interrupted;

static void on_signal(int sig)
{
    (void)sig;
    interrupted = 1;
}

/* The step nearest `expected` whose low `bits` bits are `raw`. */
static int64_t unwrap(uint32_t raw, int64_t expected, unsigned bits)
{
    int64_t mod = (int64_t)1 << bits;
    int64_t half = mod / 2;
    int64_t d = ((int64_t)raw - expected + half) % mod;
    if (d < 0) {
        d += mod;
    }
    return expected + d - half;
}

/* A frame of `len` bytes with identifier `id` (CAN FD when it is longer than 8). */
static void make_frame(struct canfd_frame *fr, uint32_t id, const uint8_t *data, size_t len)
{
    memset(fr, 0, sizeof *fr);
    fr->can_id = id;
    fr->len = (uint8_t)len;
    if (len > CAN_MAX_DLEN) {
        fr->flags = CANFD_BRS; /* DBC: CANFD_BRS = 1 */
    }
    memcpy(fr->data, data, len);
}

static void send_frame(int sock, const struct canfd_frame *fr, node_t *n)
{
    size_t size = fr->len > CAN_MAX_DLEN ? CANFD_MTU : CAN_MTU;
    for (int attempt = 0; attempt < 50; attempt++) {
        if (write(sock, fr, size) == (ssize_t)size) {
            return;
        }
        if (errno != ENOBUFS && errno != EAGAIN && errno != EINTR) {
            break;
        }
        struct timespec ts = {0, 200000}; /* transmit queue full: wait 0.2 ms */
        nanosleep(&ts, NULL);
    }
    n->send_errors++;
}

#ifndef FW_BENCH_CONTROLLER /* sensorless: bench_wire_raw() (bench_wire.h) */
/* Duty to its raw value, clipped to the DBC range [0 | 1] (raw 0..16384; a raw
 * value above 16384 is out of range and the plant rejects the frame). */
static uint16_t duty_raw(double d)
{
    return bench_dbc_pwm_duty_duty_a_encode(d < 0.0 ? 0.0 : (d > 1.0 ? 1.0 : d));
}

/* Angle [rad] to the raw value of a 16-bit SigModular angle, modulo 2 pi. */
static uint16_t angle_raw(double theta)
{
    double lsb = bench_dbc_ctrl_telemetry_theta_hat_decode(1u);
    double r = fmod(floor(theta / lsb + 0.5), 65536.0);
    if (r < 0.0) {
        r += 65536.0;
    }
    return (uint16_t)r;
}
#endif

static void send_telemetry(int sock, node_t *n);

static void send_outputs(int sock, node_t *n, int64_t k, const law_out_t *o)
{
    uint8_t buf[64];
    struct canfd_frame fr;
    struct bench_dbc_pwm_duty_t duty;
    bench_dbc_pwm_duty_init(&duty);
#ifdef FW_BENCH_CONTROLLER
    /* the bench's codec's encoding: bench_wire_raw() (bench_wire.h, as the bench's node) */
    static const bench_wire_sig_t s_da = BENCH_WIRE_PWM_DUTY_DUTY_A,
                                  s_db = BENCH_WIRE_PWM_DUTY_DUTY_B,
                                  s_dc = BENCH_WIRE_PWM_DUTY_DUTY_C;
    duty.duty_a = (uint16_t)bench_wire_raw(&s_da, o->d_a);
    duty.duty_b = (uint16_t)bench_wire_raw(&s_db, o->d_b);
    duty.duty_c = (uint16_t)bench_wire_raw(&s_dc, o->d_c);
#else
    duty.duty_a = duty_raw(o->d_a);
    duty.duty_b = duty_raw(o->d_b);
    duty.duty_c = duty_raw(o->d_c);
#endif
    duty.enable = o->enable ? 1u : 0u;
    duty.step = (uint16_t)((uint64_t)(k + 1) & ((1u << SAMPLE_STEP_BITS) - 1u));
    int len = bench_dbc_pwm_duty_pack(buf, &duty, sizeof buf);
    bench_e2e_protect(BENCH_E2E_PWM_DUTY_DATA_ID, buf, (size_t)len, BENCH_E2E_PWM_DUTY_CRC_INDEX);
    make_frame(&fr, BENCH_DBC_PWM_DUTY_FRAME_ID, buf, (size_t)len);
    send_frame(sock, &fr, n);
    n->last_duty = fr;
    n->have_last_duty = true;

    struct bench_dbc_ctrl_telemetry_t tel;
    bench_dbc_ctrl_telemetry_init(&tel);
#ifdef FW_BENCH_CONTROLLER
    static const bench_wire_sig_t s_th = BENCH_WIRE_CTRL_TELEMETRY_THETA_HAT,
                                  s_w = BENCH_WIRE_CTRL_TELEMETRY_W_HAT,
                                  s_err = BENCH_WIRE_CTRL_TELEMETRY_ERR,
                                  s_mode = BENCH_WIRE_CTRL_TELEMETRY_MODE;
    tel.theta_hat = (uint16_t)bench_wire_raw(&s_th, o->theta_hat);
    tel.w_hat = (int32_t)bench_wire_raw(&s_w, o->w_hat);
    tel.err = (int16_t)bench_wire_raw(&s_err, o->err);
    tel.mode = (uint8_t)bench_wire_raw(&s_mode, (double)o->mode);
#else
    tel.theta_hat = angle_raw(o->theta_hat);
    tel.w_hat = bench_dbc_ctrl_telemetry_w_hat_encode(o->w_hat);
    tel.err = 0;
    tel.mode = (uint8_t)o->mode;
#endif
    tel.step = (uint32_t)k;
    tel.run_id = 0; /* unknown: the nonce is in PlantTruth, which this controller does not read */
    n->last_tel = tel;
    n->have_last_tel = true;
    send_telemetry(sock, n);
}

/* The newest CtrlTelemetry with the acknowledgement held now (DBC 2.2). */
static void send_telemetry(int sock, node_t *n)
{
    uint8_t buf[64];
    struct canfd_frame fr;
    struct bench_dbc_ctrl_telemetry_t tel = n->last_tel;
    tel.cmd_ack_valid = n->ack_seq >= 0 ? 1u : 0u;
    tel.cmd_ack = (uint8_t)(n->ack_seq >= 0 ? n->ack_seq : 0);
    int len = bench_dbc_ctrl_telemetry_pack(buf, &tel, sizeof buf);
    bench_e2e_protect(BENCH_E2E_CTRL_TELEMETRY_DATA_ID, buf, (size_t)len,
                      BENCH_E2E_CTRL_TELEMETRY_CRC_INDEX);
    make_frame(&fr, BENCH_DBC_CTRL_TELEMETRY_FRAME_ID, buf, (size_t)len);
    send_frame(sock, &fr, n);
}

/* Apply the commands due at period k, in apply-step order. */
static void apply_commands(node_t *n, law_t *law, int64_t k)
{
    for (;;) {
        int best = -1;
        for (int i = 0; i < n->n_queued; i++) {
            if (n->queue[i].apply_step <= k &&
                (best < 0 || n->queue[i].apply_step < n->queue[best].apply_step)) {
                best = i;
            }
        }
        if (best < 0) {
            return;
        }
        command_t c = n->queue[best];
        n->queue[best] = n->queue[--n->n_queued];
        if (c.cmd == CMD_START || c.cmd == CMD_ENABLE || c.cmd == CMD_RESET) {
            n->faulted = false; /* the sample timeout's resume rule */
            law_enable(law, true);
        } else if (c.cmd == CMD_STOP || c.cmd == CMD_DISABLE) {
            law_enable(law, false);
            if (c.cmd == CMD_STOP) {
                n->stop = true;
            }
        }
        law_speed_ref(law, c.speed_ref_rpm);
    }
}

/* Compute period sample_k when its sample (and its reading, if the sensor reads
 * in that period) are in. */
static void try_compute(int sock, node_t *n, law_t *law, const sensor_t *sen)
{
    if (!n->have_sample || n->ack_seq < 0) {
        /* no sample is answered before the start is held (docs/PROTOCOL.md): the plant
         * sends it again and the bench its commands, so the first answer has the start */
        return;
    }
    int64_t k = n->sample_k;
#ifdef FW_BENCH_CONTROLLER
    (void)sen;
    apply_commands(n, law, k);
    /* the bench controller node's measurement (bench/nodes/_controller_node.py) */
    cc_meas_t m = {k, n->i_a, n->i_b, -n->i_a - n->i_b, n->u_dc, 0, 0.0, 0.0};
    cc_out_t o;
    int rc = cc_foc_step(&law->core, &m, &o);
    if (rc != CC_OK) {
        fprintf(stderr, "ref_controller: period %lld: the core's step failed (%d%s)\n",
                (long long)k, rc, rc == CC_ERR_U_DC ? ": u_dc = 0" : "");
        n->step_error = rc;
        n->stop = true;
        return;
    }
#if BENCH_CTL_SUPERVISION
    cc_sup_after(&law->sup, &law->core, &m, &o);
#endif
    law_out_t out = {o.d_a, o.d_b, o.d_c, o.enable != 0, o.theta_hat, o.w_hat, o.err, o.mode};
#else
    if (k % sen->every == 0) {
        int slot = (int)(k % READING_RING);
        if (n->reading_k[slot] != k) {
            return; /* wait for the reading of this period */
        }
        double th = n->reading_theta[slot];
        n->reading_k[slot] = -1;
        if (n->have_angle) {
            /* the angle's difference over the readings' spacing, filtered */
            double d = remainder(th - n->theta_m, TWO_PI);
            double T_r = (double)(k - n->angle_k) / PWM_FREQ_HZ;
            n->w_m_hat += sen->a * (d / T_r - n->w_m_hat);
        }
        n->have_angle = true;
        n->angle_k = k;
        n->theta_m = th;
    }
    apply_commands(n, law, k);
    /* the angle at the sample instant: the count's middle, advanced by the
     * estimated speed over the reading's age */
    double age_s = sen->delay_s + (double)(k - n->angle_k) / PWM_FREQ_HZ;
    double th_m = n->have_angle ? n->theta_m + M_PI / sen->counts + n->w_m_hat * age_s : 0.0;
    double w_e = MOTOR_N_P * n->w_m_hat;
    double theta = fmod(MOTOR_N_P * th_m, TWO_PI);
    if (theta < 0.0) {
        theta += TWO_PI;
    }
    foc_input_t in = {n->i_a, n->i_b, n->u_dc, theta, n->w_m_hat};
    foc_output_t fo;
    foc_step(law, &in, &fo);
    law_out_t out = {fo.d_a,  fo.d_b, fo.d_c, fo.enable, theta, w_e, 0.0,
                     law->enabled ? MODE_RUN : MODE_DISABLED};
#endif
    send_outputs(sock, n, k, &out);
    n->have_sample = false;
    n->next_k = k + 1;
    n->steps++;
}

static void on_frame(int sock, node_t *n, law_t *law, const struct canfd_frame *fr,
                     const sensor_t *sen)
{
    if (fr->can_id & (CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_ERR_FLAG)) {
        return;
    }
    switch (fr->can_id & CAN_SFF_MASK) {
    case BENCH_DBC_PHASE_SAMPLES_FRAME_ID: {
        struct bench_dbc_phase_samples_t s;
        if (fr->len != BENCH_DBC_PHASE_SAMPLES_LENGTH ||
            !bench_e2e_check(BENCH_E2E_PHASE_SAMPLES_DATA_ID, fr->data, fr->len,
                             BENCH_E2E_PHASE_SAMPLES_CRC_INDEX) ||
            bench_dbc_phase_samples_unpack(&s, fr->data, fr->len) != 0 ||
            !bench_dbc_phase_samples_status_is_in_range(s.status)) {
            n->rejected++;
            return;
        }
        int64_t k = unwrap(s.step, n->next_k, SAMPLE_STEP_BITS);
        if (k < n->next_k) {
            /* a repeat of a sample already answered: answer the newest again */
            n->repeats++;
            if (k == n->next_k - 1 && n->have_last_duty) {
                send_frame(sock, &n->last_duty, n);
                if (n->have_last_tel) {
                    send_telemetry(sock, n); /* with the acknowledgement held now */
                }
            }
            return;
        }
        n->have_sample = true;
        n->samples_accepted++;
        n->sample_k = k;
        n->i_a = bench_dbc_phase_samples_i_a_decode(s.i_a);
        n->i_b = bench_dbc_phase_samples_i_b_decode(s.i_b);
        n->u_dc = bench_dbc_phase_samples_u_dc_decode(s.u_dc);
        break;
    }
#ifndef FW_BENCH_CONTROLLER /* sensorless: no encoder */
    case BENCH_DBC_POSITION_SENSOR_FRAME_ID: {
        struct bench_dbc_position_sensor_t p;
        if (fr->len != BENCH_DBC_POSITION_SENSOR_LENGTH ||
            !bench_e2e_check(BENCH_E2E_POSITION_SENSOR_DATA_ID, fr->data, fr->len,
                             BENCH_E2E_POSITION_SENSOR_CRC_INDEX) ||
            bench_dbc_position_sensor_unpack(&p, fr->data, fr->len) != 0) {
            n->rejected++;
            return;
        }
        int64_t k = unwrap(p.step, n->next_k, SAMPLE_STEP_BITS);
        if (k < n->next_k || k >= n->next_k + READING_RING) {
            return; /* a resend of a reading used, or too far ahead */
        }
        n->reading_k[k % READING_RING] = k;
        n->reading_theta[k % READING_RING] = bench_dbc_position_sensor_theta_m_decode(p.theta_m);
        break;
    }
#endif
    case BENCH_DBC_BENCH_COMMAND_FRAME_ID: {
        struct bench_dbc_bench_command_t c;
        if (fr->len != BENCH_DBC_BENCH_COMMAND_LENGTH ||
            !bench_e2e_check(BENCH_E2E_BENCH_COMMAND_DATA_ID, fr->data, fr->len,
                             BENCH_E2E_BENCH_COMMAND_CRC_INDEX) ||
            bench_dbc_bench_command_unpack(&c, fr->data, fr->len) != 0 ||
            !bench_dbc_bench_command_cmd_is_in_range(c.cmd)) {
            n->rejected++;
            return;
        }
        int64_t step = unwrap(c.step, n->next_k, COMMAND_STEP_BITS);
        if ((c.seq == n->last_seq && step == n->last_cmd_step) || step <= n->ack_step) {
            /* the same transmission again (DBC: same seq = repeat), or a copy of a
             * command held (at or before the newest gap-free one) */
            return;
        }
        n->last_seq = c.seq;
        n->last_cmd_step = step;
        if ((c.seq - n->ack_seq - 1 + 2 * SEQ_MOD) % SEQ_MOD < SEQ_MOD / 2) {
            n->beyond[c.seq] = step;
            bool moved = false;
            int nxt = (n->ack_seq + 1) % SEQ_MOD;
            while (n->beyond[nxt] >= 0) {
                n->ack_step = n->beyond[nxt];
                n->beyond[nxt] = -1;
                n->ack_seq = nxt;
                nxt = (nxt + 1) % SEQ_MOD;
                moved = true;
            }
            if (moved && n->have_last_tel) {
                send_telemetry(sock, n); /* the acknowledgement moved: say so now */
            }
        }
        bool queued = false;
        for (int i = 0; i < n->n_queued; i++) {
            queued = queued || n->queue[i].apply_step == step; /* one command per step */
        }
        if (!queued && n->n_queued == CMD_QUEUE_LEN) {
            n->cmd_dropped++;
        } else if (!queued) {
            command_t *q = &n->queue[n->n_queued++];
            q->apply_step = step;
            q->cmd = c.cmd;
            q->speed_ref_rpm = bench_dbc_bench_command_speed_ref_decode(c.speed_ref);
        }
        if (step <= n->next_k) {
            /* due before the next period is computed: apply now (a stop for the
             * period after the plant's last one ends the program here) */
            apply_commands(n, law, n->next_k);
        }
        break; /* a sample held until the start came is computed now */
    }
    default:
        return;
    }
    try_compute(sock, n, law, sen);
}

/* The sample timeout (header comment): `periods` whole PWM periods passed since the newest
 * valid PhaseSamples (the caller counts them only once one came). */
static void sample_watch(node_t *n, law_t *law, int64_t periods)
{
    if (n->timeout_periods == 0 || periods < n->timeout_periods) {
        return;
    }
    for (int i = 0; i < n->n_queued; i++) {
        if (n->queue[i].cmd == CMD_STOP && n->queue[i].apply_step <= n->next_k) {
            n->stop = true; /* due with the sample that did not come: the run is over */
            return;
        }
    }
    if (!n->faulted) {
        n->faulted = true;
        n->sample_timeouts++;
        law_enable(law, false);
        fprintf(stderr,
                "ref_controller: no PhaseSamples for %lld periods after period %lld: PWM off "
                "until a start, enable or reset command\n",
                (long long)periods, (long long)(n->next_k - 1));
    }
}

/* The node before its first frame, with a sample timeout of `timeout_s` (0: not armed). */
static void node_init(node_t *n, double timeout_s)
{
    memset(n, 0, sizeof *n);
    n->last_seq = -1;
    n->last_cmd_step = -1;
    n->ack_seq = -1;
    n->ack_step = -1;
    for (int i = 0; i < SEQ_MOD; i++) {
        n->beyond[i] = -1;
    }
    for (int i = 0; i < READING_RING; i++) {
        n->reading_k[i] = -1;
    }
    /* whole periods, as the plant's watchdog counts them (bench/nodes/_loops.py) */
    n->timeout_periods = 0;
    if (timeout_s > 0.0) {
        n->timeout_periods = (int64_t)ceil(timeout_s / FW_T_S - 1e-9);
        n->timeout_periods = n->timeout_periods < 1 ? 1 : n->timeout_periods;
    }
}

static double monotonic_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* Raw CAN socket on `ifname` with CAN FD frames enabled and the three input IDs. */
static int open_can(const char *ifname)
{
    int sock = socket(PF_CAN, SOCK_RAW, CAN_RAW);
    if (sock < 0) {
        perror("ref_controller: socket(PF_CAN)");
        return -1;
    }
    int on = 1;
    if (setsockopt(sock, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof on) != 0) {
        perror("ref_controller: CAN_RAW_FD_FRAMES");
        close(sock);
        return -1;
    }
    struct can_filter filters[] = {
        {BENCH_DBC_PHASE_SAMPLES_FRAME_ID, CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG},
#ifndef FW_BENCH_CONTROLLER /* sensorless: no encoder */
        {BENCH_DBC_POSITION_SENSOR_FRAME_ID, CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG},
#endif
        {BENCH_DBC_BENCH_COMMAND_FRAME_ID, CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG},
    };
    if (setsockopt(sock, SOL_CAN_RAW, CAN_RAW_FILTER, filters, sizeof filters) != 0) {
        perror("ref_controller: CAN_RAW_FILTER");
        close(sock);
        return -1;
    }
    struct ifreq ifr;
    memset(&ifr, 0, sizeof ifr);
    strncpy(ifr.ifr_name, ifname, IFNAMSIZ - 1);
    if (ioctl(sock, SIOCGIFINDEX, &ifr) != 0) {
        fprintf(stderr, "ref_controller: interface %s: %s\n", ifname, strerror(errno));
        close(sock);
        return -1;
    }
    struct sockaddr_can addr;
    memset(&addr, 0, sizeof addr);
    addr.can_family = AF_CAN;
    addr.can_ifindex = ifr.ifr_ifindex;
    if (bind(sock, (struct sockaddr *)&addr, sizeof addr) != 0) {
        fprintf(stderr, "ref_controller: bind %s: %s\n", ifname, strerror(errno));
        close(sock);
        return -1;
    }
    return sock;
}

int main(int argc, char **argv)
{
    const char *ifname = "vcan0";
    sensor_t sen = {1, 65536.0, 0.0, 0.0};
    double idle_s = 30.0;
    double timeout_s = FW_SAMPLE_TIMEOUT_S;
    bool realtime = false;
    int opt;
    while ((opt = getopt(argc, argv, "i:e:n:d:t:rs:")) != -1) {
        switch (opt) {
        case 'i':
            ifname = optarg;
            break;
        case 'e':
            sen.every = atoi(optarg);
            break;
        case 'n':
            sen.counts = atof(optarg);
            break;
        case 'd':
            sen.delay_s = atof(optarg) * 1e-6;
            break;
        case 't':
            idle_s = atof(optarg);
            break;
        case 'r':
            realtime = true;
            break;
        case 's':
            timeout_s = atof(optarg) * 1e-3;
            break;
        default:
            fprintf(stderr,
                    "usage: %s [-i IFACE] [-e SENSOR_EVERY] [-n COUNTS] [-d DELAY_US] [-t IDLE_S] "
                    "[-r] [-s SAMPLE_TIMEOUT_MS]\n",
                    argv[0]);
            return 2;
        }
    }
    if (sen.every < 1 || !(sen.counts >= 1.0) || !(sen.delay_s >= 0.0) || !(idle_s > 0.0) ||
        !(timeout_s > 0.0)) {
        fprintf(stderr, "ref_controller: -e must be >= 1, -n >= 1, -d >= 0, -t > 0 and -s > 0\n");
        return 2;
    }
    sen.a = 1.0 - exp(-SPEED_FILTER_BW * (double)sen.every / PWM_FREQ_HZ);
    int sock = open_can(ifname);
    if (sock < 0) {
        return 1;
    }
    signal(SIGINT, on_signal);
    signal(SIGTERM, on_signal);

    static node_t node; /* static: off the stack */
    static law_t law;
    node_init(&node, realtime ? timeout_s : 0.0);
#ifdef FW_BENCH_CONTROLLER
    if (bench_controller_init(&law.core, &law.sup) != 0) {
        fprintf(stderr, "ref_controller: the core refused the design of %s\n",
                BENCH_CTL_ESTIMATOR);
        close(sock);
        return 1;
    }
#else
    foc_init(&law, 1.0 / PWM_FREQ_HZ, MOTOR_N_P, MOTOR_R_S, MOTOR_L_D, MOTOR_L_Q, MOTOR_PSI_F,
             MOTOR_J, MOTOR_I_MAX, MOTOR_TAU_MAX, ALPHA_C, ALPHA_S);
#endif

    printf("READY\n");
    fflush(stdout);
    int rc = 0;
    /* poll at a quarter of the sample timeout, as the bench's node does (and at least
     * every 0.1 s, for the idle limit -t) */
    double poll_s = timeout_s / 4.0 < 0.1 ? timeout_s / 4.0 : 0.1;
    int poll_ms = poll_s < 0.001 ? 1 : (int)(poll_s * 1e3);
    double t_frame = monotonic_s(), t_sample = t_frame;
    long seen = 0;
    struct pollfd pfd = {sock, POLLIN, 0};
    while (!node.stop && !interrupted) {
        int ready = poll(&pfd, 1, poll_ms);
        if (ready < 0 && errno != EINTR) {
            perror("ref_controller: poll");
            rc = 1;
            break;
        }
        double now = monotonic_s();
        if (node.samples_accepted != seen) {
            seen = node.samples_accepted;
            t_sample = now;
        } else if (seen > 0) {
            sample_watch(&node, &law, (int64_t)floor((now - t_sample) / FW_T_S));
        }
        if (ready <= 0) {
            if (now - t_frame >= idle_s) {
                fprintf(stderr, "ref_controller: no frame for %.0f s, exiting\n", idle_s);
                rc = 1;
                break;
            }
            continue;
        }
        t_frame = now;
        struct canfd_frame fr;
        ssize_t nbytes = read(sock, &fr, sizeof fr);
        if (nbytes != CAN_MTU && nbytes != CANFD_MTU) {
            if (nbytes < 0 && errno == EINTR) {
                continue;
            }
            node.rejected++;
            continue;
        }
        on_frame(sock, &node, &law, &fr, &sen);
    }
    close(sock);
#ifdef FW_BENCH_CONTROLLER
    printf("ref_controller: %s, sensorless\n", BENCH_CTL_ESTIMATOR);
#endif
    printf("ref_controller: %ld steps, %ld rejected, %ld repeats, %ld commands dropped, "
           "%ld send errors, %ld sample timeouts\n",
           node.steps, node.rejected, node.repeats, node.cmd_dropped, node.send_errors,
           node.sample_timeouts);
    return rc != 0 ? rc : (node.send_errors || node.step_error || node.sample_timeouts ? 1 : 0);
}
