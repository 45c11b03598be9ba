/* Rotating HF voltage injection (Wen Sec. 2) and its three demodulators in the core.
 *
 *   injection, eq. (3): u_ab,h = V_h exp(j w_h t), at the mid-point 1.5 T_s after the
 *                       sample of the period it acts in;
 *   tt-dq  (cc_tt_dq.c), eqs. (31)-(34): BPF in the estimated frame, i_dh i_qh, LPF;
 *   tt-ab  (cc_tt_ab.c), eqs. (23)-(28): BPF in alpha-beta, the heterodyne of sin/cos 2 theta;
 *   sfhf   (cc_sfhf.c),  eqs. (7)-(13): BPF, HPF of the positive sequence, heterodyne.
 * Each gives err = f / norm (the model normalisation of controller/_rotating.py),
 * which drives the PLL (cc_pll.h).
 */
#ifndef CC_ROTATING_H
#define CC_ROTATING_H

#include "cc_estimator.h"
#include "cc_filters.h"
#include "cc_pll.h"

typedef struct {
    double V_h, wT, inv_norm, f;
    long long k;
    int track;                  /* tt-dq: the BPF follows the HF current's frequency */
    double w_h, T_s, B, w0_min; /* its centre, period, bandwidth, lowest centre */
    cc_pll_t pll;
    cc_bq2_t bpf;
    cc_fo_t lpf;     /* tt-dq, sfhf */
    cc_fo2_t lpf_ab; /* tt-ab */
    cc_fo2_t hpf;    /* sfhf */
} cc_rot_t;

/* constants; the caller initialises pll, bpf, lpf / lpf_ab, hpf with their _init */
void cc_rot_init(cc_rot_t *r, double V_h, double wT, double inv_norm);
/* tt-dq's tracking band-pass: centre |w_h - w_hat|, at least w0_min, bandwidth B */
void cc_rot_tracking(cc_rot_t *r, double w_h, double T_s, double B, double w0_min);
void cc_rot_reset(cc_est_t *e, cc_rot_t *r, double theta0);
void cc_rot_injection(const cc_rot_t *r, double *u_a, double *u_b);

void cc_tt_dq_step(cc_est_t *e, cc_rot_t *r, long long k, double i_a, double i_b);
void cc_tt_ab_step(cc_est_t *e, cc_rot_t *r, long long k, double i_a, double i_b);
void cc_sfhf_step(cc_est_t *e, cc_rot_t *r, long long k, double i_a, double i_b);

/* shared by the demodulators: publish the estimate and step the PLL */
void cc_rot_publish(cc_est_t *e, cc_rot_t *r, double th, double f, double err, double i_af,
                    double i_bf);

#endif
