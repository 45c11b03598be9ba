/* The controller node's per-period logic (bn_ctl.h): ControllerNode.on_message
 * and controller_loop of bench/nodes/_controller_node.py and _loops.py, in C. */
#include "bn_ctl.h"

#include <errno.h>
#include <math.h>
#include <stddef.h>
#include <string.h>

#include "bench_dbc.h"
#include "bench_e2e.h"
#include "bench_wire.h"

size_t bn_ctl_bus_size(void) { return sizeof(bn_bus_t); }
size_t bn_ctl_size(void) { return sizeof(bn_ctl_t); }
size_t bn_ctl_prefix_size(void) { return offsetof(bn_ctl_t, t_last); }

void bn_ctl_reset(bn_ctl_t *ctl)
{
    for (int j = 0; j < BN_CTL_RING; j++)
        ctl->s_k[j] = ctl->t_k[j] = -1;
    for (int j = 0; j < BN_CTL_ANSWERS; j++)
        ctl->a_k[j] = -1;
    memset(&ctl->c, 0, sizeof ctl->c);
    ctl->next_k = 0;
    ctl->error = 0;
    ctl->has_last = 0;
    ctl->send_ack = 0;
    ctl->stopped = 0;
    ctl->faulted = 0;
    ctl->n_cmds = ctl->cmds_more = 0;
    ctl->applied_seq = -1;
    ctl->applied_upto = -1;
    ctl->has_w_ref = 0;
    ctl->w_m_ref = 0.0;
    ctl->t_last = ctl->t_sample = 0;
    ctl->seen = 0;
    memset(&ctl->held, 0, sizeof ctl->held);
    ctl->slack = 0;
}

/* bench/wire/_protocol.py unwrap: the step nearest expected whose value mod m is raw */
static int64_t unwrap(int64_t raw, int64_t expected, int64_t m)
{
    int64_t half = m / 2;
    int64_t d = ((raw - expected + half) % m + m) % m - half;
    return expected + d;
}

static size_t slot(int64_t k) { return (size_t)(((k % BN_CTL_RING) + BN_CTL_RING) % BN_CTL_RING); }

/* a signal's raw value as Codec.encode gives it: bench_wire_raw() (bench_wire.h, which
 * `bench codegen` writes for the firmware too) */
static int64_t raw_of(const bn_sig_t *s, double v)
{
    const bench_wire_sig_t w = {s->lo, s->hi, s->scale, s->offset, s->modulus};
    return bench_wire_raw(&w, v);
}

static int64_t raw(const bn_ctl_t *ctl, int j, double v) { return raw_of(&ctl->sig[j], v); }

static void duty_frame(const bn_ctl_t *ctl, const cc_out_t *o, bn_frame_t *f)
{
    struct bench_dbc_pwm_duty_t d;
    bench_dbc_pwm_duty_init(&d);
    d.duty_a = (uint16_t)raw(ctl, BN_CTL_DUTY_A, o->d_a);
    d.duty_b = (uint16_t)raw(ctl, BN_CTL_DUTY_B, o->d_b);
    d.duty_c = (uint16_t)raw(ctl, BN_CTL_DUTY_C, o->d_c);
    d.enable = (uint8_t)raw(ctl, BN_CTL_ENABLE, o->enable ? 1.0 : 0.0);
    d.step = (uint16_t)raw(ctl, BN_CTL_DUTY_STEP, (double)((o->k + 1) % ctl->m_step));
    memset(f, 0, sizeof *f);
    f->id = BENCH_DBC_PWM_DUTY_FRAME_ID;
    f->flags = ctl->duty_flags;
    f->len = (uint8_t)bench_dbc_pwm_duty_pack(f->data, &d, sizeof f->data);
    bench_e2e_protect(BENCH_E2E_PWM_DUTY_DATA_ID, f->data, f->len, BENCH_E2E_PWM_DUTY_CRC_INDEX);
}

