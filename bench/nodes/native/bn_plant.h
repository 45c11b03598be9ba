/* The plant node's per-period logic in C (bench.nodes._plant_node.PlantNode's hot path).
 *
 * Transport-free: frames in, frames out.  bn_plant_on_frame takes a received
 * frame (PwmDuty: length, E2E CRC, DBC ranges, step; the other frames are
 * the caller's), bn_plant_advance runs one period on the plant core
 * (plant_rt/core, the instance the Python plant built) and writes the frames
 * of the next instant (PhaseSamples, PositionSensor, PlantTruth, PlantStatus)
 * with the C codec `bench codegen` writes and its E2E CRC.  Bench commands are
 * kept by Python (bench.nodes._counters.CommandQueue: de-duplication, seq) and
 * handed over as the pending list (bn_plant_t.cmds); this unit applies them
 * at their step.  Every counter the Python node reports is in bn_plant_t,
 * which Python reads after the run (bench/nodes/native/_plant_native.py
 * mirrors it field by field).  No allocation: every buffer is in the struct,
 * or made by Python before the run and handed over once (the sensors' noise
 * values, bn_plant_noise_t; the fault timeline's tables, bn_plant_faults_t).
 *
 * bn_plant_loop (bn_plant_loop.c) drives the unit on a bn_bus_t in lockstep
 * or in real time and returns to Python only on an event it does not handle.
 */
#ifndef BN_PLANT_H
#define BN_PLANT_H

#include <stdint.h>

#include "bn.h"
#include "plant.h"
#include "plant_protection.h"

