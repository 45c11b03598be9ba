/* Two-degree-of-freedom PI controller (cc_pi.h; Wen Sec. 3.3, eq. (14)). */
#include "cc_pi.h"

void cc_pi_init(cc_pi_t *p, double k_p, double k_i, double T_s, double k_t)
{
    p->k_p = k_p;
    p->k_i = k_i;
    p->T_s = T_s;
    p->k_t = k_t;
    cc_pi_reset(p);
}

void cc_pi_reset(cc_pi_t *p)
{
    p->u_i = 0.0;
    p->e = 0.0;
    p->u = 0.0;
}

double cc_pi_output(cc_pi_t *p, double r, double y, double u_ff)
{
    p->e = r - y;
    p->u = p->k_t * r - p->k_p * y + p->u_i + u_ff;
    return p->u;
}

void cc_pi_update(cc_pi_t *p, double u_lim)
{
    p->u_i += p->T_s * p->k_i * (p->e + (u_lim - p->u) / p->k_t);
}