static void tel_frame(const bn_ctl_t *ctl, const cc_out_t *o, bn_frame_t *f)
{
    struct bench_dbc_ctrl_telemetry_t t;
    int32_t ack = ctl->ack_seq;
    bench_dbc_ctrl_telemetry_init(&t);
    t.theta_hat = (uint16_t)raw(ctl, BN_CTL_THETA_HAT, o->theta_hat);
    t.w_hat = (int32_t)raw(ctl, BN_CTL_W_HAT, o->w_hat);
    t.err = (int16_t)raw(ctl, BN_CTL_ERR, o->err);
    t.mode = (uint8_t)raw(ctl, BN_CTL_MODE, (double)o->mode);
    t.step = (uint32_t)raw(ctl, BN_CTL_TEL_STEP, (double)(o->k % ctl->m_tel));
    t.run_id = (uint16_t)raw(ctl, BN_CTL_RUN_ID, (double)ctl->run_id);
    t.cmd_ack_valid = (uint8_t)raw(ctl, BN_CTL_ACK_VALID, ack >= 0 ? 1.0 : 0.0);
    t.cmd_ack = (uint8_t)raw(ctl, BN_CTL_ACK, ack > 0 ? (double)ack : 0.0);
    memset(f, 0, sizeof *f);
    f->id = BENCH_DBC_CTRL_TELEMETRY_FRAME_ID;
    f->flags = ctl->tel_flags;
    f->len = (uint8_t)bench_dbc_ctrl_telemetry_pack(f->data, &t, sizeof f->data);
    bench_e2e_protect(BENCH_E2E_CTRL_TELEMETRY_DATA_ID, f->data, f->len,
                      BENCH_E2E_CTRL_TELEMETRY_CRC_INDEX);
}

static void emit(bn_ctl_t *ctl, bn_ctl_sink_t sink, void *ctx, const bn_frame_t *f)
{
    if (sink(ctx, f) != 0) {
        ctl->c.send_errors++;
        ctl->c.frames_lost_on_send++;
    }
}

static void reject(bn_ctl_t *ctl, int reason) { ctl->c.reasons[reason]++; }

int bn_ctl_apply_commands(bn_ctl_t *ctl, int64_t k)
{
    if (k > ctl->applied_upto) ctl->applied_upto = k;
    if (ctl->n_cmds == 0 || ctl->cmds[0].step > k) return BN_CTL_EV_NONE; /* in step order */
    int kept = 0, rc = CC_OK;
    for (int j = 0; j < ctl->n_cmds; j++) {
        bn_ctl_cmd_t c = ctl->cmds[j];
        if (c.step > k || rc != CC_OK) {
            ctl->cmds[kept++] = c;
            continue;
        }
        ctl->applied_seq = c.seq;
        if (c.cmd == BENCH_DBC_BENCH_COMMAND_CMD_START_CHOICE
            || c.cmd == BENCH_DBC_BENCH_COMMAND_CMD_ENABLE_CHOICE
            || c.cmd == BENCH_DBC_BENCH_COMMAND_CMD_RESET_CHOICE) {
            ctl->faulted = 0;
            rc = cc_foc_set_enable(ctl->foc, 1);
        } else if (c.cmd == BENCH_DBC_BENCH_COMMAND_CMD_STOP_CHOICE
                   || c.cmd == BENCH_DBC_BENCH_COMMAND_CMD_DISABLE_CHOICE) {
            rc = cc_foc_set_enable(ctl->foc, 0);
            if (c.cmd == BENCH_DBC_BENCH_COMMAND_CMD_STOP_CHOICE) ctl->stopped = 1;
        }
        if (rc != CC_OK) continue; /* as Python's set_enable raises before the reference */
        ctl->w_m_ref = c.speed_ref_rpm / ctl->rpm_per_rad_s;
        ctl->has_w_ref = 1;
        cc_foc_set_speed_ref(ctl->foc, ctl->w_m_ref);
    }
    ctl->n_cmds = kept;
    if (rc != CC_OK) {
        ctl->error = rc;
        return BN_CTL_EV_ERROR;
    }
    return BN_CTL_EV_NONE;
}

