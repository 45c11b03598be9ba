/* Drive supervision: the per-period check of controller/_supervision.py, in C.
 *
 * Python designs every threshold (SupervisionPars.design, with its
 * derivations) and hands them to cc_sup_init; this file runs the check each
 * period, operation for operation as Supervisor.check and Supervisor.wrap do
 * (tests/test_supervision.py compares them bit for bit).  Each detection is a
 * controller mode (CtrlTelemetry.mode, dbc/bench.dbc), stops the switching
 * and latches; docs/PROTECTION.md is its prose.
 */
#ifndef CC_SUPERVISION_H
#define CC_SUPERVISION_H

#include "cc_foc.h"

/* detection modes (controller/_supervision.py) */
#define CC_MODE_CURRENT_SENSOR 5
#define CC_MODE_OPEN_PHASE 6
#define CC_MODE_DC_UNDERVOLTAGE 7
#define CC_MODE_DC_OVERVOLTAGE 8

typedef struct {
    /* thresholds (SupervisionPars) */
    double T_s, i_rail, i_res, du_stuck, i_min, rho_open, u_uv, u_ov, u_hyst;
    long long n_range, n_stuck, n_open_min, n_open_max, n_dc;
    /* state */
    long long latched;    /* the latched detection mode (0: none) */
    long long detected_k; /* the period of the latest detection (-1: none) */
    long long n_rail[2], stuck_n, blk_n, blk_len, u_n;
    int blk_scored;
    double stuck_lo[2], stuck_hi[2], du_lo[2], du_hi[2], u_prev[2];
    int has_u_prev;
    double ms[3], s[3], u_sum;
} cc_sup_t;

void cc_sup_init(cc_sup_t *s, double T_s, double i_rail, long long n_range, double i_res,
                 double du_stuck, long long n_stuck, double i_min, double rho_open,
                 long long n_open_min, long long n_open_max, double u_uv, double u_ov,
                 double u_hyst, long long n_dc);
/* the detection of this period (a CC_MODE_* above, or 0): samples i_a, i_b, u_dc and what
 * the controller answered to them (Supervisor.check) */
long long cc_sup_check(cc_sup_t *s, double i_a, double i_b, double u_dc, const cc_out_t *o);
/* the detection windows emptied (on init, and when a latched detection clears) */
void cc_sup_reset_windows(cc_sup_t *s);
/* whether the latched detection may clear on a new enable (Supervisor.release_ok) */
int cc_sup_release_ok(const cc_sup_t *s, double u_dc);
/* the supervision after the controller's step (Supervisor.wrap): o is the step's output
 * for the samples m; on a detection, and while one is latched, the controller is disabled
 * and o carries enable 0, duties 0.5 and the detection's mode */
void cc_sup_after(cc_sup_t *s, cc_foc_t *c, const cc_meas_t *m, cc_out_t *o);

#endif
