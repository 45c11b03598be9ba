/* HF square-wave injection at low switching frequency, Xue Secs. 2-3.
 *
 *   injection, eq. (3): +/-U_h along the estimated d axis, the sign alternating
 *                       every PWM period, at the angle theta_hat + t_comp w_hat
 *                       (delay compensation);
 *   HF response, eq. (7): h(k) = (i(k) - i(k-1)) / 2;
 *   envelope, eqs. (4)-(6): one position quadrature sample E per injection period;
 *   rate conversion and CIC interpolation, eq. (8) (cc_cic.h), or a plain hold;
 *   error Im(E conj u) / (|E| |u|) L_q / (L_q - L_d) into the Luenberger observer,
 *   eqs. (9)-(12) (cc_luenberger.h).
 */
#ifndef CC_SQUARE_WAVE_H
#define CC_SQUARE_WAVE_H

#include "cc_cic.h"
#include "cc_estimator.h"
#include "cc_luenberger.h"

typedef struct {
    int cic;
    double U_h, t_comp, k_err;
    double e_alpha, e_beta, u_next_a, u_next_b;
    double sg0, sg1, sg2, c0, c1, c2, s0, s1, s2, ha1, hb1;
    double held[4];
    long long env_n, n, n_tot;
    double ia1, ib1, id1, iq1, id2, iq2;
    cc_luen_t obs;
    cc_cici_t interp[4];
} cc_sqw_t;

/* constants; the caller initialises obs (cc_luen_init); M the CIC delay (-1: out of range) */
int cc_sqw_init(cc_est_t *e, cc_sqw_t *q, int cic, long long M, double U_h, double t_comp,
                double k_err);
void cc_sqw_reset(cc_est_t *e, cc_sqw_t *q, double theta0);
void cc_sqw_step(cc_est_t *e, cc_sqw_t *q, double i_a, double i_b, double torque);
void cc_sqw_injection(const cc_sqw_t *q, double *u_a, double *u_b);

#endif
