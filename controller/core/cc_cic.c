/* CIC interpolation, Xue eq. (8) (cc_cic.h). */
#include "cc_cic.h"

int cc_cic_init(cc_cic_t *c, long long M)
{
    if (M < 1 || M > CC_CIC_MAX)
        return -1;
    c->M = M;
    c->inv_M = 1.0 / (double)M;
    cc_cic_reset(c);
    return 0;
}

void cc_cic_reset(cc_cic_t *c)
{
    for (long long j = 0; j < c->M; j++)
        c->buf[j] = 0.0;
    c->i = 0;
    c->acc = 0.0;
    c->n = 0;
}

double cc_cic_step(cc_cic_t *c, double x)
{
    long long i = c->i;
    c->acc += x - c->buf[i]; /* comb, then integrator */
    c->buf[i] = x;
    i += 1;
    c->i = i == c->M ? 0 : i;
    c->n += 1;
    if (c->n >= CC_CIC_REANCHOR) { /* re-anchor the integrator on the delay line */
        double s = 0.0;
        for (long long j = 0; j < c->M; j++)
            s += c->buf[j];
        c->n = 0;
        c->acc = s;
    }
    return c->acc * c->inv_M;
}

int cc_cici_init(cc_cici_t *f, long long M)
{
    f->held = 0.0;
    return cc_cic_init(&f->cic, M);
}

void cc_cici_reset(cc_cici_t *f, double x0)
{
    cc_cic_reset(&f->cic);
    f->held = x0;
}

void cc_cici_prime(cc_cici_t *f, double x0)
{
    cc_cici_reset(f, x0);
    for (long long j = 0; j < f->cic.M; j++)
        cc_cic_step(&f->cic, x0);
}

double cc_cici_step(cc_cici_t *f, int fresh, double x)
{
    if (fresh)
        f->held = x;
    return cc_cic_step(&f->cic, f->held);
}
