/* The controller node's per-period logic in C (the native loop of issue 29).
 *
 * What bench/nodes/_controller_node.py's ControllerNode does with a frame,
 * on frames in and frames out, without a transport:
 *
 *   PhaseSamples  length, E2E CRC, DBC ranges; its step unwrapped against the
 *                 next step; a repeat answered from the last 8 answers; one
 *                 further ahead than sample_lead rejected (future_counter); a
 *                 sample from the future held until the missing ones come
 *                 (real time: skip to the newest); steps run strictly in order
 *   PlantTruth    the sensored baseline waits for the truth of the same step
 *   each step     the controller core (cc_foc_step on the cc_foc_t Python
 *                 built, then the supervision cc_sup_after when it is on),
 *                 PwmDuty and CtrlTelemetry packed by the C code `bench
 *                 codegen` writes, with their E2E CRC
 *
 * A BenchCommand frame is Python's (bench/nodes/_counters.py CommandQueue:
 * de-duplication, seq, late commands, one home for those rules): an event the
 * caller hands to Python, which queues it and hands the pending list back
 * (bn_ctl_t.cmds, in step order).  This unit applies the pending commands at
 * their step to the core (bn_ctl_apply_commands: ControllerNode._apply_commands
 * with CommandQueue.due, the rule the native node and the in-process pair
 * share; the Python node keeps its own for the Python loop), with no return to
 * Python; Python takes back what it applied (applied_upto, applied_seq,
 * stopped, faulted) at its next event.  The signals' scale,
 * offset, range and modulus come from the DBC through Python's codec
 * (bn_sig_t, bn.h), so no DBC fact is written here.
 *
 * No allocation: every buffer is in bn_ctl_t.  bn_ctl_serve is the loop on a
 * bn_bus_t; an in-process driver calls bn_ctl_on_frame with its own sink.
 */
#ifndef BN_CTL_H
#define BN_CTL_H

#include <stdint.h>

#include "bn.h"
#include "cc_foc.h"
#include "cc_supervision.h"