#ifdef __cplusplus
extern "C" {
#endif

#define BN_PLANT_RING 64   /* duties held, by step (t mod 64) */
#define BN_PLANT_CMDS 256  /* pending commands handed over at a time */
#define BN_PLANT_OUT 12    /* frames of one period, at most (outbox 4, five messages, babble) */
#define BN_PLANT_HISTORY 512 /* duties kept for a lockstep delay fault (NodeFaults' _HISTORY) */
#define BN_PLANT_SENT 16   /* periods of frames kept for retransmission (delay + 3) */

/* bn_plant_t.sig (bn_sig_t, bn.h): Python fills it from its Codec by the names
 * bn_plant_signal_names() lists, in that order. */

enum {
    BN_S_PS_I_A, BN_S_PS_I_B, BN_S_PS_U_DC, BN_S_PS_STATUS, BN_S_PS_STEP,
    BN_S_POS_THETA_M, BN_S_POS_STEP,
    BN_S_TR_THETA_E, BN_S_TR_W_M, BN_S_TR_TAU_E, BN_S_TR_TAU_L, BN_S_TR_DUTY_AGE, BN_S_TR_STEP,
    BN_S_TR_RUN_ID,
    BN_S_ST_STATE, BN_S_ST_FAULT_CODE, BN_S_ST_OVERRUNS, BN_S_ST_LATE_FRAMES, BN_S_ST_STEP,
    BN_S_PD_DUTY_A, BN_S_PD_DUTY_B, BN_S_PD_DUTY_C, BN_S_PD_ENABLE, BN_S_PD_STEP,
    BN_S_PC_I_A, BN_S_PC_I_B, BN_S_PC_STEP, BN_S_PC_RUN_ID,
    BN_S_N
};

/* Rejection reasons, in the order of bn_plant_reject_names(). */
enum {
    BN_RJ_BAD_CRC, BN_RJ_BAD_LENGTH, BN_RJ_DECODE_ERROR, BN_RJ_OUT_OF_RANGE, BN_RJ_STALE,
    BN_RJ_FUTURE, BN_RJ_WRONG_STEP, BN_RJ_REPEATED, BN_RJ_N
};

typedef struct {
    int64_t step;
    int32_t cmd, seq;
    double load_nm;
} bn_plant_cmd_t;

typedef struct {
    double d[3];
    int32_t en;
    int32_t pad;
    int64_t tag; /* the duty's step; -1: empty */
} bn_plant_duty_t;

/* Sensor noise handed over by Python (bench.nodes.native._plant_native.noise_draws): the
 * values the plant's generator gives the sensors (plant_rt._sensors.Sensors: its
 * random.Random(seed).gauss(0.0, sd), called by the core per plant_sensors_measure),
 * drawn by Python in the order the sensors take them, so no generator is written in C. */
typedef struct {
    const double *draws; /* NULL: the plant has no noise */
    int64_t n, used;
} bn_plant_noise_t;

/* The scenario's plant and sensor faults (plant_rt._faults.PlantFaults), handed over by
 * Python (bench.nodes.native._plant_native.NativeFaults).
 *
 * The machine and leg faults are an edge table Python makes from PlantFaults: at each
 * instant where the parameters in force (PlantFaults.parameters) or the legs
 * (PlantFaults.leg_faults) change, the plant's whole parameter set and the legs, which
 * the unit hands to plant_set_pars / plant_set_legs before that instant's sample, as
 * PlantFaults.before_period does through Plant.set_parameters.  The sensor faults are
 * PlantFaults.sample's windows, in its order, applied to the measured sample with its
 * rules (tests/test_native_faults.py holds them to the Python node's frames). */
typedef struct {
    int64_t k;                /* from this instant on */
    int32_t set_pars, set_legs;
    int32_t leg[3];           /* PLANT_LEG_* (plant_leg.h) */
    int32_t pad;
    plant_pars pars;
} bn_plant_edge_t;

enum { BN_SF_OFFSET, BN_SF_GAIN, BN_SF_STUCK, BN_SF_LOST, BN_SF_U_OFFSET, BN_SF_POS_LOST };

/* The bus faults (bench.nodes._fault_bus.NodeFaults) as tables over the instants
 * 0 .. n_k - 1, each entry NodeFaults' own answer for that instant (its draws included):
 * fate = duty_fate(k), shift_ls / shift_rt = duty_shift(k) in lockstep / real time,
 * nosend = not sends("PhaseSamples", k) (bit 0) and not sends("PositionSensor", k)
 * (bit 1), and babble's frames by instant.  The unit applies them where the Python
 * node asks them (PlantNode._on_duty, ready, advance_*, frames_now); bit 0 of nosend at
 * t - 1 is also NodeFaults.answer_lost(t), the lockstep answer to a sample lost on its
 * first sending, and hold_ns the real-time delay in us (NodeFaults.duty_hold_s). */
enum { BN_FATE_NONE = 0, BN_FATE_LOST = 1, BN_FATE_CORRUPT = 2 };

typedef struct {
    int64_t k;
    bn_frame_t to_plant, to_ctrl; /* a foreign PwmDuty taken, a foreign PhaseSamples sent */
} bn_plant_babble_t;

typedef struct {
    int32_t kind;             /* BN_SF_* */
    int32_t phase;            /* 0, 1, 2 */
    int64_t k0, k1;           /* [k0, k1); k1 < 0: to the end */
    double value;             /* a, factor or v */
    int32_t held, pad;        /* current_stuck: its value is held (in hold) */
    double hold;
} bn_plant_sfault_t;

typedef struct {
    int32_t on;                /* a fault timeline: PlantCurrents frames too (DBC 2.4) */
    int32_t n_edges, next_edge, n_sensor;
    const bn_plant_edge_t *edges;
    bn_plant_sfault_t *sensor;
    double last[3];            /* the previous sample as measured (current_stuck's source) */
    int64_t last_k;            /* its instant; -1: none */
    int64_t n_k;               /* the bus tables' length; an instant beyond: no fault */
    const int8_t *fate;        /* NULL: none of these faults */
    const int32_t *shift_ls, *shift_rt;
    const uint8_t *nosend;
    const bn_plant_babble_t *babble;
    int32_t n_babble, next_babble;
    uint64_t duties_lost, not_sent[2], babbled; /* NodeFaults.report() */
    bn_plant_duty_t history[BN_PLANT_HISTORY];  /* NodeFaults.history, by tag mod its size */
    /* Lockstep: the PhaseSamples lost on their first sending (PlantNode.withheld), kept in
     * Python's buffer of wh_cap frames (one per lost instant of the tables), in order;
     * [wh_sent, wh_n) are not sent yet.  The instant that next gets its sample through
     * sends them first (out_wh: withheld[out_wh[0], out_wh[1]) go before out[out_wh_at]),
     * and its record for retransmission holds them first (sent_wh, by sent's index). */
    bn_frame_t *withheld;
    int64_t wh_cap, wh_n, wh_sent;
    int64_t out_wh[2];
    int32_t out_wh_at, pad_wh;
    int64_t sent_wh[BN_PLANT_SENT][2];
    /* Real time: a delay in us (NodeFaults.duty_hold_s) as ns per instant of arrival (NULL:
     * none); released: when the duty in each ring slot may be applied (INT64_MIN: not
     * held, PlantNode.released_at); clock_ns: the clock of the frames' receive stamps
     * (bn_frame_t.t_ns), NULL: CLOCK_REALTIME (bn_realtime_ns); a test's fake clock. */
    const int64_t *hold_ns;
    int64_t released[BN_PLANT_RING];
    int64_t (*clock_ns)(void);
} bn_plant_faults_t;

typedef struct {
    /* ---- configuration (Python, before the run) */
    plant *pl;                    /* the Plant's core instance (plant_rt.Plant.core_address) */
    int64_t n_steps;              /* 0: until stopped */
    int32_t delay, truth_every, status_every, encoder_every;
    double encoder_delay_s;
    int64_t encoder_counts;
    plant_protection prot;
    int32_t has_prot, watchdog_periods, watchdog_rounds, realtime, external, run_id;
    int64_t m_samples, m_truth, m_status, m_step; /* counter moduli */
    bn_sig_t sig[BN_S_N];
    int32_t msg_flags[5];         /* BN_FD, BN_BRS of PhaseSamples, PositionSensor, PlantTruth,
                                     PlantStatus, PlantCurrents */
    int32_t pad_flags;
    bn_plant_noise_t noise;
    bn_plant_faults_t faults;
    /* ---- state (Python hands its node's over and takes it back) */
    int64_t k;                    /* the plant's period (plant_rt.Plant.k) */
    int64_t meas_k;               /* the step of pl->meas (sensor delay), -1: none */
    int32_t started, stopped, fault, dut_answered;
    int64_t fault_step, last_duty_k, rounds_waiting, latest_duty_step;
    int64_t dropped_upto;         /* PlantNode.dropped_upto: a dropped duty's arrival, -1 */
    double latest[3];
    int32_t latest_en, duty_age;
    int32_t load_changed;         /* a command set the load (pl->tau_const) */
    int32_t ctrl_ack;             /* CtrlTelemetry.cmd_ack, -1: none */
    int64_t cmd_horizon, applied_upto;
    int32_t applied_seq, n_cmds, cmds_more, pace_every;
    bn_plant_duty_t applied;      /* lockstep: the duty taken in its own period last (tag -1: none) */
    bn_plant_cmd_t cmds[BN_PLANT_CMDS]; /* pending, by step */
    bn_plant_duty_t duties[BN_PLANT_RING];
    /* ---- counters (added to the Python node's after the run) */
    uint64_t accepted, rejected[BN_RJ_N], duty_rejected[BN_RJ_N];
    uint64_t late_duties, retransmits, overruns, send_errors, frames_lost_on_send;
    uint64_t trips[8], resets, late_frames_base;
    /* ---- frames */
    bn_frame_t out[BN_PLANT_OUT];   /* this period's, to send */
    int32_t n_out, n_outbox;
    bn_frame_t outbox[4];           /* status frames queued by a trip or reset */
    bn_frame_t sent[BN_PLANT_SENT][BN_PLANT_OUT];
    int32_t n_sent[BN_PLANT_SENT];
    int64_t sent_head;              /* periods recorded */
} bn_plant_t;

/* "PhaseSamples.i_a,PhaseSamples.i_b,...": the signals of bn_plant_t.sig, in order. */
const char *bn_plant_signal_names(void);
/* "bad_crc,bad_length,...": the rejection reasons, in order. */
const char *bn_plant_reject_names(void);
size_t bn_plant_sizeof(void);
size_t bn_plant_loop_sizeof(void);
size_t bn_plant_edge_sizeof(void);
size_t bn_plant_sfault_sizeof(void);

/* The raw value bench.wire._codec.Codec.encode packs for physical value v
 * (clipped, or wrapped for a modular signal; cantools' rounding). */
int64_t bn_plant_raw(const bn_sig_t *s, double v);

/* Take one PwmDuty frame (any other frame: the caller's). */
void bn_plant_on_duty(bn_plant_t *u, const bn_frame_t *f);

/* The frames of the present instant into u->out (PlantNode.frames_now). */
void bn_plant_frames_now(bn_plant_t *u);

/* Lockstep: the duty of the present period is here (PlantNode.ready). */
int bn_plant_ready(const bn_plant_t *u);
/* A duty for step t is held. */
int bn_plant_has_duty(const bn_plant_t *u, int64_t t);
/* Lockstep: pacing lets the present period run (PlantNode.paced). */
int bn_plant_paced(const bn_plant_t *u);
/* Lockstep: the controller acknowledged the commands the next sample needs. */
int bn_plant_acked(const bn_plant_t *u);

/* One period (lockstep or real time as u->realtime), the commands of the
 * next step, and the next instant's frames into u->out (outbox first). */
void bn_plant_advance(bn_plant_t *u);

/* Lockstep: one retransmission round without the needed duty (the watchdog). */
void bn_plant_duty_timeout(bn_plant_t *u);

/* A PlantStatus frame of the present step. */
void bn_plant_status_frame(bn_plant_t *u, int state, int fault_code, bn_frame_t *f);

/* Apply the pending commands due at the present step (PlantNode.apply_commands). */
void bn_plant_apply_commands(bn_plant_t *u);

/* ---- the loop on a bus (bn_plant_loop.c) -------------------------------- */

enum {
    BN_EV_DONE = 0,     /* the run's steps are done, or stopped */
    BN_EV_FRAME = 1,    /* a frame for Python (BenchCommand, CtrlTelemetry): in ev_frame */
    BN_EV_POLL = 2,     /* a while passed (or a signal): Python checks its stop and re-enters */
    BN_EV_STALL = 3,    /* lockstep: no progress for stall_s (what waited: stall_what) */
    BN_EV_CMDS = 4,     /* the pending list handed over is used up: Python hands more */
    BN_EV_TRIPPED = 5,  /* lockstep, a controller under test: the watchdog tripped */
    BN_EV_ERROR = 6     /* a receive error: -errno in err */
};

enum { BN_WAIT_DUTY = 1, BN_WAIT_COMMAND = 2, BN_WAIT_ACK = 3 };

typedef struct {
    bn_plant_t *u;
    bn_bus_t *bus;
    uint32_t ids[4];            /* frames taken (PwmDuty first); 0: unused */
    uint32_t event_ids[4];      /* of those, the ones returned to Python */
    double retransmit_s, stall_s, first_s, poll_s;
    double last_answer_s;       /* lockstep, a controller under test: the wait for the last answer */
    /* real time: the clock's period, busy tail and stall (ns), and the busy buffer */
    int64_t period_ns, busy_tail_ns, stall_ns;
    uint32_t *busy;
    uint64_t busy_cap;
    uint32_t *late;             /* caller's buffer: each wake-up's lateness (ns, saturated) */
    uint64_t late_cap, n_late;
    bn_clock_t clock;
    int32_t rt_started;
    /* loop state (kept across returns) */
    int32_t phase;              /* 0: first frames not sent yet; real time: 1 send, 2 receive
                                   and step, 3 after the step, 4 done */
    int32_t stall_what;
    int64_t t_progress, t_quiet, t_poll;
    int32_t last_phase;         /* 0, 1: waiting for the last answer, 2: done */
    int64_t t_last_end;
    int64_t t_first_sent;       /* real time, a controller under test: sample 0 last sent */
    bn_frame_t ev_frame;
    int32_t err;
    /* real time: the caller's buffer of 3 busy_cap entries, each period's time (ns,
     * saturated) sending [0, cap), receiving [cap, 2 cap) and stepping [2 cap, 3 cap);
     * part_ns: the period's so far (BN_PART_*) */
    uint32_t *parts;
    int64_t part_ns[3];
    /* real time: the frames for Python (BenchCommand) met while draining before a step,
     * held and handed over after the step, one per return, while more than
     * held_margin_ns are left to the next deadline (the rest in later periods) */
    int64_t held_margin_ns;
    bn_held_t held;
    /* the bench commands Python took, whose copies take() drops (bn.h; Python sets it up) */
    bn_cmd_seen_t cmd_seen;
} bn_plant_loop_t;

enum { BN_PART_SEND = 0, BN_PART_RECV = 1, BN_PART_STEP = 2 };

/* Run until an event (BN_EV_*); re-enter after Python handled it. */
int bn_plant_loop(bn_plant_loop_t *L);

/* Send one frame as bench.nodes._send.send_all does (retries, counted). */
void bn_plant_send(bn_plant_t *u, bn_bus_t *bus, const bn_frame_t *f);

#ifdef __cplusplus
}
#endif

#endif /* BN_PLANT_H */
