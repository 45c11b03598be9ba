/* The in-process native pair: the plant unit (bn_plant.h) and the controller unit
 * (bn_ctl.h) stepped together in one call, frames passed in memory.
 *
 * bench.nodes._loops.run_inprocess, period for period: the plant's frames of the
 * instant are recorded and handed to the controller unit, its answers recorded
 * and the duties handed to the plant unit, then the bench commands of the
 * schedule that are due to be fed are fed, then the plant advances (lockstep).
 * Every frame goes into the caller's record buffer in the order run_inprocess
 * lists them (the plant's frames of an instant, the controller's answers, the
 * commands fed).
 *
 * The bench commands are known before the run: Python hands the whole schedule
 * over once (bn_pair_cmd_t, in feed order: first, as fed already, the commands
 * the nodes hold at the start), each entry with what the nodes'
 * CommandQueue.add made of it when Python ran the nodes' own rules on it for the
 * plant step at which it is fed (bench/nodes/native/_pair.py).  Feeding one here
 * records its frame and puts its entries into the plant's and the controller's
 * pending lists (in step order); each unit applies them at their step
 * (bn_plant_apply_commands, bn_ctl_apply_commands).  A command fed while a list
 * is full waits, and joins it as the list empties: the list holds the earliest
 * pending commands, so it holds every command due as long as no more than its
 * length come due at one step (a schedule in step order: _pair.py checks).
 * The call returns to Python only for:
 *
 *   BN_PAIR_FULL   the record buffer is full: Python takes the frames, calls again
 *   BN_PAIR_CMDS   a pending list ran dry with commands waiting (not in a run
 *                  _pair.py lets run: a bug, Python raises)
 *   BN_PAIR_STALL  the plant has no duty for its period (run_inprocess raises)
 *   BN_PAIR_ERROR  the controller unit failed (ctl->error), or it is not at the
 *                  plant's step when a command is fed (a bug: Python raises)
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
    BN_PAIR_CMDS = 3,
    BN_PAIR_FULL = 4,
    BN_PAIR_STALL = 5,
    BN_PAIR_ERROR = 6
};

/* answers of the controller to one instant's frames, at most (2 per sample) */
#define BN_PAIR_REPLIES 16

/* one bench command of the schedule: fed after the answers of plant step feed_k */
typedef struct {
    int64_t feed_k;
    bn_frame_t frame;      /* recorded when fed */
    /* the plant's queue: accepted at p_step (-1: not queued); its cmd_horizon after */
    int64_t p_step, p_horizon;
    int32_t p_cmd, p_seq;
    double p_load_nm;
    /* the controller's queue: accepted at c_step (-1: not queued); ack_seq after */
    int64_t c_step;
    int32_t c_cmd, c_seq;
    double c_speed_ref_rpm;
    int32_t c_ack_seq, pad;
} bn_pair_cmd_t;

typedef struct {
    bn_plant_t *p;
    bn_ctl_t *c;
    const bn_pair_cmd_t *sched; /* the bench commands, in feed order */
    int64_t n_sched;
    int64_t n_fed;      /* commands of sched fed so far */
    int64_t p_next, c_next; /* the first fed command not yet in the plant's, the
                               controller's pending list (a list full: it waits) */
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
size_t bn_pair_cmd_sizeof(void);

/* Run until an event (BN_PAIR_*); call again after Python handled it. */
int bn_pair_run(bn_pair_t *P);

#ifdef __cplusplus
}
#endif

#endif /* BN_PAIR_H */
