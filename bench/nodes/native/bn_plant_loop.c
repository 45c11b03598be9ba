/* The plant node's loop on a bus (bn_plant.h): bench.nodes._loops._serve_lockstep
 * and _serve_realtime around the unit of bn_plant.c, without Python.  It
 * returns to Python only on an event (BN_EV_*) and is re-entered after it:
 * its state is in bn_plant_loop_t. */
#include <errno.h>
#include <string.h>
#include <time.h>

#include "bn_plant.h"

void bn_plant_send(bn_plant_t *u, bn_bus_t *bus, const bn_frame_t *f)
{
    for (int attempt = 0; attempt < 5; attempt++) { /* bench.nodes._send.SEND_ATTEMPTS */
        if (bn_send(bus, f) == 0) return;
        u->send_errors++;
        if (attempt == 4) {
            u->frames_lost_on_send++;
        } else {
            struct timespec ts = {0, 500000L * (attempt + 1)};
            nanosleep(&ts, NULL);
        }
    }
}

/* Frames f[0, n): one sendmmsg; what it did not take, one by one with retries. */
static void send_frames(bn_plant_loop_t *L, const bn_frame_t *f, int64_t n)
{
    while (n > 0) {
        int m = (int)(n < BN_BATCH ? n : BN_BATCH);
        int j = bn_send_many(L->bus, f, m);
        if (j < 0) j = 0;
        for (; j < m; j++) bn_plant_send(L->u, L->bus, &f[j]);
        f += m;
        n -= m;
    }
}

/* The instant's frames, with the lockstep samples withheld by a fault first (out_wh). */
static void send_out(bn_plant_loop_t *L)
{
    bn_plant_t *u = L->u;
    bn_plant_faults_t *F = &u->faults;
    int64_t wn = F->out_wh[1] - F->out_wh[0];
    int at = wn > 0 ? F->out_wh_at : u->n_out;
    send_frames(L, u->out, at);
    if (wn > 0) send_frames(L, &F->withheld[F->out_wh[0]], wn);
    send_frames(L, &u->out[at], u->n_out - at);
    u->n_out = 0;
    F->out_wh[0] = F->out_wh[1] = 0;
}

/* PlantNode.retransmit */
static void retransmit(bn_plant_loop_t *L)
{
    bn_plant_t *u = L->u;
    int64_t keep = u->delay + 3, n = u->sent_head < keep ? u->sent_head : keep;
    u->retransmits++;
    for (int64_t p = u->sent_head - n; p < u->sent_head; p++) {
        int64_t s = p % BN_PLANT_SENT;
        const int64_t *w = u->faults.sent_wh[s]; /* withheld samples sent with it, first */
        for (int64_t j = w[0]; j < w[1]; j++) bn_plant_send(u, L->bus, &u->faults.withheld[j]);
        for (int j = 0; j < u->n_sent[s]; j++) bn_plant_send(u, L->bus, &u->sent[s][j]);
    }
}

static int done(const bn_plant_t *u) { return u->stopped || (u->n_steps > 0 && u->k >= u->n_steps); }

/* A received frame: 1 when it is an event for Python (in L->ev_frame). */
static int take(bn_plant_loop_t *L, const bn_frame_t *f)
{
    if (f->flags & BN_EXT) return 0;
    if (f->id == L->ids[0]) {
        bn_plant_on_duty(L->u, f);
        return 0;
    }
    if (bn_cmd_seen_copy(&L->cmd_seen, f, L->u->k)) return 0; /* a command's copy (bn.h) */
    for (int j = 0; j < 4; j++) {
        if (L->event_ids[j] && f->id == L->event_ids[j]) {
            L->ev_frame = *f;
            return 1;
        }
    }
    return 0;
}

static int64_t ns(double s) { return (int64_t)(s * 1e9); }

/* Real time: the oldest held frame that is no copy of a command Python took since it
 * was held (bn.h, bn_cmd_seen_t: dropped and counted) into ev_frame: 1; 0: none left. */
static int unhold(bn_plant_loop_t *L)
{
    while (L->held.n > 0) {
        bn_held_take(&L->held, &L->ev_frame);
        if (!bn_cmd_seen_copy(&L->cmd_seen, &L->ev_frame, L->u->k)) return 1;
    }
    return 0;
}

