/* Magnet-polarity test, one period at a time (cc_startup.h). */
#include <math.h>

#include "cc_math.h"
#include "cc_startup.h"

void cc_polarity_init(cc_polarity_t *p, double L_d, double T_s, double i_pulse, double u_frac)
{
    p->L_d = L_d;
    p->T_s = T_s;
    p->i_pulse = i_pulse;
    p->u_frac = u_frac;
    p->U = 0.0;
    p->N = 1;
    p->n = 0;
    p->i0 = p->i1 = 0.0;
    p->d_i_pos = p->d_i_neg = 0.0;
    p->done = 0;
    p->flip = 0;
}

void cc_polarity_start(cc_polarity_t *p, double u_dc, double i_d0)
{
    double flux = p->L_d * p->i_pulse;
    double a = p->u_frac * u_dc / CC_SQRT3;
    double b = flux / (2.0 * p->T_s);
    p->U = b < a ? b : a;
    double n = ceil(flux / (p->U * p->T_s) - 1e-9);
    p->N = n > 2.0 ? (long long)n : 2; /* also for U = 0: no division result to use */
    p->n = 0;
    p->i0 = i_d0;
    p->i1 = i_d0;
    p->d_i_pos = 0.0;
    p->d_i_neg = 0.0;
    p->done = 0;
    p->flip = 0;
}

double cc_polarity_step(cc_polarity_t *p, double i_d)
{
    long long n = p->n;
    long long N = p->N;
    if (n < 3 * N) {
        double d = i_d - p->i0;
        if (d > p->d_i_pos)
            p->d_i_pos = d;
    } else {
        if (n == 3 * N) /* start of the second half: its own reference */
            p->i1 = i_d;
        double d = p->i1 - i_d;
        if (d > p->d_i_neg)
            p->d_i_neg = d;
    }
    p->n = n + 1;
    if (n >= 6 * N) {
        p->done = 1;
        p->flip = p->d_i_pos < p->d_i_neg;
        return 0.0;
    }
    long long phase = n / N;
    if (phase == 0 || phase == 4)
        return p->U;
    if (phase == 1 || phase == 3)
        return -p->U;
    return 0.0;
}
