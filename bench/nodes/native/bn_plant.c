/* The plant node's per-period logic (bn_plant.h): bench.nodes._plant_node.PlantNode's
 * hot path, statement for statement; the comments name the Python method each
 * function follows.  Frames in, frames out; no transport, no allocation. */
#include "bn_plant.h"

#include <math.h>
#include <string.h>

#include "bench_dbc.h"
#include "bench_e2e.h"
#include "plant_machine.h"
#include "plant_protection.h"
#include "plant_sensors.h"

#define TWO_PI 6.283185307179586

static const char SIG_NAMES[] =
    "PhaseSamples.i_a,PhaseSamples.i_b,PhaseSamples.u_dc,PhaseSamples.status,PhaseSamples.step,"
    "PositionSensor.theta_m,PositionSensor.step,"
    "PlantTruth.theta_e,PlantTruth.w_m,PlantTruth.tau_e,PlantTruth.tau_L,PlantTruth.duty_age,"
    "PlantTruth.step,PlantTruth.run_id,"
    "PlantStatus.state,PlantStatus.fault_code,PlantStatus.overruns,PlantStatus.late_frames,"
    "PlantStatus.step,"
    "PwmDuty.duty_a,PwmDuty.duty_b,PwmDuty.duty_c,PwmDuty.enable,PwmDuty.step,"
    "PlantCurrents.i_a,PlantCurrents.i_b,PlantCurrents.step,PlantCurrents.run_id";

static const char REJECT_NAMES[] =
    "bad_crc,bad_length,decode_error,out_of_range,stale_counter,future_counter,wrong_step,"
    "repeated_counter";

const char *bn_plant_signal_names(void) { return SIG_NAMES; }
const char *bn_plant_reject_names(void) { return REJECT_NAMES; }
size_t bn_plant_sizeof(void) { return sizeof(bn_plant_t); }
size_t bn_plant_loop_sizeof(void) { return sizeof(bn_plant_loop_t); }
size_t bn_plant_edge_sizeof(void) { return sizeof(bn_plant_edge_t); }
size_t bn_plant_sfault_sizeof(void) { return sizeof(bn_plant_sfault_t); }

/* Python's float % (the sign of the divisor). */
static double py_mod(double x, double m)
{
    double r = fmod(x, m);
    if (r != 0.0 && ((m < 0.0) != (r < 0.0))) r += m;
    return r;
}

/* Python's round() of a float: half to even (the default rounding mode). */
static double py_round(double x) { return nearbyint(x); }

int64_t bn_plant_raw(const bn_sig_t *s, double v)
{
    /* Codec.encode: wrap or clip the physical value */
    if (s->modulus) {
        double w = py_round((v - s->offset) / s->scale), r;
        if (fabs(w) < 0x1p62 && s->modulus > 0) {
            /* a whole number: its remainder in integers is fmod's exactly (both are exact);
             * a zero remainder comes out +0.0 where fmod keeps -0.0, which no raw value
             * below tells apart (0 * scale + offset, then rounded to a whole number) */
            int64_t q = (int64_t)w % s->modulus;
            r = (double)(q < 0 ? q + s->modulus : q);
        } else {
            r = py_mod(w, (double)s->modulus);
        }
        v = r * s->scale + s->offset;
    } else if (v < s->lo) {
        v = s->lo;
    } else if (v > s->hi) {
        v = s->hi;
    }
    /* bench.wire._hotcodec._raw_expr: cantools' numeric_scaled_to_raw, x = v - offset,
     * q, m = divmod(x, scale), round(q if m == 0 else x / scale), is round(x / scale):
     * a remainder of 0 (fmod is exact) makes x a whole multiple of scale, so x / scale
     * rounds to a whole number, which Python's float floor division then returns as q
     * (floor of (x - m) / scale = x / scale); bench_wire_raw (bench_wire.h) says the same */
    if (s->scale == 1.0 && s->offset == 0.0) return (int64_t)py_round(v);
    return (int64_t)py_round((v - s->offset) / s->scale);
}

#define RAW(u, idx, v) bn_plant_raw(&(u)->sig[idx], (v))

static void put(bn_plant_t *u, bn_frame_t *f, uint32_t id, int len, int msg)
{
    (void)u;
    f->id = id;
    f->len = (uint8_t)len;
    f->flags = (uint8_t)u->msg_flags[msg];
    f->t_ns = 0;
}