static int loop_lockstep(bn_plant_loop_t *L)
{
    bn_plant_t *u = L->u;
    bn_frame_t f;
    int64_t rt = ns(L->retransmit_s);
    for (;;) {
        if (done(u)) {
            /* bench.nodes._loops._last_answer: a controller under test may have lost
             * the last sample; resend until its answer came, or a while (also after a
             * stop command: the bench's last command stops the run at its last step) */
            if (!u->external || L->last_phase == 2) return BN_EV_DONE;
            int64_t now = bn_now_ns();
            if (L->last_phase == 0) {
                L->last_phase = 1;
                L->t_last_end = now + ns(L->last_answer_s);
                L->t_quiet = now;
            }
            if (bn_plant_has_duty(u, u->k + 1 - u->delay) || now > L->t_last_end) {
                L->last_phase = 2;
                return BN_EV_DONE;
            }
            int64_t until = L->t_quiet + rt < L->t_last_end ? L->t_quiet + rt : L->t_last_end;
            int r = bn_recv_until(L->bus, &f, until);
            if (r < 0) {
                L->err = r;
                return BN_EV_ERROR;
            }
            if (r > 0 && take(L, &f)) return BN_EV_FRAME;
            if (bn_now_ns() - L->t_quiet >= rt) {
                retransmit(L);
                L->t_quiet = bn_now_ns();
            }
            continue;
        }
        if (u->n_cmds == 0 && u->cmds_more) return BN_EV_CMDS;
        int what = !bn_plant_ready(u)    ? BN_WAIT_DUTY
                   : !bn_plant_paced(u)  ? BN_WAIT_COMMAND
                   : !bn_plant_acked(u)  ? BN_WAIT_ACK
                                         : 0;
        int64_t now = bn_now_ns();
        if (what == 0) {
            bn_plant_advance(u);
            send_out(L);
            L->t_progress = L->t_quiet = bn_now_ns();
            continue;
        }
        double limit = what == BN_WAIT_DUTY && L->first_s > 0 && !u->dut_answered ? L->first_s
                                                                                   : L->stall_s;
        if (now - L->t_progress > ns(limit)) {
            L->stall_what = what;
            return BN_EV_STALL;
        }
        int64_t until = L->t_quiet + rt < L->t_poll ? L->t_quiet + rt : L->t_poll;
        int r = bn_recv_until(L->bus, &f, until);
        if (r < 0) {
            L->err = r;
            return BN_EV_ERROR;
        }
        now = bn_now_ns();
        if (r > 0 && take(L, &f)) return BN_EV_FRAME;
        if (now - L->t_quiet >= rt) {
            if (what == BN_WAIT_DUTY) { /* _serve_lockstep's no_duty */
                bn_plant_duty_timeout(u);
                send_out(L);
                if (u->external && u->fault == PLANT_FAULT_WATCHDOG) return BN_EV_TRIPPED;
                retransmit(L);
            } else if (what == BN_WAIT_ACK) {
                retransmit(L);
            }
            L->t_quiet = now;
        }
        if (now >= L->t_poll) {
            L->t_poll = now + ns(L->poll_s);
            return BN_EV_POLL;
        }
    }
}

/* Real time with a controller under test (bench.nodes._loops._wait_first_answer):
 * sample 0 (in u->out) is sent every retransmit_s until the controller's first
 * valid duty; the clock starts after it, with sample 0 already out.  0: answered. */
static int first_answer(bn_plant_loop_t *L)
{
    bn_plant_t *u = L->u;
    bn_frame_t f;
    int64_t rt = ns(L->retransmit_s);
    while (!u->dut_answered) {
        int64_t now = bn_now_ns();
        if (now - L->t_progress > ns(L->first_s)) {
            L->stall_what = BN_WAIT_DUTY;
            return BN_EV_STALL;
        }
        if (L->t_first_sent == 0 || now - L->t_first_sent >= rt) {
            for (int j = 0; j < u->n_out; j++) bn_plant_send(u, L->bus, &u->out[j]);
            L->t_first_sent = now;
        }
        if (now >= L->t_poll) {
            L->t_poll = now + ns(L->poll_s);
            return BN_EV_POLL;
        }
        int64_t until = L->t_first_sent + rt < L->t_poll ? L->t_first_sent + rt : L->t_poll;
        int r = bn_recv_until(L->bus, &f, until);
        if (r < 0) {
            L->err = r;
            return BN_EV_ERROR;
        }
        if (r > 0 && take(L, &f)) return BN_EV_FRAME;
    }
    u->n_out = 0; /* sample 0 is out; the clock starts with period 0 */
    return 0;
}

