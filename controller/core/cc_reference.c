/* The speed loop's reference model (cc_reference.h). */
#include "cc_reference.h"

void cc_ref_init(cc_ref_t *r, double alpha_s, double n_p, double a_max, double T_s)
{
    r->alpha_s = alpha_s;
    r->n_p = n_p;
    r->a_max = a_max;
    r->T_s = T_s;
    r->w = 0.0;
}

void cc_ref_reset(cc_ref_t *r, double w0) { r->w = w0; }

double cc_ref_step(cc_ref_t *r, double w_ref)
{
    double dw = r->alpha_s * (w_ref - r->w);
    double a = r->n_p * dw;
    double a_max = r->a_max;
    if (a > a_max) {
        a = a_max;
        dw = a_max / r->n_p;
    } else if (a < -a_max) {
        a = -a_max;
        dw = -a_max / r->n_p;
    }
    r->w += r->T_s * dw;
    return a;
}