void bn_plant_status_frame(bn_plant_t *u, int state, int fault_code, bn_frame_t *f)
{
    struct bench_dbc_plant_status_t m;
    uint64_t late = u->late_frames_base + u->late_duties;
    for (int r = 0; r < BN_RJ_N; r++) late += u->duty_rejected[r];
    bench_dbc_plant_status_init(&m);
    m.state = (uint8_t)RAW(u, BN_S_ST_STATE, state);
    m.fault_code = (uint8_t)RAW(u, BN_S_ST_FAULT_CODE, fault_code);
    m.overruns = (uint16_t)RAW(u, BN_S_ST_OVERRUNS, (double)(u->overruns < 0xFFFF ? u->overruns : 0xFFFF));
    m.late_frames = (uint16_t)RAW(u, BN_S_ST_LATE_FRAMES, (double)(late < 0xFFFF ? late : 0xFFFF));
    m.step = (uint16_t)RAW(u, BN_S_ST_STEP, (double)(u->k % u->m_status));
    memset(f, 0, sizeof *f);
    bench_dbc_plant_status_pack(f->data, &m, sizeof f->data);
    bench_e2e_protect(BENCH_E2E_PLANT_STATUS_DATA_ID, f->data, BENCH_DBC_PLANT_STATUS_LENGTH,
                      BENCH_E2E_PLANT_STATUS_CRC_INDEX);
    put(u, f, BENCH_DBC_PLANT_STATUS_FRAME_ID, BENCH_DBC_PLANT_STATUS_LENGTH, 3);
}

static void queue_status(bn_plant_t *u, int state, int code)
{
    if (u->n_outbox < (int)(sizeof u->outbox / sizeof u->outbox[0]))
        bn_plant_status_frame(u, state, code, &u->outbox[u->n_outbox++]);
}

/* PlantNode.trip */
static void trip(bn_plant_t *u, int code)
{
    if (u->fault != PLANT_FAULT_NONE) return;
    u->fault = code;
    u->fault_step = u->k;
    if (code >= 0 && code < 8) u->trips[code]++;
    queue_status(u, BENCH_DBC_PLANT_STATUS_STATE_FAULT_CHOICE, code);
}

/* PlantNode.reset_fault */
static void reset_fault(bn_plant_t *u)
{
    u->last_duty_k = u->k;
    u->rounds_waiting = 0;
    if (u->fault == PLANT_FAULT_NONE) return;
    u->fault = PLANT_FAULT_NONE;
    u->fault_step = -1;
    u->resets++;
    queue_status(u, BENCH_DBC_PLANT_STATUS_STATE_RUNNING_CHOICE, PLANT_FAULT_NONE);
}

static int64_t unwrap(int64_t raw, int64_t expected, int64_t modulus)
{
    int64_t half = modulus / 2;
    int64_t d = (raw - expected + half) % modulus;
    if (d < 0) d += modulus;
    return expected + d - half;
}

int bn_plant_has_duty(const bn_plant_t *u, int64_t t)
{
    return t >= 0 && u->duties[t & (BN_PLANT_RING - 1)].tag == t;
}

#define has_duty bn_plant_has_duty

/* NodeFaults.duty_fate(k) and duty_shift(k) from their tables (bn_plant_faults_t) */
static int duty_fate(const bn_plant_t *u, int64_t k)
{
    const bn_plant_faults_t *F = &u->faults;
    return F->fate != NULL && k >= 0 && k < F->n_k ? F->fate[k] : BN_FATE_NONE;
}

static int64_t duty_shift(const bn_plant_t *u, int64_t k, int realtime)
{
    const bn_plant_faults_t *F = &u->faults;
    const int32_t *s = realtime ? F->shift_rt : F->shift_ls;
    return s != NULL && k >= 0 && k < F->n_k ? s[k] : 0;
}

/* NodeFaults.answer_lost(t): lockstep, the duty tagged t answers sample t - 1, lost on its
 * first sending (bit 0 of the nosend table: NodeFaults.lost("PhaseSamples", t - 1)) */
static int answer_lost(const bn_plant_t *u, int64_t t)
{
    const bn_plant_faults_t *F = &u->faults;
    return F->nosend != NULL && t >= 1 && t - 1 < F->n_k && (F->nosend[t - 1] & 1);
}

/* PlantNode.clock: the clock of the frames' receive stamps */
static int64_t clock_now(const bn_plant_t *u)
{
    return u->faults.clock_ns != NULL ? u->faults.clock_ns() : bn_realtime_ns();
}

static void reject_duty(bn_plant_t *u, int reason)
{
    u->rejected[reason]++;
    if (reason != BN_RJ_REPEATED) u->duty_rejected[reason]++;
}

static int in_check(const bn_sig_t *s, double v)
{
    return s->chk_lo > s->chk_hi || !(v < s->chk_lo || v > s->chk_hi);
}

