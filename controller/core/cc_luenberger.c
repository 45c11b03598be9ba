/* Luenberger observer of Xue eqs. (9)-(12) (cc_luenberger.h). */
#include "cc_luenberger.h"
#include "cc_math.h"

void cc_luen_init(cc_luen_t *o, double T_s, double g1, double g2, double g3, double gt)
{
    o->T_s = T_s;
    o->g1 = g1;
    o->g2 = g2;
    o->g3 = g3;
    o->gt = gt;
    cc_luen_reset(o, 0.0, 0.0, 0.0);
}

void cc_luen_reset(cc_luen_t *o, double theta0, double w0, double x0)
{
    o->theta_hat = cc_mod(theta0, CC_TWO_PI);
    o->w_hat = w0;
    o->x = x0;
}

void cc_luen_step(cc_luen_t *o, double e, double tau_e)
{
    double w = o->w_hat;
    double th = o->theta_hat + o->T_s * w + o->g3 * e;
    if (th >= CC_TWO_PI) {
        th -= CC_TWO_PI;
        if (th >= CC_TWO_PI)
            th = cc_mod(th, CC_TWO_PI);
    } else if (th < 0.0) {
        th += CC_TWO_PI;
        if (th < 0.0)
            th = cc_mod(th, CC_TWO_PI);
    }
    o->theta_hat = th;
    o->w_hat = w + o->T_s * o->x + o->g2 * e + o->gt * tau_e;
    o->x += o->g1 * e;
}
