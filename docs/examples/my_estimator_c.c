/* docs/examples/my_estimator.py's flux observer with a PLL, written in C against the
 * controller core's estimator interface (controller/core/cc_estimator.h): the same
 * operations in the same order, so it gives the Python estimator's numbers bit for bit
 * (built without fused multiply-adds). Build it as a shared library:
 *
 *   cc -std=c99 -O2 -shared -fPIC -ffp-contract=off -I controller/core \
 *      -o docs/examples/libmy_estimator_c.so docs/examples/my_estimator_c.c -lm
 *
 * and name it through docs/examples/my_estimator_c.py (--estimator my_estimator_c:create).
 * Options, in the order my_estimator.Options declares them: alpha_o, w_c (rad/s). */
#include <math.h>
#include <stddef.h>

#include "cc_estimator.h"

typedef struct {
    double T_s, R_s, L_d, L_q, psi_f, k_p, k_i, w_c;
    double psi_a, psi_b;
    cc_est_t out;
} flux_pll_t;

static const double TWO_PI = 2.0 * 3.14159265358979323846;

/* Python's float %: the sign of the divisor */
static double py_mod(double x, double m)
{
    double r = fmod(x, m);
    if (r != 0.0) {
        if ((m < 0.0) != (r < 0.0))
            r += m;
    } else {
        r = copysign(0.0, m);
    }
    return r;
}

static int update(void *ctx, const cc_est_in_t *x, cc_est_t *out)
{
    flux_pll_t *p = ctx;
    double T = p->T_s, th = p->out.theta_hat;
    double c = cos(th), s = sin(th);
    double i_d = c * x->i_alpha + s * x->i_beta;
    double i_q = -s * x->i_alpha + c * x->i_beta;
    double psi_d = p->L_d * i_d + p->psi_f;
    double psi_q = p->L_q * i_q;
    double m_a = c * psi_d - s * psi_q, m_b = s * psi_d + c * psi_q;
    p->psi_a += T * (x->u_alpha - p->R_s * x->i_alpha + p->w_c * (m_a - p->psi_a));
    p->psi_b += T * (x->u_beta - p->R_s * x->i_beta + p->w_c * (m_b - p->psi_b));
    double fa = p->psi_a - p->L_q * x->i_alpha, fb = p->psi_b - p->L_q * x->i_beta;
    cc_est_t *e = &p->out;
    e->err = atan2(-s * fa + c * fb, c * fa + s * fb);
    e->w_hat += T * p->k_i * e->err;
    e->theta_hat = py_mod(th + T * (e->w_hat + p->k_p * e->err), TWO_PI);
    e->i_alpha_f = x->i_alpha;
    e->i_beta_f = x->i_beta;
    *out = *e;
    return 0;
}

static int injection(void *ctx, double *u_alpha, double *u_beta)
{
    (void)ctx;
    *u_alpha = 0.0;
    *u_beta = 0.0;
    return 0;
}

static int reset(void *ctx, double theta0, cc_est_t *out)
{
    flux_pll_t *p = ctx;
    p->out.theta_hat = py_mod(theta0, TWO_PI);
    p->out.w_hat = 0.0;
    p->psi_a = p->psi_f * cos(theta0);
    p->psi_b = p->psi_f * sin(theta0);
    *out = p->out;
    return 0;
}

size_t cc_estimator_size(void) { return sizeof(flux_pll_t); }

int cc_estimator_init(void *state, cc_est_if_t *iface, const cc_est_design_t *d)
{
    if (d->n_options != 2 || !(d->options[0] > 0.0) || !(d->options[1] >= 0.0))
        return 1;
    flux_pll_t *p = state;
    double alpha_o = d->options[0];
    p->T_s = d->T_s;
    p->R_s = d->R_s;
    p->L_d = d->L_d;
    p->L_q = d->L_q;
    p->psi_f = d->psi_f;
    p->k_p = 2.0 * alpha_o;
    p->k_i = alpha_o * alpha_o;
    p->w_c = d->options[1];
    p->out.theta_hat = p->out.w_hat = p->out.err = 0.0;
    p->out.i_alpha_f = p->out.i_beta_f = 0.0;
    cc_est_t ignored;
    reset(p, 0.0, &ignored);
    iface->ctx = p;
    iface->update = update;
    iface->injection = injection;
    iface->reset = reset;
    iface->hf_current_next = NULL;
    iface->set_saliency_offset = NULL;
    return 0;
}