/* PlantNode.on_message (PwmDuty) with Codec.decode's checks, and PlantNode._on_duty */
void bn_plant_on_duty(bn_plant_t *u, const bn_frame_t *f)
{
    struct bench_dbc_pwm_duty_t m;
    if (f->flags & (BN_RTR | BN_ERR)) {
        reject_duty(u, BN_RJ_DECODE_ERROR);
        return;
    }
    if (f->len != BENCH_DBC_PWM_DUTY_LENGTH) {
        reject_duty(u, BN_RJ_BAD_LENGTH);
        return;
    }
    if (bench_dbc_pwm_duty_unpack(&m, f->data, f->len) != 0) {
        reject_duty(u, BN_RJ_DECODE_ERROR);
        return;
    }
    if (!bench_e2e_check(BENCH_E2E_PWM_DUTY_DATA_ID, f->data, f->len,
                         BENCH_E2E_PWM_DUTY_CRC_INDEX)) {
        reject_duty(u, BN_RJ_BAD_CRC);
        return;
    }
    const bn_sig_t *S = u->sig;
    double d_a = (double)m.duty_a * S[BN_S_PD_DUTY_A].scale + S[BN_S_PD_DUTY_A].offset;
    double d_b = (double)m.duty_b * S[BN_S_PD_DUTY_B].scale + S[BN_S_PD_DUTY_B].offset;
    double d_c = (double)m.duty_c * S[BN_S_PD_DUTY_C].scale + S[BN_S_PD_DUTY_C].offset;
    if (!in_check(&S[BN_S_PD_DUTY_A], d_a) || !in_check(&S[BN_S_PD_DUTY_B], d_b) ||
        !in_check(&S[BN_S_PD_DUTY_C], d_c) || !in_check(&S[BN_S_PD_ENABLE], (double)m.enable) ||
        !in_check(&S[BN_S_PD_STEP], (double)m.step)) {
        reject_duty(u, BN_RJ_OUT_OF_RANGE);
        return;
    }
    int64_t k = u->k;
    int64_t t = unwrap((int64_t)m.step, k - u->delay, u->m_step);
    if (t == 0) { /* answers no sample */
        reject_duty(u, BN_RJ_WRONG_STEP);
        u->dut_answered = 1;
        trip(u, BENCH_DBC_PLANT_STATUS_FAULT_CODE_WRONG_STEP_CHOICE);
        return;
    }
    if (t > k + 1) {
        reject_duty(u, BN_RJ_FUTURE);
        return;
    }
    int fate = duty_fate(u, t + u->delay);
    if (fate == BN_FATE_NONE && !u->realtime && t >= k - u->delay && answer_lost(u, t))
        fate = BN_FATE_LOST; /* the answer to a sample lost on its first sending: too late */
    if (fate != BN_FATE_NONE) { /* a bus fault: lost, or arrives with a bad E2E CRC */
        if (t > u->dropped_upto)
            u->dropped_upto = t; /* arrived all the same (bn_plant_ready) */
        if (fate == BN_FATE_CORRUPT)
            reject_duty(u, BN_RJ_BAD_CRC);
        else
            u->faults.duties_lost++;
        return;
    }
    if (u->realtime) {
        if (t == u->latest_duty_step || has_duty(u, t)) {
            u->rejected[BN_RJ_REPEATED]++;
            return;
        }
        if (t < u->latest_duty_step) {
            reject_duty(u, BN_RJ_STALE);
            return;
        }
    } else {
        int64_t needed = k - u->delay;
        if (t < needed - 16) { /* DUTY_REPEAT_WINDOW */
            reject_duty(u, BN_RJ_STALE);
            return;
        }
        if (t < needed || has_duty(u, t)) {
            u->rejected[BN_RJ_REPEATED]++;
            return;
        }
    }
    if (!(0.0 <= d_a && d_a <= 1.0 && 0.0 <= d_b && d_b <= 1.0 && 0.0 <= d_c && d_c <= 1.0)) {
        reject_duty(u, BN_RJ_OUT_OF_RANGE);
        return;
    }
    u->accepted++;
    u->dut_answered = 1;
    u->last_duty_k = k;
    bn_plant_duty_t *slot = &u->duties[t & (BN_PLANT_RING - 1)];
    slot->d[0] = d_a;
    slot->d[1] = d_b;
    slot->d[2] = d_c;
    slot->en = m.enable != 0;
    slot->tag = t;
    if (u->realtime) { /* a delay in us: the frame is held from its arrival */
        const bn_plant_faults_t *F = &u->faults;
        int64_t hold = F->hold_ns != NULL && k >= 0 && k < F->n_k ? F->hold_ns[k] : 0;
        u->faults.released[t & (BN_PLANT_RING - 1)] =
            hold > 0 ? (f->t_ns != 0 ? f->t_ns : clock_now(u)) + hold : INT64_MIN;
    }
    if (!u->realtime && t > u->latest_duty_step) {
        u->latest_duty_step = t;
        memcpy(u->latest, slot->d, sizeof u->latest);
        u->latest_en = slot->en;
    }
}