/* ControllerNode._run_ready: the steps whose sample (and truth) are here, in order */
static int run_ready(bn_ctl_t *ctl, bn_ctl_sink_t sink, void *ctx)
{
    for (;;) {
        int64_t k = ctl->next_k;
        size_t s = slot(k);
        if (ctl->s_k[s] != k || (ctl->needs_truth && ctl->t_k[s] != k))
            return BN_CTL_EV_NONE;
        if (ctl->n_cmds == 0 && ctl->cmds_more)
            return BN_CTL_EV_CMDS; /* Python hands the rest of its pending list */
        int ev = bn_ctl_apply_commands(ctl, k);
        if (ev != BN_CTL_EV_NONE) return ev;
        cc_meas_t m;
        m.k = k;
        m.i_a = ctl->s_i_a[s];
        m.i_b = ctl->s_i_b[s];
        m.i_c = -m.i_a - m.i_b;
        m.u_dc = ctl->s_u_dc[s];
        m.has_truth = 0;
        m.theta_e = m.w_e = 0.0;
        if (ctl->needs_truth) {
            m.has_truth = 1;
            m.theta_e = ctl->t_theta[s];
            m.w_e = ctl->t_w_m[s] * ctl->n_p;
        }
        cc_out_t o;
        int rc = cc_foc_step(ctl->foc, &m, &o);
        if (rc != CC_OK) {
            ctl->error = rc;
            return BN_CTL_EV_ERROR;
        }
        if (ctl->sup != NULL)
            cc_sup_after(ctl->sup, ctl->foc, &m, &o);
        ctl->s_k[s] = -1;
        ctl->t_k[s] = -1;
        ctl->last = o;
        ctl->has_last = 1;
        size_t a = (size_t)(k % BN_CTL_ANSWERS);
        ctl->a_k[a] = k;
        duty_frame(ctl, &o, &ctl->a_duty[a]);
        tel_frame(ctl, &o, &ctl->a_tel[a]);
        emit(ctl, sink, ctx, &ctl->a_duty[a]);
        emit(ctl, sink, ctx, &ctl->a_tel[a]);
        ctl->next_k = k + 1;
        ctl->c.steps++;
    }
}

int bn_ctl_resume(bn_ctl_t *ctl, bn_ctl_sink_t sink, void *ctx)
{
    if (ctl->send_ack) {
        ctl->send_ack = 0;
        if (ctl->has_last) {
            bn_frame_t f;
            tel_frame(ctl, &ctl->last, &f);
            emit(ctl, sink, ctx, &f);
        }
    }
    return run_ready(ctl, sink, ctx);
}

