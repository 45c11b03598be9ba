/* Position tracking observer (PLL) of Wen Fig. 4, below eqs. (9), (28), (34):
 *     w_i   += T_s k_i err  (+ T_s accel: a known acceleration fed forward beside the loop)
 *     w_hat  = k_p err + w_i
 *     theta += T_s w_hat  (mod 2 pi)
 * Gains from the phase-margin design of controller/_pll.py. */
#ifndef CC_PLL_H
#define CC_PLL_H

typedef struct { double k_p, k_i, T_s, theta_hat, w_hat, w_i; } cc_pll_t;

void cc_pll_init(cc_pll_t *p, double k_p, double k_i, double T_s);
void cc_pll_reset(cc_pll_t *p, double theta0, double w0);
void cc_pll_step(cc_pll_t *p, double err, double accel);

#endif