/* The sensors' noise source during a native run: Python's draws, in order (bn_plant_noise_t). */
static int next_draw(void *ctx, double sd, double *out)
{
    bn_plant_noise_t *n = ctx;
    (void)sd; /* drawn with it */
    if (n->used >= n->n) return 1;
    *out = n->draws[n->used++];
    return 0;
}

/* Plant.sample: the measured values of the true ones (the noise from u->noise). */
static void measure(bn_plant_t *u, const double i[3], double u_dc, double meas[4])
{
    plant_sensors *s = &u->pl->sens;
    if (u->noise.draws == NULL) {
        plant_sensors_measure(s, i, u_dc, meas);
        return;
    }
    plant_gauss_fn fn = s->gauss;
    void *ctx = s->gauss_ctx;
    s->gauss = next_draw;
    s->gauss_ctx = &u->noise;
    plant_sensors_measure(s, i, u_dc, meas);
    s->gauss = fn; /* the Python generator's again, for Python after the run */
    s->gauss_ctx = ctx;
}

/* PlantFaults.before_period: the parameters and legs of instant k on (the edges up to k). */
static void fault_edges(bn_plant_t *u, int64_t k)
{
    bn_plant_faults_t *F = &u->faults;
    while (F->next_edge < F->n_edges && F->edges[F->next_edge].k <= k) {
        const bn_plant_edge_t *e = &F->edges[F->next_edge++];
        if (e->set_legs) plant_set_legs(u->pl, e->leg);
        if (e->set_pars) plant_set_pars(u->pl, &e->pars);
    }
}

static int window_active(const bn_plant_sfault_t *w, int64_t k)
{
    return w->k0 <= k && (w->k1 < 0 || k < w->k1);
}

/* PlantFaults.sample: the active sensor faults on the measured sample of instant k. */
static void fault_sample(bn_plant_t *u, int64_t k, double meas[4])
{
    bn_plant_faults_t *F = &u->faults;
    double i[3] = {meas[0], meas[1], meas[2]};
    int have_last = F->last_k == k - 1;
    double last[3] = {F->last[0], F->last[1], F->last[2]};
    F->last[0] = meas[0];
    F->last[1] = meas[1];
    F->last[2] = meas[2];
    F->last_k = k;
    for (int n = 0; n < F->n_sensor; n++) {
        bn_plant_sfault_t *w = &F->sensor[n];
        if (!window_active(w, k)) continue;
        int x = w->phase;
        switch (w->kind) {
        case BN_SF_U_OFFSET: meas[3] += w->value; break;
        case BN_SF_OFFSET: i[x] += w->value; break;
        case BN_SF_GAIN: i[x] *= w->value; break;
        case BN_SF_LOST: i[x] = 0.0; break;
        case BN_SF_STUCK:
            if (!w->held) { /* the last sample before the window (at k0 = 0 its own) */
                w->hold = have_last ? last[x] : i[x];
                w->held = 1;
            }
            i[x] = w->hold;
            break;
        default: break; /* BN_SF_POS_LOST: the frame, not the sample */
        }
    }
    meas[0] = i[0];
    meas[1] = i[1];
    meas[2] = i[2];
}

/* NodeFaults.sends(message, k) from its table: bit 0 PhaseSamples, bit 1 PositionSensor */
static int sends(bn_plant_t *u, int bit, int64_t k)
{
    bn_plant_faults_t *F = &u->faults;
    if (F->nosend == NULL || k < 0 || k >= F->n_k || !(F->nosend[k] & (1 << bit))) return 1;
    F->not_sent[bit]++;
    return 0;
}

/* PlantNode.frames_now; i_now: the plant's phase currents now when the caller has them
 * (plant_currents of the same state: the same numbers), else NULL */
