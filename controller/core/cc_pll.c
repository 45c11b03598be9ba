/* Position tracking observer of Wen Fig. 4 (cc_pll.h). */
#include "cc_math.h"
#include "cc_pll.h"

void cc_pll_init(cc_pll_t *p, double k_p, double k_i, double T_s)
{
    p->k_p = k_p;
    p->k_i = k_i;
    p->T_s = T_s;
    cc_pll_reset(p, 0.0, 0.0);
}

void cc_pll_reset(cc_pll_t *p, double theta0, double w0)
{
    p->theta_hat = cc_mod(theta0, CC_TWO_PI);
    p->w_hat = w0;
    p->w_i = w0;
}

void cc_pll_step(cc_pll_t *p, double err, double accel)
{
    p->w_i += p->T_s * p->k_i * err;
    if (accel != 0.0)
        p->w_i += p->T_s * accel;
    p->w_hat = p->k_p * err + p->w_i;
    p->theta_hat = cc_mod(p->theta_hat + p->T_s * p->w_hat, CC_TWO_PI);
}
