/* The sensored baseline: the measured angle and speed pass through (the only
 * estimator that reads plant truth). */
#ifndef CC_SENSORED_H
#define CC_SENSORED_H

#include "cc_estimator.h"

static inline void cc_sensored_step(cc_est_t *e, double i_a, double i_b, double theta_e,
                                    double w_e)
{
    e->theta_hat = theta_e;
    e->w_hat = w_e;
    e->i_alpha_f = i_a;
    e->i_beta_f = i_b;
}

#endif