static void frames_now(bn_plant_t *u, const double *i_now)
{
    plant *pl = u->pl;
    int64_t k = u->k;
    double i[3], uu, meas[4];
    if (u->faults.on) fault_edges(u, k);
    if (u->meas_k == k) {
        memcpy(i, pl->meas, sizeof i);
        uu = pl->meas[3];
    } else {
        if (i_now != NULL && !u->faults.on) /* a fault edge may have changed the legs */
            memcpy(i, i_now, sizeof i);
        else
            plant_currents(pl, i);
        uu = pl->u_dc;
    }
    measure(u, i, uu, meas);
    if (u->faults.on) fault_sample(u, k, meas);
    int status;
    if (u->fault != PLANT_FAULT_NONE)
        status = BENCH_DBC_PHASE_SAMPLES_STATUS_FAULT_CHOICE;
    else
        status = u->started && !u->stopped ? BENCH_DBC_PHASE_SAMPLES_STATUS_RUNNING_CHOICE
                                           : BENCH_DBC_PHASE_SAMPLES_STATUS_IDLE_CHOICE;
    int n = 0;
    for (int b = 0; b < u->n_outbox; b++) u->out[n++] = u->outbox[b];
    u->n_outbox = 0;
    int first = n;
    u->faults.out_wh[0] = u->faults.out_wh[1] = 0; /* no withheld samples in u->out */
    {
        struct bench_dbc_phase_samples_t m;
        bn_frame_t *f = &u->out[n++];
        bench_dbc_phase_samples_init(&m);
        m.i_a = (int16_t)RAW(u, BN_S_PS_I_A, meas[0]);
        m.i_b = (int16_t)RAW(u, BN_S_PS_I_B, meas[1]);
        m.u_dc = (uint16_t)RAW(u, BN_S_PS_U_DC, meas[3]);
        m.status = (uint8_t)RAW(u, BN_S_PS_STATUS, status);
        m.step = (uint16_t)RAW(u, BN_S_PS_STEP, (double)(k % u->m_samples));
        memset(f, 0, sizeof *f);
        bench_dbc_phase_samples_pack(f->data, &m, sizeof f->data);
        bench_e2e_protect(BENCH_E2E_PHASE_SAMPLES_DATA_ID, f->data, BENCH_DBC_PHASE_SAMPLES_LENGTH,
                          BENCH_E2E_PHASE_SAMPLES_CRC_INDEX);
        put(u, f, BENCH_DBC_PHASE_SAMPLES_FRAME_ID, BENCH_DBC_PHASE_SAMPLES_LENGTH, 0);
    }
    if (u->encoder_every && k % u->encoder_every == 0) {
        struct bench_dbc_position_sensor_t m;
        bn_frame_t *f = &u->out[n++];
        double th = plant_encoder_angle(pl->x.th_m, pl->x.w_m, u->encoder_delay_s,
                                        (long)u->encoder_counts);
        bench_dbc_position_sensor_init(&m);
        m.theta_m = (uint16_t)RAW(u, BN_S_POS_THETA_M, th);
        m.step = (uint16_t)RAW(u, BN_S_POS_STEP, (double)(k % u->m_samples));
        memset(f, 0, sizeof *f);
        bench_dbc_position_sensor_pack(f->data, &m, sizeof f->data);
        bench_e2e_protect(BENCH_E2E_POSITION_SENSOR_DATA_ID, f->data,
                          BENCH_DBC_POSITION_SENSOR_LENGTH, BENCH_E2E_POSITION_SENSOR_CRC_INDEX);
        put(u, f, BENCH_DBC_POSITION_SENSOR_FRAME_ID, BENCH_DBC_POSITION_SENSOR_LENGTH, 1);
    }
    if (k % u->truth_every == 0) { /* Plant.truth */
        struct bench_dbc_plant_truth_t m;
        bn_frame_t *f = &u->out[n++];
        double w_m = pl->x.w_m;
        double tau_e = plant_machine_torque(&pl->m, pl->x.i_d, pl->x.i_q);
        double tau_l = pl->imposed ? tau_e - pl->m.b * w_m : pl->tau_const;
        bench_dbc_plant_truth_init(&m);
        m.theta_e = (uint16_t)RAW(u, BN_S_TR_THETA_E, py_mod(pl->m.n_p * pl->x.th_m, TWO_PI));
        m.w_m = (int16_t)RAW(u, BN_S_TR_W_M, w_m);
        m.tau_e = (int16_t)RAW(u, BN_S_TR_TAU_E, tau_e);
        m.tau_l = (int16_t)RAW(u, BN_S_TR_TAU_L, tau_l);
        m.duty_age = (uint8_t)RAW(u, BN_S_TR_DUTY_AGE, u->duty_age);
        m.step = (uint32_t)RAW(u, BN_S_TR_STEP, (double)(k % u->m_truth));
        m.run_id = (uint16_t)RAW(u, BN_S_TR_RUN_ID, u->run_id);
        memset(f, 0, sizeof *f);
        bench_dbc_plant_truth_pack(f->data, &m, sizeof f->data);
        bench_e2e_protect(BENCH_E2E_PLANT_TRUTH_DATA_ID, f->data, BENCH_DBC_PLANT_TRUTH_LENGTH,
                          BENCH_E2E_PLANT_TRUTH_CRC_INDEX);
        put(u, f, BENCH_DBC_PLANT_TRUTH_FRAME_ID, BENCH_DBC_PLANT_TRUTH_LENGTH, 2);
    }
    if (u->faults.on && k % u->truth_every == 0) { /* the true phase currents (DBC 2.4) */
        struct bench_dbc_plant_currents_t m;
        bn_frame_t *f = &u->out[n++];
        double it[3];
        plant_currents(pl, it);
        bench_dbc_plant_currents_init(&m);
        m.i_a = (int16_t)RAW(u, BN_S_PC_I_A, it[0]);
        m.i_b = (int16_t)RAW(u, BN_S_PC_I_B, it[1]);
        m.step = (uint32_t)RAW(u, BN_S_PC_STEP, (double)(k % u->m_truth));
        m.run_id = (uint16_t)RAW(u, BN_S_PC_RUN_ID, u->run_id);
        memset(f, 0, sizeof *f);
        bench_dbc_plant_currents_pack(f->data, &m, sizeof f->data);
        bench_e2e_protect(BENCH_E2E_PLANT_CURRENTS_DATA_ID, f->data,
                          BENCH_DBC_PLANT_CURRENTS_LENGTH, BENCH_E2E_PLANT_CURRENTS_CRC_INDEX);
        put(u, f, BENCH_DBC_PLANT_CURRENTS_FRAME_ID, BENCH_DBC_PLANT_CURRENTS_LENGTH, 4);
    }
    if (u->faults.on) { /* PlantNode.frames_now's filter and babble */
        bn_plant_faults_t *F = &u->faults;
        int ps = sends(u, 0, k), pos = sends(u, 1, k), kept = first;
        for (int j = first; j < n; j++) {
            uint32_t id = u->out[j].id;
            if (id == BENCH_DBC_PHASE_SAMPLES_FRAME_ID && !ps) {
                /* lockstep: sent again, in order, with the next that gets through */
                if (!u->realtime && F->withheld != NULL && F->wh_n < F->wh_cap)
                    F->withheld[F->wh_n++] = u->out[j];
                continue;
            }
            if (id == BENCH_DBC_POSITION_SENSOR_FRAME_ID && !pos) continue;
            u->out[kept++] = u->out[j];
        }
        n = kept;
        if (ps && F->wh_sent < F->wh_n) { /* the withheld samples go first */
            F->out_wh[0] = F->wh_sent;
            F->out_wh[1] = F->wh_n;
            F->out_wh_at = first;
            F->wh_sent = F->wh_n;
        }
        while (F->next_babble < F->n_babble && F->babble[F->next_babble].k < k) F->next_babble++;
        if (F->next_babble < F->n_babble && F->babble[F->next_babble].k == k) {
            const bn_plant_babble_t *b = &F->babble[F->next_babble++];
            F->babbled += 2;
            bn_plant_on_duty(u, &b->to_plant);
            u->out[n++] = b->to_ctrl;
        }
    }
    u->n_out = n;
    /* PlantNode.sent: this instant's frames (the outbox is not retransmitted) */
    int64_t s = u->sent_head % BN_PLANT_SENT;
    u->faults.sent_wh[s][0] = u->faults.out_wh[0];
    u->faults.sent_wh[s][1] = u->faults.out_wh[1];
    u->n_sent[s] = n - first;
    memcpy(u->sent[s], &u->out[first], (size_t)(n - first) * sizeof(bn_frame_t));
    u->sent_head++;
}