static int on_sample(bn_ctl_t *ctl, const bn_frame_t *in, bn_ctl_sink_t sink, void *ctx)
{
    struct bench_dbc_phase_samples_t s;
    if (in->len != BENCH_DBC_PHASE_SAMPLES_LENGTH) {
        reject(ctl, BN_CTL_R_BAD_LENGTH);
        return BN_CTL_EV_NONE;
    }
    if (bench_dbc_phase_samples_unpack(&s, in->data, in->len) != 0) {
        reject(ctl, BN_CTL_R_DECODE_ERROR);
        return BN_CTL_EV_NONE;
    }
    if (!bench_e2e_check(BENCH_E2E_PHASE_SAMPLES_DATA_ID, in->data, in->len,
                         BENCH_E2E_PHASE_SAMPLES_CRC_INDEX)) {
        reject(ctl, BN_CTL_R_BAD_CRC);
        return BN_CTL_EV_NONE;
    }
    if (!(bench_dbc_phase_samples_i_a_is_in_range(s.i_a)
          && bench_dbc_phase_samples_i_b_is_in_range(s.i_b)
          && bench_dbc_phase_samples_u_dc_is_in_range(s.u_dc)
          && bench_dbc_phase_samples_status_is_in_range(s.status)
          && bench_dbc_phase_samples_step_is_in_range(s.step))) {
        reject(ctl, BN_CTL_R_OUT_OF_RANGE);
        return BN_CTL_EV_NONE;
    }
    int64_t k = unwrap((int64_t)s.step, ctl->next_k, ctl->m_step);
    if (k < ctl->next_k) {
        size_t a = (size_t)(((k % BN_CTL_ANSWERS) + BN_CTL_ANSWERS) % BN_CTL_ANSWERS);
        if (ctl->a_k[a] != k) {
            reject(ctl, BN_CTL_R_STALE);
            return BN_CTL_EV_NONE;
        }
        reject(ctl, BN_CTL_R_REPEATED);
        emit(ctl, sink, ctx, &ctl->a_duty[a]);
        if (ctl->has_last && ctl->last.k == k) {
            bn_frame_t f; /* the telemetry with the acknowledgement held now */
            tel_frame(ctl, &ctl->last, &f);
            emit(ctl, sink, ctx, &f);
        } else {
            emit(ctl, sink, ctx, &ctl->a_tel[a]);
        }
        return BN_CTL_EV_NONE;
    }
    if (ctl->sample_lead >= 0 && k > ctl->next_k + ctl->sample_lead) {
        reject(ctl, BN_CTL_R_FUTURE); /* further than a lockstep plant can be */
        return BN_CTL_EV_NONE;
    }
    size_t j = slot(k);
    if (ctl->s_k[j] == k) {
        reject(ctl, BN_CTL_R_REPEATED);
        return BN_CTL_EV_NONE;
    }
    ctl->c.frames_accepted++;
    ctl->c.samples_accepted++;
    if (ctl->realtime && k > ctl->next_k)
        ctl->next_k = k; /* real time: never wait for the past, skip to the newest */
    ctl->s_k[j] = k;
    ctl->s_i_a[j] = bench_dbc_phase_samples_i_a_decode(s.i_a);
    ctl->s_i_b[j] = bench_dbc_phase_samples_i_b_decode(s.i_b);
    ctl->s_u_dc[j] = bench_dbc_phase_samples_u_dc_decode(s.u_dc);
    return run_ready(ctl, sink, ctx);
}

static int on_truth(bn_ctl_t *ctl, const bn_frame_t *in, bn_ctl_sink_t sink, void *ctx)
{
    struct bench_dbc_plant_truth_t t;
    if (in->len != BENCH_DBC_PLANT_TRUTH_LENGTH) {
        reject(ctl, BN_CTL_R_BAD_LENGTH);
        return BN_CTL_EV_NONE;
    }
    if (bench_dbc_plant_truth_unpack(&t, in->data, in->len) != 0) {
        reject(ctl, BN_CTL_R_DECODE_ERROR);
        return BN_CTL_EV_NONE;
    }
    if (!bench_e2e_check(BENCH_E2E_PLANT_TRUTH_DATA_ID, in->data, in->len,
                         BENCH_E2E_PLANT_TRUTH_CRC_INDEX)) {
        reject(ctl, BN_CTL_R_BAD_CRC);
        return BN_CTL_EV_NONE;
    }
    if (!(bench_dbc_plant_truth_theta_e_is_in_range(t.theta_e)
          && bench_dbc_plant_truth_w_m_is_in_range(t.w_m)
          && bench_dbc_plant_truth_tau_e_is_in_range(t.tau_e)
          && bench_dbc_plant_truth_tau_l_is_in_range(t.tau_l)
          && bench_dbc_plant_truth_step_is_in_range(t.step)
          && bench_dbc_plant_truth_duty_age_is_in_range(t.duty_age)
          && bench_dbc_plant_truth_run_id_is_in_range(t.run_id))) {
        reject(ctl, BN_CTL_R_OUT_OF_RANGE);
        return BN_CTL_EV_NONE;
    }
    int64_t k = unwrap((int64_t)t.step, ctl->next_k, ctl->m_truth);
    size_t j = slot(k);
    if (k < ctl->next_k || ctl->t_k[j] == k) {
        reject(ctl, BN_CTL_R_REPEATED);
        return BN_CTL_EV_NONE;
    }
    if (k > ctl->next_k + (ctl->truth_lead >= 0 ? ctl->truth_lead : ctl->m_step)) {
        reject(ctl, BN_CTL_R_FUTURE);
        return BN_CTL_EV_NONE;
    }
    ctl->c.frames_accepted++;
    ctl->t_k[j] = k;
    ctl->t_theta[j] = bench_dbc_plant_truth_theta_e_decode(t.theta_e);
    ctl->t_w_m[j] = bench_dbc_plant_truth_w_m_decode(t.w_m);
    return run_ready(ctl, sink, ctx);
}

