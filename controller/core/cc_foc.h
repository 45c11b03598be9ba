/* Field-oriented speed control with a rotor-position estimator of the core, one PWM
 * period at a time (controller/_controller.py derives the structure and the gains):
 *
 *   sample k -> Clarke -> estimator -> Park(theta_hat) (HF removed)
 *            -> speed PI -> torque and current limits -> d-q current PI + decoupling
 *            -> voltage limit u_dc/sqrt(3) - |u_h| -> inverse Park(theta_hat + 1.5 T_s w_hat)
 *            + HF injection (Wen eq. (3) or Xue eq. (3)) -> SVPWM duties for period k + 1
 *            -> dead-time feed-forward on the duties (when on, cc_compensation.h)
 *            -> PI integrators updated with the realised outputs
 *
 * with the drive's countermeasures, each off unless switched on: the current offsets
 * measured at each start with the PWM disabled and removed from every sample, and the
 * estimate corrected by the cross-saturation offset (a hybrid's injection estimate alone);
 * and the start-up: alignment (estimator converging at standstill), the polarity
 * test (cc_startup.h), settling, then the speed loop.
 */
#ifndef CC_FOC_H
#define CC_FOC_H

#include "cc_compensation.h"
#include "cc_estimator.h"
#include "cc_filters.h"
#include "cc_hybrid.h"
#include "cc_pi.h"
#include "cc_reference.h"
#include "cc_rotating.h"
#include "cc_square_wave.h"
#include "cc_startup.h"

/* modes (controller/_api.py) */
#define CC_MODE_DISABLED 0
#define CC_MODE_ALIGN 1
#define CC_MODE_POLARITY 2
#define CC_MODE_RUN 3

/* the estimators of the core */
#define CC_EST_TT_DQ 1
#define CC_EST_TT_AB 2
#define CC_EST_SFHF 3
#define CC_EST_SQUARE_WAVE 4
#define CC_EST_SENSORED 5
#define CC_EST_HYBRID_TT_DQ 6
#define CC_EST_HYBRID_SQUARE_WAVE 7
#define CC_EST_SELF_DEMOD 8
#define CC_EST_EPF 9
/* an estimator outside the core, through the interface of cc_estimator.h (cc_est_if_t):
 * a user's estimator */
#define CC_EST_EXTERNAL 10

/* step results */
#define CC_OK 0
#define CC_ERR_NO_TRUTH -1 /* the sensored estimator without theta_e and w_e */
#define CC_ERR_U_DC -2     /* u_dc == 0 */
#define CC_ERR_ESTIMATOR -3 /* an external estimator failed (its context says why) */

typedef struct {
    int kind;
    cc_est_t out;
    cc_rot_t rot; /* tt-dq, tt-ab, sfhf, self-demod, epf, and the hybrid-tt-dq's injection */
    cc_sqw_t sqw; /* square-wave, and the hybrid-square-wave's injection */
    cc_hyb_t hyb; /* the hybrids' own */
    cc_est_if_t ext; /* CC_EST_EXTERNAL: its functions, set by the caller after _init */
} cc_estim_t;

typedef struct {
    long long k;
    double i_a, i_b, i_c; /* phase currents (A) */
    double u_dc;          /* DC-link voltage (V) */
    int has_truth;        /* the sensored baseline only: */
    double theta_e, w_e;  /* true electrical angle (rad) and speed (rad/s) */
} cc_meas_t;

typedef struct {
    long long k;
    double d_a, d_b, d_c; /* duties for period k + 1 */
    int enable;
    double theta_hat, w_hat, err;
    long long mode;
    double i_d, i_q;
} cc_out_t;

typedef struct {
    /* constants */
    double n_p, L_d, L_q, psi_f, k_tau, i_max, tau_max, t_delay, theta0;
    long long n_align, n_settle;
    int raw_feedback; /* the current PIs see the sampled current, HF included */
    int align;        /* start with the alignment and polarity test (else in MODE_RUN) */
    /* blocks */
    cc_pi_t pi_d, pi_q, pi_w;
    cc_fo_t lpf_w;
    cc_ref_t ref; /* the speed loop's reference model (EstimatorInput.accel_ref) */
    cc_polarity_t polarity;
    cc_estim_t est;
    /* the drive's countermeasures (cc_compensation.h), each off unless switched on */
    int dead_time, hf_next, cross_sat, sal_own, calibrate;
    double k_dq;
    cc_deadtime_t dt;
    cc_offset_cal_t cal;
    /* states */
    long long mode, n_mode;
    int settled, has_i_ref;
    double i_ref_d, i_ref_q, theta_pol;
    double w_m_ref, i_d_ref, i_q_ref, tau_ref, w_m_hat, u_d, u_q, u_a1, u_b1, u_a2, u_b2;
} cc_foc_t;

/* The constants; the blocks (pi_*, lpf_w, ref, polarity, the estimator's) are
 * initialised by their own _init, the estimator with cc_estim_init first. */
void cc_foc_init(cc_foc_t *c, double n_p, double L_d, double L_q, double psi_f, double i_max,
                 double tau_max, double t_delay, long long n_align, long long n_settle,
                 double theta0, int raw_feedback, int align);
/* the countermeasures, after cc_foc_init: the dead-time feed-forward (hf_next: the phase
 * currents expected include the estimator's predicted HF current), the cross-saturation
 * correction (sal_own: the hybrid corrects its injection estimate itself), the offset
 * calibration over n periods */
void cc_foc_dead_time(cc_foc_t *c, double T_s, double t_dead, double v_ce, double v_f,
                      double i_band, int sine, int hf_next);
void cc_foc_cross_saturation(cc_foc_t *c, double k_dq, int sal_own);
void cc_foc_offset_calibration(cc_foc_t *c, long long n);
/* the estimator's kind and its links (a hybrid's injection estimator); -1: unknown.
 * CC_EST_EXTERNAL: the caller then sets e->ext (cc_estimator.h).
 * Those below return 0, or nonzero when an external estimator failed. */
int cc_estim_init(cc_estim_t *e, int kind);
int cc_estim_reset(cc_estim_t *e, double theta0);
/* the HF voltage (alpha, beta) (V) the estimator adds to the command for the next period */
int cc_estim_injection(const cc_estim_t *e, double *u_a, double *u_b);
/* the HF current (alpha, beta) (A) the estimator predicts at the mid-point of period k + 1
 * (0 where it predicts none) */
int cc_estim_hf_current_next(const cc_estim_t *e, double *i_a, double *i_b);

void cc_foc_set_speed_ref(cc_foc_t *c, double w_m_ref);
/* hold (i_d, i_q) references in MODE_RUN (on != 0), or return to speed control */
void cc_foc_set_current_ref(cc_foc_t *c, int on, double i_d, double i_q);
/* CC_OK, or CC_ERR_ESTIMATOR when an external estimator's reset failed */
int cc_foc_set_enable(cc_foc_t *c, int enable);
/* the duties for period k + 1 from the samples of period k; CC_OK, or an error: nothing
 * changed for CC_ERR_U_DC and CC_ERR_NO_TRUTH; CC_ERR_ESTIMATOR stops the period where the
 * external estimator failed (as the exception does in the Python step) */
int cc_foc_step(cc_foc_t *c, const cc_meas_t *m, cc_out_t *o);

#endif