static int loop_realtime(bn_plant_loop_t *L)
{
    bn_plant_t *u = L->u;
    bn_frame_t f;
    if (!L->rt_started && u->external) {
        int ev = first_answer(L);
        if (ev != 0) return ev;
    }
    if (!L->rt_started) {
        bn_clock_init(&L->clock, L->period_ns, L->busy_tail_ns, L->stall_ns, L->busy,
                      (size_t)L->busy_cap);
        bn_clock_start(&L->clock);
        L->rt_started = 1;
        L->phase = 1;
    }
    for (;;) {
        int64_t t0 = bn_now_ns(), t1;
        if (L->phase == 1) {
            send_out(L); /* this instant's frames leave at its deadline */
            t1 = bn_now_ns();
            L->part_ns[BN_PART_SEND] += t1 - t0;
            t0 = t1;
            L->phase = done(u) ? 4 : 2;
        }
        if (L->phase == 4) { /* done: the frames still held go to Python first */
            if (unhold(L)) return BN_EV_FRAME;
            u->overruns = L->clock.st.missed;
            return BN_EV_DONE;
        }
        if (L->phase == 2) {
            /* A command frame is held, not handed to Python here: the step and the next
             * send would wait on Python's handling.  It goes to Python after the step
             * (below), so one that arrives for the present step is applied a period
             * later (counted as a late command); the bench sends them 0.5 s ahead. */
            for (;;) {
                int r = bn_recv_until(L->bus, &f, 0);
                if (r < 0) {
                    L->err = r;
                    return BN_EV_ERROR;
                }
                if (r == 0) break;
                if (take(L, &f) && bn_held_put(&L->held, &f, &L->ev_frame) &&
                    !bn_cmd_seen_copy(&L->cmd_seen, &L->ev_frame, u->k)) {
                    L->part_ns[BN_PART_RECV] += bn_now_ns() - t0; /* full: the oldest now */
                    return BN_EV_FRAME;
                }
            }
            t1 = bn_now_ns();
            L->part_ns[BN_PART_RECV] += t1 - t0;
            t0 = t1;
            if (u->n_cmds == 0 && u->cmds_more) return BN_EV_CMDS;
            bn_plant_advance(u);
            t1 = bn_now_ns();
            L->part_ns[BN_PART_STEP] += t1 - t0;
            L->phase = 3;
            /* Python's poll in the slack of a period whose work is done, not at the start
             * of the next one: a poll at the wake-up made the period it delayed late */
            if (t1 >= L->t_poll) {
                L->t_poll = t1 + ns(L->poll_s);
                return BN_EV_POLL;
            }
        }
        /* phase 3: the period's work is done; a held frame goes to Python while its
         * handling ends before the deadline */
        if (L->held.n > 0 && bn_clock_deadline(&L->clock) - bn_now_ns() > L->held_margin_ns &&
            unhold(L))
            return BN_EV_FRAME;
        uint64_t p = L->clock.st.periods;
        if (L->parts != NULL && p < L->busy_cap) {
            for (int j = 0; j < 3; j++) {
                int64_t v = L->part_ns[j];
                L->parts[(uint64_t)j * L->busy_cap + p] =
                    (uint32_t)(v > (int64_t)UINT32_MAX ? UINT32_MAX : v);
            }
        }
        L->part_ns[0] = L->part_ns[1] = L->part_ns[2] = 0;
        int64_t late = bn_clock_wait(&L->clock);
        if (L->late != NULL && L->n_late < L->late_cap)
            L->late[L->n_late++] = (uint32_t)(late > (int64_t)UINT32_MAX ? UINT32_MAX : late);
        L->phase = 1;
    }
}

int bn_plant_loop(bn_plant_loop_t *L)
{
    bn_plant_t *u = L->u;
    if (L->phase == 0) {
        L->t_progress = L->t_quiet = bn_now_ns();
        L->t_poll = L->t_progress + ns(L->poll_s);
        bn_plant_frames_now(u);
        if (!u->realtime) {
            send_out(L);
            L->phase = 1;
        }
    }
    return u->realtime ? loop_realtime(L) : loop_lockstep(L);
}
