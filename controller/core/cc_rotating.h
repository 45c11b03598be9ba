/* Rotating HF voltage injection (Wen Sec. 2) and its three demodulators in the core.
 *
 *   injection, eq. (3): u_ab,h = V_h exp(j w_h t), at the mid-point 1.5 T_s after the
 *                       sample of the period it acts in;
 *   tt-dq  (cc_tt_dq.c), eqs. (31)-(34): BPF in the estimated frame, i_dh i_qh, LPF;
 *   tt-ab  (cc_tt_ab.c), eqs. (23)-(28): BPF in alpha-beta, the heterodyne of sin/cos 2 theta;
 *   sfhf   (cc_sfhf.c),  eqs. (7)-(13): BPF, HPF of the positive sequence, heterodyne;
 *   self-demod (cc_self_demod.c), Wen's [27]: sequences separated by the BPF's
 *                       quadrature twin, the positive one demodulating the negative;
 *   epf    (cc_epf.c),   Wen's [25]: two demodulation signals in the estimated frame.
 * Each gives err = f / norm (the model normalisation of controller/_rotating.py),
 * or with normalise = "measured" (cc_rot_measured) err = f / (2 max(|(f, g)|, floor)):
 * g the quadrature of f through a second LPF (lpf_m), |.| cc_hypot (cc_math.h), floor
 * the tenth of the model amplitude the estimator's module states; err drives the PLL
 * (cc_pll.h).
 */
#ifndef CC_ROTATING_H
#define CC_ROTATING_H

#include "cc_estimator.h"
#include "cc_math.h"
#include "cc_filters.h"
#include "cc_luenberger.h"
#include "cc_pll.h"

typedef struct {
    double V_h, wT, inv_norm, f;
    double I_p, I_n;            /* model HF current amplitudes (A), eqs. (5)-(6) */
    long long k;
    int track;                  /* tt-dq: the BPF follows the HF current's frequency */
    double w_h, T_s, B, w0_min; /* its centre, period, bandwidth, lowest centre */
    int accel_ff;               /* tt-dq: the speed loop's designed acceleration fed into */
    double accel;               /* the PLL beside its loop (rad/s^2), this period's */
    cc_pll_t pll;
    int mech;       /* observer = "mechanical": the Luenberger observer below, not pll */
    cc_luen_t luen; /* with the torque feed-forward; its speed reported as */
    double l3;      /* w_hat + l3 err (controller/_rotating.py) */
    double torque;  /* the controller's torque this period (N m), its feed-forward */
    cc_bq2_t bpf;
    cc_fo_t lpf;     /* tt-dq, sfhf */
    cc_fo2_t lpf_ab; /* tt-ab */
    cc_fo2_t hpf;    /* sfhf */
    cc_bq2_t quad;   /* self-demod: the BPF's quadrature twin (s / w_h) H_B */
    cc_fo2_t lpf_n;  /* epf: the negative sequence's LPF (lpf_ab: the positive's) */
    int measured;     /* normalise = "measured": the amplitude from f and its quadrature */
    double amp_floor; /* the least amplitude err is normalised by (A^2 or A) */
    cc_fo2_t lpf_m;   /* the LPF of (f, quadrature), lpf's coefficients (epf: of (f, its
                       * quadrature) once more; tt-ab: unused, its lpf_ab gives both) */
} cc_rot_t;

/* constants; the caller initialises pll, bpf, lpf / lpf_ab, hpf with their _init */
void cc_rot_init(cc_rot_t *r, double V_h, double wT, double inv_norm);
/* tt-dq's tracking band-pass: centre |w_h - w_hat|, at least w0_min, bandwidth B */
void cc_rot_tracking(cc_rot_t *r, double w_h, double T_s, double B, double w0_min);
void cc_rot_reset(cc_est_t *e, cc_rot_t *r, double theta0);
void cc_rot_injection(const cc_rot_t *r, double *u_a, double *u_b);
/* the model amplitudes I_p, I_n (A) cc_rot_hf_current_next predicts with */
void cc_rot_hf_model(cc_rot_t *r, double I_p, double I_n);
/* the model HF current (alpha, beta) (A) at the mid-point of period k + 1, eqs. (4)/(7)
 * with theta_hat: I_p e^{j(ph - pi/2)} + I_n e^{j(2 theta_hat - ph + pi/2)} */
void cc_rot_hf_current_next(const cc_rot_t *r, double *i_a, double *i_b);

/* accel_ref: the speed loop's designed acceleration (rad/s^2), fed forward with accel_ff */
void cc_tt_dq_step(cc_est_t *e, cc_rot_t *r, long long k, double i_a, double i_b,
                   double accel_ref);
void cc_tt_ab_step(cc_est_t *e, cc_rot_t *r, long long k, double i_a, double i_b);
void cc_sfhf_step(cc_est_t *e, cc_rot_t *r, long long k, double i_a, double i_b);
void cc_self_demod_step(cc_est_t *e, cc_rot_t *r, long long k, double i_a, double i_b);
void cc_epf_step(cc_est_t *e, cc_rot_t *r, long long k, double i_a, double i_b);

/* the observer's angle (rad), the PLL's or the mechanical observer's */
static inline double cc_rot_theta(const cc_rot_t *r)
{
    return r->mech ? r->luen.theta_hat : r->pll.theta_hat;
}

/* observer = "mechanical" (after cc_rot_init): the Luenberger observer's gains and l3 */
void cc_rot_mechanical(cc_rot_t *r, double T_s, double g1, double g2, double g3, double gt,
                       double l3);

/* normalise = "measured" (after cc_rot_init and lpf's _init): err = f / (2 max(|(f, g)|,
 * amp_floor)), lpf_m initialised with lpf's coefficients */
void cc_rot_measured(cc_rot_t *r, double amp_floor);
/* err of the measured normalisation: f / (2 max(cc_hypot(a, b), amp_floor)) */
static inline double cc_rot_err_measured(const cc_rot_t *r, double f, double a, double b)
{
    double n = cc_hypot(a, b);
    return f / (2.0 * (r->amp_floor > n ? r->amp_floor : n)); /* Python's max(n, amp_floor) */
}

/* shared by the demodulators: publish the estimate and step the observer */
void cc_rot_publish(cc_est_t *e, cc_rot_t *r, double th, double f, double err, double i_af,
                    double i_bf);

#endif
