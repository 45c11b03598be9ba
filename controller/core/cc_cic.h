/* Single-order cascaded integrator-comb (CIC) interpolation, Xue Sec. 3.2, eq. (8).
 *
 *   H(z) = (1/M) (1 - z^-M) / (1 - z^-1)      comb, then integrator
 *
 * preceded by a sample-and-hold (the rate conversion of Xue Figs. 4, 7-9):
 * cc_cici_step takes the slow sample on the period it arrives (fresh) and
 * holds it on the others.  The integrator is re-anchored on the delay line
 * every CC_CIC_REANCHOR steps, so that rounding cannot accumulate.
 */
#ifndef CC_CIC_H
#define CC_CIC_H

#define CC_CIC_MAX 64
#define CC_CIC_REANCHOR 4096

typedef struct {
    long long M;
    double inv_M;
    double buf[CC_CIC_MAX];
    long long i;
    double acc;
    long long n;
} cc_cic_t;

typedef struct { cc_cic_t cic; double held; } cc_cici_t;

/* M: the differential delay, 1 .. CC_CIC_MAX; returns -1 outside */
int cc_cic_init(cc_cic_t *c, long long M);
void cc_cic_reset(cc_cic_t *c);
double cc_cic_step(cc_cic_t *c, double x);

int cc_cici_init(cc_cici_t *f, long long M);
void cc_cici_reset(cc_cici_t *f, double x0);
/* empty the filter and fill its delay line with x0 (a start without a transient) */
void cc_cici_prime(cc_cici_t *f, double x0);
double cc_cici_step(cc_cici_t *f, int fresh, double x);

#endif