void bn_plant_frames_now(bn_plant_t *u) { frames_now(u, NULL); }

int bn_plant_ready(const bn_plant_t *u)
{
    int64_t t = u->k - u->delay;
    /* a dropped duty is not waited for, but a controller under test's arrival is
     * (PlantNode.ready) */
    return t <= 0 || has_duty(u, t) ||
           (duty_fate(u, u->k) != BN_FATE_NONE && (!u->external || u->dropped_upto >= t)) ||
           answer_lost(u, t);
}

int bn_plant_paced(const bn_plant_t *u) { return u->pace_every <= 0 || u->k < u->cmd_horizon; }

int bn_plant_acked(const bn_plant_t *u)
{
    if (u->ctrl_ack < 0 || u->realtime || !u->external) return 1;
    int need = u->applied_seq;
    for (int j = 0; j < u->n_cmds; j++)
        if (u->cmds[j].step == u->k + 1) need = u->cmds[j].seq;
    return need < 0 || ((u->ctrl_ack - need) % 16 + 16) % 16 < 8; /* seq_at_least */
}

/* PlantNode.apply_commands with CommandQueue.due */
void bn_plant_apply_commands(bn_plant_t *u)
{
    int64_t k = u->k;
    if (k > u->applied_upto) u->applied_upto = k;
    int kept = 0;
    for (int j = 0; j < u->n_cmds; j++) { /* the list is in step order */
        bn_plant_cmd_t c = u->cmds[j];
        if (c.step > k) {
            u->cmds[kept++] = c;
            continue;
        }
        u->applied_seq = c.seq;
        if (c.cmd == BENCH_DBC_BENCH_COMMAND_CMD_START_CHOICE) {
            u->started = 1;
            u->last_duty_k = k;
        } else if (c.cmd == BENCH_DBC_BENCH_COMMAND_CMD_STOP_CHOICE) {
            u->stopped = 1;
        } else if (c.cmd == BENCH_DBC_BENCH_COMMAND_CMD_RESET_CHOICE ||
                   c.cmd == BENCH_DBC_BENCH_COMMAND_CMD_ENABLE_CHOICE) {
            reset_fault(u);
        }
        u->pl->load_const = 1; /* plant.set_load(ConstantLoad(c.load_nm)) */
        u->pl->tau_const = c.load_nm;
        u->load_changed = 1;
    }
    u->n_cmds = kept;
}

