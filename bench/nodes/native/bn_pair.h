/* The in-process native pair: the plant unit (bn_plant.h) and the controller unit
 * (bn_ctl.h) stepped together in one call, frames passed in memory.
 *
 * bench.nodes._loops.run_inprocess, period for period: the plant's frames of the
 * instant are recorded and handed to the controller unit, its answers recorded
 * and the duties handed to the plant unit, then the plant advances (lockstep).
 * Every frame goes into the caller's record buffer in the order run_inprocess
 * lists them (the plant's frames of an instant, then the controller's answers).
 * The call returns to Python only for what C does not know or keep:
 *
 *   BN_PAIR_FEED   the plant reached the step at which run_inprocess hands the
 *                  nodes the next bench command (feed_step); Python feeds it to
 *                  both nodes' command queues, hands them back, and calls again
 *   BN_PAIR_DUE    the controller has a command due (bn_ctl's BN_CTL_EV_DUE)
 *   BN_PAIR_CMDS   the plant's pending list handed over is used up
 *   BN_PAIR_FULL   the record buffer is full: Python takes the frames, calls again
 *   BN_PAIR_STALL  the plant has no duty for its period (run_inprocess raises)
 *   BN_PAIR_ERROR  the controller core's step failed (ctl->error)
 *   BN_PAIR_DONE   the run's steps are done, or a stop command ran
 *
 * The latency model (bench.nodes._link.LockstepLink) is not here: a scenario
 * with lockstep latency runs in Python (the caller's fallback).  No allocation.
 */
#ifndef BN_PAIR_H
#define BN_PAIR_H

#include <stdint.h>

#include "bn.h"
#include "bn_ctl.h"
#include "bn_plant.h"

#ifdef __cplusplus
extern "C" {
#endif

enum {
    BN_PAIR_DONE = 0,
    BN_PAIR_FEED = 1,
    BN_PAIR_DUE = 2,
    BN_PAIR_CMDS = 3,
    BN_PAIR_FULL = 4,
    BN_PAIR_STALL = 5,
    BN_PAIR_ERROR = 6
};

/* answers of the controller to one instant's frames, at most (2 per sample) */
#define BN_PAIR_REPLIES 16

typedef struct {
    bn_plant_t *p;
    bn_ctl_t *c;
    int64_t lead;       /* run_inprocess's INPROCESS_LEAD */
    int64_t feed_step;  /* step of the next command to feed (INT64_MAX: none) */
    bn_frame_t *rec;    /* caller's buffer: every frame, in wire order */
    uint64_t rec_cap, n_rec;
    uint64_t steps;     /* periods advanced by the pair */
    int32_t timed;      /* 1: add each unit's time to plant_ns and ctl_ns (bench perf) */
    int32_t pad0;
    int64_t plant_ns;   /* in the plant unit: advance (model step, commands) and frames encoded */
    int64_t ctl_ns;     /* in the controller unit: frames decoded, core step, frames encoded */
    /* state kept across returns */
    int32_t phase;      /* 0: frames of the instant not made; 1: handing them over; 2: advance */
    int32_t j;          /* next frame of p->out for the controller */
    int32_t n_replies;
    int32_t pad;
    bn_frame_t replies[BN_PAIR_REPLIES];
} bn_pair_t;

size_t bn_pair_sizeof(void);

/* Run until an event (BN_PAIR_*); call again after Python handled it. */
int bn_pair_run(bn_pair_t *P);

#ifdef __cplusplus
}
#endif

#endif /* BN_PAIR_H */
