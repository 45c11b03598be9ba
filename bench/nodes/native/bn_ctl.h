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
 * The bench commands stay Python's (bench/nodes/_counters.py CommandQueue,
 * one home for their rules): a BenchCommand frame, and a step at which a
 * command is due, are events the caller hands to Python, which applies them
 * to the same core and calls again (bn_ctl_resume).  The signals' scale,
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
    BN_CTL_EV_DUE = 2,      /* a command is due at step due_k: apply, then resume */
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
    /* the commands' state, kept by Python's CommandQueue and copied here */
    int64_t cmd_next_step; /* apply step of the first pending command (INT64_MAX: none) */
    int32_t ack_seq;       /* CommandQueue.ack_seq (-1: none) */
    int32_t send_ack;      /* set by Python: send the last output's telemetry now */
    int32_t stopped;       /* set by Python (a stop command ran) */
    /* loop timing (bn_ctl_serve) */
    int64_t idle_ns, sample_timeout_ns, poll_ns, return_ns;
    /* state */
    int64_t next_k;
    int64_t due_k;
    int32_t error;
    int32_t has_last;
    cc_out_t last;
    bn_frame_t cmd_frame;
    bn_ctl_counts_t c;
    /* loop state */
    int64_t t_last, t_sample;
    uint64_t seen;
    /* rings */
    int64_t s_k[BN_CTL_RING], t_k[BN_CTL_RING], a_k[BN_CTL_ANSWERS];
    double s_i_a[BN_CTL_RING], s_i_b[BN_CTL_RING], s_u_dc[BN_CTL_RING];
    double t_theta[BN_CTL_RING], t_w_m[BN_CTL_RING];
    bn_frame_t a_duty[BN_CTL_ANSWERS], a_tel[BN_CTL_ANSWERS];
} bn_ctl_t;

/* where the frames to send go; 0 or -errno */
typedef int (*bn_ctl_sink_t)(void *ctx, const bn_frame_t *f);

/* Empty rings and counters, next step 0 (the set-up fields are kept). */
void bn_ctl_reset(bn_ctl_t *ctl);

/* Take one received frame (PhaseSamples, PlantTruth or BenchCommand); the frames
 * it answers go to sink.  BN_CTL_EV_NONE, or an event for Python. */
int bn_ctl_on_frame(bn_ctl_t *ctl, const bn_frame_t *in, bn_ctl_sink_t sink, void *ctx);

/* After Python handled an event: send the telemetry it asked for (send_ack) and
 * run the steps that are ready.  BN_CTL_EV_NONE, or an event. */
int bn_ctl_resume(bn_ctl_t *ctl, bn_ctl_sink_t sink, void *ctx);

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
