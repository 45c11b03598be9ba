/* The in-process native pair (bn_pair.h): run_inprocess's loop on the two units. */
#include "bn_pair.h"

#include <string.h>

#include "bench_dbc.h"

size_t bn_pair_sizeof(void) { return sizeof(bn_pair_t); }

/* the controller's answers: kept until the instant's frames are all handed over */
static int reply_sink(void *ctx, const bn_frame_t *f)
{
    bn_pair_t *P = (bn_pair_t *)ctx;
    if (P->n_replies >= BN_PAIR_REPLIES) return -1; /* counted as lost on send */
    P->replies[P->n_replies++] = *f;
    return 0;
}

static int done(const bn_plant_t *u) { return u->stopped || (u->n_steps > 0 && u->k >= u->n_steps); }

int bn_pair_run(bn_pair_t *P)
{
    bn_plant_t *u = P->p;
    bn_ctl_t *c = P->c;
    if (P->phase == 1 && P->j > 0) {
        /* back from an event of the controller: its commands were applied */
        int ev = bn_ctl_resume(c, reply_sink, P);
        if (ev == BN_CTL_EV_DUE) return BN_PAIR_DUE;
        if (ev != BN_CTL_EV_NONE) return BN_PAIR_ERROR;
    }
    for (;;) {
        if (P->phase == 0 || P->phase == 2) {
            /* room for one instant's frames and their answers */
            if (P->rec_cap - P->n_rec < (uint64_t)(BN_PLANT_OUT + BN_PAIR_REPLIES))
                return BN_PAIR_FULL;
            int64_t t0 = P->timed ? bn_now_ns() : 0;
            if (P->phase == 0) {
                bn_plant_frames_now(u);
            } else {
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
            int ev = bn_ctl_on_frame(c, &u->out[P->j++], reply_sink, P);
            if (P->timed) P->ctl_ns += bn_now_ns() - t0;
            if (ev == BN_CTL_EV_DUE) return BN_PAIR_DUE;
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
        if (u->k + P->lead >= P->feed_step) return BN_PAIR_FEED;
    }
}