int bn_ctl_on_frame(bn_ctl_t *ctl, const bn_frame_t *in, bn_ctl_sink_t sink, void *ctx)
{
    if (in->flags & BN_EXT) {
        ctl->c.frames_unknown++; /* not in the DBC: its identifiers are 11-bit */
        return BN_CTL_EV_NONE;
    }
    int cmd = in->id == BENCH_DBC_BENCH_COMMAND_FRAME_ID;
    if (!cmd && (in->flags & (BN_RTR | BN_ERR))) {
        reject(ctl, BN_CTL_R_DECODE_ERROR);
        return BN_CTL_EV_NONE;
    }
    if (cmd) {
        if (bn_cmd_seen_copy(&ctl->cmd_seen, in, ctl->next_k)) return BN_CTL_EV_NONE;
        ctl->cmd_frame = *in;
        return BN_CTL_EV_COMMAND;
    }
    if (in->id == BENCH_DBC_PHASE_SAMPLES_FRAME_ID)
        return on_sample(ctl, in, sink, ctx);
    if (in->id == BENCH_DBC_PLANT_TRUTH_FRAME_ID && ctl->needs_truth)
        return on_truth(ctl, in, sink, ctx);
    return BN_CTL_EV_NONE; /* the loop listens to no other frame */
}

/* The frames one received frame makes (a duty and its telemetry, or the answers
 * resent), collected and sent together with one bn_send_many when it is handled. */
typedef struct {
    bn_ctl_t *ctl;
    bn_bus_t *bus;
    int n;
    bn_frame_t f[BN_BATCH];
} batch_t;

/* Send what is collected; what the batch did not take goes one by one (bn_send's
 * wait for room), each failure counted as emit counts it. */
static void flush(batch_t *b)
{
    int j = b->n > 0 ? bn_send_many(b->bus, b->f, b->n) : 0;
    for (; j < b->n; j++) {
        if (bn_send(b->bus, &b->f[j]) != 0) {
            b->ctl->c.send_errors++;
            b->ctl->c.frames_lost_on_send++;
        }
    }
    b->n = 0;
}

static int bus_sink(void *ctx, const bn_frame_t *f)
{
    batch_t *b = (batch_t *)ctx;
    if (b->n == BN_BATCH)
        flush(b);
    b->f[b->n++] = *f;
    return 0;
}

/* The oldest held command frame that is no copy of a command Python took since it was
 * held (bn.h, bn_cmd_seen_t: dropped and counted) into cmd_frame, for Python:
 * BN_CTL_EV_COMMAND; BN_CTL_EV_NONE when none is left */
static int unhold(bn_ctl_t *ctl)
{
    int ev = BN_CTL_EV_NONE;
    while (ctl->held.n > 0 && ev == BN_CTL_EV_NONE) {
        bn_held_take(&ctl->held, &ctl->cmd_frame);
        if (!bn_cmd_seen_copy(&ctl->cmd_seen, &ctl->cmd_frame, ctl->next_k))
            ev = BN_CTL_EV_COMMAND;
    }
    if (ctl->held.n == 0) ctl->slack = 0;
    return ev;
}

/* controller_loop: frames until an event; real time: the sample timeout.  In real time
 * a command frame is held while a sample may be waiting behind it, so that no duty waits
 * on Python's handling of a command: it goes to Python once a step has sent its duty (or
 * before the first step) and nothing more is queued, or after a poll interval without a
 * sample.  One that arrives
 * for the step being computed is then applied at the next step, counted as late; the
 * bench sends commands ahead of their step. */