#ifdef __cplusplus
extern "C" {
#endif

/* pending samples and truths by step (>= twice the PhaseSamples step range the
 * unwrap spans, 2^10) */
#define BN_CTL_RING 2048
/* answers kept for repeated samples (the Python node's 8) */
#define BN_CTL_ANSWERS 8
/* pending commands handed over at a time (as bn_plant.h's BN_PLANT_CMDS) */
#define BN_CTL_CMDS 256

/* the output signals, in this order in bn_ctl_t.sig */
enum {
    BN_CTL_DUTY_A,
    BN_CTL_DUTY_B,
    BN_CTL_DUTY_C,
    BN_CTL_ENABLE,
    BN_CTL_DUTY_STEP,
    BN_CTL_THETA_HAT,
    BN_CTL_W_HAT,
    BN_CTL_ERR,
    BN_CTL_MODE,
    BN_CTL_TEL_STEP,
    BN_CTL_RUN_ID,
    BN_CTL_ACK_VALID,
    BN_CTL_ACK,
    BN_CTL_NSIG
};

/* bn_ctl_t.sig: one signal's encoding (bn_sig_t, bn.h): clipped to [lo, hi], or
 * with modulus > 0 its raw value taken modulo modulus; raw = (v - offset) / scale
 * rounded half to even, as cantools (the range check is not used here) */

/* rejection reasons (bench/wire/_codec.py, bench/nodes/_counters.py) */
enum {
    BN_CTL_R_BAD_LENGTH,
    BN_CTL_R_DECODE_ERROR,
    BN_CTL_R_BAD_CRC,
    BN_CTL_R_OUT_OF_RANGE,
    BN_CTL_R_STALE,
    BN_CTL_R_FUTURE,
    BN_CTL_R_REPEATED,
    BN_CTL_R_N
};

/* events: why bn_ctl_on_frame, bn_ctl_resume or bn_ctl_serve returned */
enum {
    BN_CTL_EV_NONE = 0,     /* frame handled (on_frame, resume) */
    BN_CTL_EV_COMMAND = 1,  /* a BenchCommand frame (cmd_frame): Python's queue */
    BN_CTL_EV_CMDS = 2,     /* the pending list handed over is used up (cmds_more):
                               Python takes back what was applied, hands more, resumes */
    BN_CTL_EV_STOPPED = 3,  /* stopped was set (a stop command ran) */
    BN_CTL_EV_IDLE = 4,     /* idle_ns without a frame */
    BN_CTL_EV_TIMEOUT = 5,  /* real time: no valid sample for sample_timeout_ns */
    BN_CTL_EV_POLL = 6,     /* return_ns passed, or a signal: Python checks its stop */
    BN_CTL_EV_ERROR = 7     /* error: a cc_foc_step error (< 0) or a bus errno (> 0) */
};

typedef struct {
    uint64_t frames_accepted, frames_unknown;
    uint64_t reasons[BN_CTL_R_N];
    uint64_t samples_accepted, send_errors, frames_lost_on_send, steps;
} bn_ctl_counts_t;

/* one pending command (CommandQueue's Command: apply step, cmd, seq, speed_ref) */
typedef struct {
    int64_t step;
    int32_t cmd, seq;
    double speed_ref_rpm;
} bn_ctl_cmd_t;

typedef struct {
    /* set-up (Python, before the first call) */
    cc_foc_t *foc;
    cc_sup_t *sup; /* NULL: no supervision */
    int32_t needs_truth, realtime;
    double n_p;
    int64_t m_step, m_truth, m_tel; /* step counter ranges (2^bits) */
    /* the most steps a sample / a truth may be ahead of next_k (lockstep with the
     * plan's delay: ControllerNode.sample_lead, truth_lead); -1: the unwrap window
     * (a truth: m_step) */
    int64_t sample_lead, truth_lead;
    bn_sig_t sig[BN_CTL_NSIG];
    uint8_t duty_flags, tel_flags; /* BN_FD, BN_BRS of PwmDuty and CtrlTelemetry */
    uint32_t run_id;               /* the run's nonce (CtrlTelemetry.run_id) */
    double rpm_per_rad_s;  /* bench.wire._protocol.RPM_PER_RAD_S: speed_ref to rad/s */
    /* the commands' state: CommandQueue's, copied here by Python; applied here */
    int32_t ack_seq;       /* CommandQueue.ack_seq (-1: none) */
    int32_t send_ack;      /* set by Python: send the last output's telemetry now */
    int32_t stopped;       /* a stop command ran (here, or set by Python) */
    int32_t faulted;       /* ControllerNode.faulted: cleared by start, enable, reset */
    int32_t n_cmds, cmds_more; /* pending list: its length; 1: Python holds more */
    int32_t applied_seq;   /* CommandQueue.applied_seq */
    int32_t has_w_ref;     /* 1: a command set the speed reference (w_m_ref) */
    int64_t applied_upto;  /* CommandQueue.applied_upto */
    double w_m_ref;        /* the speed reference the newest command set (rad/s) */
    /* loop timing (bn_ctl_serve) */
    int64_t idle_ns, sample_timeout_ns, poll_ns, return_ns;
    /* state */
    int64_t next_k;
    int32_t error;
    int32_t has_last;
    cc_out_t last;
    bn_frame_t cmd_frame;
    bn_ctl_counts_t c;
    bn_ctl_cmd_t cmds[BN_CTL_CMDS]; /* pending, by step */
    /* real time (bn_ctl_serve): command frames met while a sample may wait, held and
     * handed over one per return once a duty is out (slack) or before the first step,
     * or after a poll interval without a sample */
    bn_held_t held;
    int32_t slack;
    /* loop state */
    int64_t t_last, t_sample;
    uint64_t seen;
    /* rings */
    int64_t s_k[BN_CTL_RING], t_k[BN_CTL_RING], a_k[BN_CTL_ANSWERS];
    double s_i_a[BN_CTL_RING], s_i_b[BN_CTL_RING], s_u_dc[BN_CTL_RING];
    double t_theta[BN_CTL_RING], t_w_m[BN_CTL_RING];
    bn_frame_t a_duty[BN_CTL_ANSWERS], a_tel[BN_CTL_ANSWERS];
    /* the bench commands Python took, whose copies bn_ctl_on_frame drops (bn.h) */
    bn_cmd_seen_t cmd_seen;
} bn_ctl_t;

/* where the frames to send go; 0 or -errno */
typedef int (*bn_ctl_sink_t)(void *ctx, const bn_frame_t *f);

/* Empty rings and counters, next step 0 (the set-up fields are kept). */
void bn_ctl_reset(bn_ctl_t *ctl);

/* ControllerNode._apply_commands with CommandQueue.due at step k: the pending
 * commands due at k, in step order, applied to the core (start, enable, reset:
 * enable, faulted cleared; stop, disable: disable, a stop sets stopped; each its
 * speed reference).  BN_CTL_EV_NONE, or BN_CTL_EV_ERROR (ctl->error) when the core
 * refused to enable. */
int bn_ctl_apply_commands(bn_ctl_t *ctl, int64_t k);

/* Take one received frame (PhaseSamples, PlantTruth or BenchCommand); the frames
 * it answers go to sink.  BN_CTL_EV_NONE, or an event for Python. */
int bn_ctl_on_frame(bn_ctl_t *ctl, const bn_frame_t *in, bn_ctl_sink_t sink, void *ctx);

/* After Python handled an event: send the telemetry it asked for (send_ack) and
 * run the steps that are ready.  BN_CTL_EV_NONE, or an event. */
int bn_ctl_resume(bn_ctl_t *ctl, bn_ctl_sink_t sink, void *ctx);

/* The copies of bench commands (bn.h): keep none yet, their id and span; Python took
 * the command frame f (CommandQueue.recent has its key) at step next_k; the copies
 * dropped so far. */
void bn_ctl_cmd_seen_init(bn_ctl_t *ctl, uint32_t id, int64_t span);
void bn_ctl_cmd_taken(bn_ctl_t *ctl, const bn_frame_t *f);
uint64_t bn_ctl_cmd_copies(const bn_ctl_t *ctl);

/* The node's loop on a bus until an event for Python (never BN_CTL_EV_NONE).
 * Call again after handling it; the loop resumes where it stopped. */
int bn_ctl_serve(bn_ctl_t *ctl, bn_bus_t *bus);

/* bn_bus_t for Python (ctypes): open udp_multicast (group, port) or SocketCAN
 * (ifname, CAN FD); its size, so Python can hold one. */
size_t bn_ctl_bus_size(void);
size_t bn_ctl_size(void);
/* the head of bn_ctl_t Python mirrors (set-up, commands, state, counters): its size */
size_t bn_ctl_prefix_size(void);

#ifdef __cplusplus
}
#endif

#endif /* BN_CTL_H */
