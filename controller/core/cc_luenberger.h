/* Luenberger position-speed observer with torque feed-forward, Xue Sec. 3.3,
 * eqs. (9)-(12), forward Euler (gains g1..g3, gt from controller/_luenberger.py):
 *     theta += T_s w + g3 e            (mod 2 pi)
 *     w     += T_s x + g2 e + gt tau_e
 *     x     += g1 e                                                       */
#ifndef CC_LUENBERGER_H
#define CC_LUENBERGER_H

typedef struct { double T_s, g1, g2, g3, gt, theta_hat, w_hat, x; } cc_luen_t;

void cc_luen_init(cc_luen_t *o, double T_s, double g1, double g2, double g3, double gt);
void cc_luen_reset(cc_luen_t *o, double theta0, double w0, double x0);
void cc_luen_step(cc_luen_t *o, double e, double tau_e);

#endif
