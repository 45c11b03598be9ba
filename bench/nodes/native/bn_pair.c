/* The in-process native pair (bn_pair.h): run_inprocess's loop on the two units. */
#include "bn_pair.h"

#include <string.h>

#include "bench_dbc.h"

size_t bn_pair_sizeof(void) { return sizeof(bn_pair_t); }
size_t bn_pair_cmd_sizeof(void) { return sizeof(bn_pair_cmd_t); }

/* the controller's answers: kept until the instant's frames are all handed over */
static int reply_sink(void *ctx, const bn_frame_t *f)
{
    bn_pair_t *P = (bn_pair_t *)ctx;
    if (P->n_replies >= BN_PAIR_REPLIES) return -1; /* counted as lost on send */
    P->replies[P->n_replies++] = *f;
    return 0;
}

static int done(const bn_plant_t *u) { return u->stopped || (u->n_steps > 0 && u->k >= u->n_steps); }

/* The fed commands waiting for room, into the plant's and the controller's pending
 * lists (CommandQueue.pending, in step order) */
static void top_up(bn_pair_t *P)
{
    bn_plant_t *u = P->p;
    bn_ctl_t *c = P->c;
    for (; P->p_next < P->n_fed && u->n_cmds < BN_PLANT_CMDS; P->p_next++) {
        const bn_pair_cmd_t *e = &P->sched[P->p_next];
        if (e->p_step < 0) continue;
        int j = u->n_cmds++;
        for (; j > 0 && u->cmds[j - 1].step > e->p_step; j--)
            u->cmds[j] = u->cmds[j - 1];
        u->cmds[j].step = e->p_step;
        u->cmds[j].cmd = e->p_cmd;
        u->cmds[j].seq = e->p_seq;
        u->cmds[j].load_nm = e->p_load_nm;
    }
    for (; P->c_next < P->n_fed && c->n_cmds < BN_CTL_CMDS; P->c_next++) {
        const bn_pair_cmd_t *e = &P->sched[P->c_next];
        if (e->c_step < 0) continue;
        int j = c->n_cmds++;
        for (; j > 0 && c->cmds[j - 1].step > e->c_step; j--)
            c->cmds[j] = c->cmds[j - 1];
        c->cmds[j].step = e->c_step;
        c->cmds[j].cmd = e->c_cmd;
        c->cmds[j].seq = e->c_seq;
        c->cmds[j].speed_ref_rpm = e->c_speed_ref_rpm;
    }
    u->cmds_more = P->p_next < P->n_fed;
    c->cmds_more = P->c_next < P->n_fed;
}

/* The schedule's commands due to be fed at the plant's step: recorded, their
 * acknowledgement and horizon taken, and into the pending lists.  BN_PAIR_DONE
 * when all are fed, or the event that stopped it (nothing of that command done). */
static int feed(bn_pair_t *P)
{
    bn_plant_t *u = P->p;
    bn_ctl_t *c = P->c;
    while (P->n_fed < P->n_sched && P->sched[P->n_fed].feed_k <= u->k) {
        const bn_pair_cmd_t *e = &P->sched[P->n_fed];
        if (P->n_rec >= P->rec_cap) return BN_PAIR_FULL;
        if (c->next_k != u->k + 1) return BN_PAIR_ERROR; /* not where Python ran the rules */
        u->cmd_horizon = e->p_horizon;
        c->ack_seq = e->c_ack_seq;
        P->rec[P->n_rec++] = e->frame;
        P->n_fed++;
    }
    top_up(P);
    return BN_PAIR_DONE;
}

/* a frame to the controller: a list that ran dry is topped up, and the steps resumed */
static int to_ctl(bn_pair_t *P, const bn_frame_t *f)
{
    int ev = bn_ctl_on_frame(P->c, f, reply_sink, P);
    while (ev == BN_CTL_EV_CMDS && P->c_next < P->n_fed) {
        top_up(P);
        ev = bn_ctl_resume(P->c, reply_sink, P);
    }
    return ev;
}

int bn_pair_run(bn_pair_t *P)
{
    bn_plant_t *u = P->p;
    top_up(P);
    for (;;) {
        if (P->phase == 0 || P->phase == 2) {
            if (P->phase == 2) {
                int ev = feed(P);
                if (ev != BN_PAIR_DONE) return ev;
            }
            /* room for one instant's frames and their answers */
            if (P->rec_cap - P->n_rec < (uint64_t)(BN_PLANT_OUT + BN_PAIR_REPLIES))
                return BN_PAIR_FULL;
            int64_t t0 = P->timed ? bn_now_ns() : 0;
            if (P->phase == 0) {
                bn_plant_frames_now(u);
            } else {
                top_up(P); /* the plant's list emptied as it applied them */
                if (u->n_cmds == 0 && u->cmds_more) return BN_PAIR_CMDS;
                bn_plant_advance(u);
                P->steps++;
            }
            if (P->timed) P->plant_ns += bn_now_ns() - t0;
            memcpy(&P->rec[P->n_rec], u->out, (size_t)u->n_out * sizeof(bn_frame_t));
            P->n_rec += (uint64_t)u->n_out;
            P->phase = 1;
            P->j = 0;
            P->n_replies = 0;
        }
        /* phase 1: the instant's frames to the controller */
        while (P->j < u->n_out) {
            int64_t t0 = P->timed ? bn_now_ns() : 0;
            int ev = to_ctl(P, &u->out[P->j++]);
            if (P->timed) P->ctl_ns += bn_now_ns() - t0;
            if (ev == BN_CTL_EV_CMDS) return BN_PAIR_CMDS;
            if (ev != BN_CTL_EV_NONE) return BN_PAIR_ERROR;
        }
        /* its answers: recorded, and the duties to the plant */
        memcpy(&P->rec[P->n_rec], P->replies, (size_t)P->n_replies * sizeof(bn_frame_t));
        P->n_rec += (uint64_t)P->n_replies;
        for (int r = 0; r < P->n_replies; r++)
            if (P->replies[r].id == BENCH_DBC_PWM_DUTY_FRAME_ID && !(P->replies[r].flags & BN_EXT))
                bn_plant_on_duty(u, &P->replies[r]);
        P->n_replies = 0;
        P->j = 0;
        P->phase = 2;
        if (done(u)) return BN_PAIR_DONE;
        if (!bn_plant_ready(u)) return BN_PAIR_STALL;
    }
}