static void step_plant(bn_plant_t *u, double d_a, double d_b, double d_c, int en)
{
    plant *pl = u->pl;
    double t0 = (double)u->k * pl->T_s; /* Plant.step */
    if (en)
        plant_step(pl, d_a, d_b, d_c, t0);
    else
        plant_step_off(pl, t0);
    u->k++;
    if (pl->t_meas > 0.0) u->meas_k = u->k;
    double i[3];
    int have_i = 0; /* the currents of the state after the step, for the frames too */
    if (u->has_prot && u->fault == PLANT_FAULT_NONE) { /* PlantNode._check_protection */
        plant_currents(pl, i);
        have_i = 1;
        int code = plant_protection_check(&u->prot, i[0], i[1], i[2], pl->u_dc, pl->x.w_m);
        if (code != PLANT_FAULT_NONE) trip(u, code);
    }
    bn_plant_apply_commands(u);
    /* PlantNode._periodic_status */
    if (u->status_every && u->started && !u->stopped && u->k % u->status_every == 0)
        queue_status(u,
                     u->fault != PLANT_FAULT_NONE ? BENCH_DBC_PLANT_STATUS_STATE_FAULT_CHOICE
                                                  : BENCH_DBC_PLANT_STATUS_STATE_RUNNING_CHOICE,
                     u->fault);
    frames_now(u, have_i ? i : NULL);
}

static int64_t clamp_age(int64_t a) { return a < 0 ? 0 : (a > 254 ? 254 : a); }

/* NodeFaults.keep and delayed: the duty period k applies instead of duty t (in d, en) */
static void delayed(bn_plant_t *u, int64_t k, int64_t t, double d[3], int *en)
{
    bn_plant_faults_t *F = &u->faults;
    bn_plant_duty_t *h = &F->history[t % BN_PLANT_HISTORY];
    memcpy(h->d, d, sizeof h->d);
    h->en = *en;
    h->tag = t;
    int64_t n = duty_shift(u, k, 0);
    if (n == 0) return;
    const bn_plant_duty_t *best = NULL;
    for (int j = 0; j < BN_PLANT_HISTORY; j++) {
        const bn_plant_duty_t *e = &F->history[j];
        if (e->tag >= 0 && e->tag <= t - n && (best == NULL || e->tag > best->tag)) best = e;
    }
    if (best != NULL) {
        memcpy(d, best->d, 3 * sizeof(double));
        *en = best->en;
    } else {
        d[0] = d[1] = d[2] = 0.5;
        *en = 0;
    }
    int64_t age = u->duty_age + n;
    u->duty_age = (int32_t)(age < 254 ? age : 254);
}