int bn_ctl_serve(bn_ctl_t *ctl, bn_bus_t *bus)
{
    int64_t now = bn_now_ns();
    int64_t t_return = now + ctl->return_ns;
    if (ctl->t_last == 0)
        ctl->t_last = ctl->t_sample = now;
    batch_t out;
    out.ctl = ctl;
    out.bus = bus;
    out.n = 0;
    int ev = bn_ctl_resume(ctl, bus_sink, &out);
    flush(&out);
    if (ev != BN_CTL_EV_NONE)
        return ev;
    for (;;) {
        if (ctl->stopped) { /* the frames still held go to Python first */
            int e = unhold(ctl);
            return e != BN_CTL_EV_NONE ? e : BN_CTL_EV_STOPPED;
        }
        now = bn_now_ns();
        if (now >= t_return)
            return BN_CTL_EV_POLL; /* also while frames keep coming: Python looks in time */
        bn_frame_t in;
        int64_t deadline = bn_now_ns() + ctl->poll_ns;
        if (deadline > t_return)
            deadline = t_return;
        /* before the first step no sample waits for a duty (a start goes at once) */
        int slack = ctl->held.n > 0 && (ctl->slack || ctl->c.steps == 0);
        int r = bn_recv_until(bus, &in, slack ? 0 : deadline); /* slack: what is queued */
        if (r == 0 && ctl->held.n > 0 && (slack || bn_now_ns() >= deadline)) {
            int e = unhold(ctl);
            if (e != BN_CTL_EV_NONE) return e;
            if (slack) continue; /* every frame held was a copy: wait for frames again */
        }
        now = bn_now_ns();
        if (r < 0) {
            ctl->error = -r;
            return BN_CTL_EV_ERROR;
        }
        if (ctl->realtime) {
            if (ctl->c.samples_accepted != ctl->seen) {
                ctl->seen = ctl->c.samples_accepted;
                ctl->t_sample = now;
            } else if (ctl->seen && now - ctl->t_sample > ctl->sample_timeout_ns) {
                /* again after one more poll while no sample comes, as the Python loop */
                ctl->t_sample = now - ctl->sample_timeout_ns + ctl->poll_ns;
                return BN_CTL_EV_TIMEOUT;
            }
        }
        if (r == 0) {
            if (now - ctl->t_last > ctl->idle_ns)
                return BN_CTL_EV_IDLE;
            if (now < deadline || now >= t_return)
                return BN_CTL_EV_POLL; /* a signal, or time for Python to look */
            continue;
        }
        uint32_t id = in.id; /* the loop listens to these identifiers (extended or not) */
        if (id != BENCH_DBC_PHASE_SAMPLES_FRAME_ID && id != BENCH_DBC_BENCH_COMMAND_FRAME_ID
            && !(ctl->needs_truth && id == BENCH_DBC_PLANT_TRUTH_FRAME_ID))
            continue;
        ctl->t_last = now;
        uint64_t steps = ctl->c.steps;
        ev = bn_ctl_on_frame(ctl, &in, bus_sink, &out);
        flush(&out);
        if (ctl->c.steps != steps)
            ctl->slack = 1; /* a duty is out */
        if (ev == BN_CTL_EV_COMMAND && ctl->realtime) {
            bn_frame_t got = ctl->cmd_frame;
            if (!bn_held_put(&ctl->held, &got, &ctl->cmd_frame) ||
                bn_cmd_seen_copy(&ctl->cmd_seen, &ctl->cmd_frame, ctl->next_k))
                continue;
            return BN_CTL_EV_COMMAND; /* full: the oldest now */
        }
        if (ev != BN_CTL_EV_NONE)
            return ev;
    }
}

void bn_ctl_cmd_seen_init(bn_ctl_t *ctl, uint32_t id, int64_t span)
{
    bn_cmd_seen_init(&ctl->cmd_seen, id, span);
}

void bn_ctl_cmd_taken(bn_ctl_t *ctl, const bn_frame_t *f)
{
    bn_cmd_seen_take(&ctl->cmd_seen, f, ctl->next_k);
}

uint64_t bn_ctl_cmd_copies(const bn_ctl_t *ctl) { return ctl->cmd_seen.copies; }