/* PlantNode.advance_lockstep */
static void advance_lockstep(bn_plant_t *u)
{
    int64_t k = u->k, t = k - u->delay;
    double d[3] = {0.5, 0.5, 0.5};
    int en = 0;
    if (t <= 0) {
        u->duty_age = 255;
    } else if (!has_duty(u, t)) {
        /* the newest duty before t: a later one may be here already (a controller that
         * answers a resent sample at once is ahead of the plant), never applied early */
        int64_t held_step = u->latest_duty_step;
        if (held_step < t) {
            memcpy(d, u->latest, sizeof d);
            en = u->latest_en;
        } else {
            memcpy(d, u->applied.d, sizeof d);
            en = u->applied.en;
            held_step = u->applied.tag;
        }
        u->duty_age = held_step < 0 ? 255 : (int32_t)clamp_age(k - held_step);
        u->late_duties++;
        if (u->watchdog_periods && u->latest_duty_step >= 0 && u->fault == PLANT_FAULT_NONE &&
            t - u->latest_duty_step >= u->watchdog_periods - 1)
            trip(u, PLANT_FAULT_WATCHDOG);
    } else {
        bn_plant_duty_t *slot = &u->duties[t & (BN_PLANT_RING - 1)];
        u->duty_age = (int32_t)(k - t < 254 ? k - t : 254);
        memcpy(d, slot->d, sizeof d);
        en = slot->en;
        u->applied = *slot;
        /* every duty up to t is used up (tag 0..t: -1); t > 0 here, so one unsigned
         * comparison is both bounds, and the loop has no branch to mispredict */
        for (int j = 0; j < BN_PLANT_RING; j++) {
            int64_t tag = u->duties[j].tag;
            u->duties[j].tag = (uint64_t)tag <= (uint64_t)t ? -1 : tag;
        }
        if (u->faults.shift_ls != NULL) delayed(u, k, t, d, &en);
    }
    if (u->fault != PLANT_FAULT_NONE) {
        en = 0;
        u->duty_age = 255;
    }
    u->rounds_waiting = 0;
    step_plant(u, d[0], d[1], d[2], en);
}

/* PlantNode.advance_realtime */
static void advance_realtime(bn_plant_t *u)
{
    int64_t k = u->k, best = -1, due = k - duty_shift(u, k, 1), now = 0;
    int have_now = 0;
    for (int j = 0; j < BN_PLANT_RING; j++) {
        int64_t tag = u->duties[j].tag;
        if (tag < 0 || tag > due || tag <= best) continue;
        int64_t at = u->faults.released[j];
        if (at != INT64_MIN) { /* held by a delay in us: due once released by now */
            if (!have_now) {
                now = clock_now(u);
                have_now = 1;
            }
            if (at > now) continue;
        }
        best = tag;
    }
    if (best >= 0) {
        bn_plant_duty_t *slot = &u->duties[best & (BN_PLANT_RING - 1)];
        u->latest_duty_step = best;
        memcpy(u->latest, slot->d, sizeof u->latest);
        u->latest_en = slot->en;
        /* an older one still held: passed */
        for (int j = 0; j < BN_PLANT_RING; j++)
            if (u->duties[j].tag >= 0 && u->duties[j].tag <= best) u->duties[j].tag = -1;
    }
    double d[3];
    memcpy(d, u->latest, sizeof d);
    int en = u->latest_en;
    u->duty_age = u->latest_duty_step < 0 ? 255 : (int32_t)clamp_age(k - u->latest_duty_step);
    if (u->latest_duty_step < k - u->delay) {
        if (u->latest_duty_step < 0)
            en = 0;
        else
            u->late_duties++;
    }
    if (u->watchdog_periods && u->latest_duty_step >= 0 && u->fault == PLANT_FAULT_NONE &&
        k - u->last_duty_k >= u->watchdog_periods)
        trip(u, PLANT_FAULT_WATCHDOG);
    if (u->fault != PLANT_FAULT_NONE) {
        en = 0;
        u->duty_age = 255;
    }
    step_plant(u, d[0], d[1], d[2], en);
}

void bn_plant_advance(bn_plant_t *u)
{
    if (u->realtime)
        advance_realtime(u);
    else
        advance_lockstep(u);
}

/* PlantNode.on_duty_timeout: the frames to send are the outbox (u->out) */
void bn_plant_duty_timeout(bn_plant_t *u)
{
    u->n_out = 0;
    u->faults.out_wh[0] = u->faults.out_wh[1] = 0;
    if (u->external && !u->dut_answered) goto flush;
    u->rounds_waiting++;
    if (u->watchdog_rounds && u->started && u->latest_duty_step >= 0 &&
        u->fault == PLANT_FAULT_NONE && u->rounds_waiting >= u->watchdog_rounds)
        trip(u, PLANT_FAULT_WATCHDOG);
flush:
    for (int b = 0; b < u->n_outbox; b++) u->out[u->n_out++] = u->outbox[b];
    u->n_outbox = 0;
}
