/* Reduced-order flux observer (cc_flux_observer.h). */
#include "cc_flux_observer.h"
#include "cc_math.h"

void cc_flux_init(cc_flux_t *o, double R_s, double L_d, double L_q, double psi_f, double T_s,
                  double zeta_f, double w_min, double k_p, double k_i)
{
    o->L_d = L_d;
    o->L_q = L_q;
    o->psi_f = psi_f;
    o->T_s = T_s;
    o->w_min = w_min;
    o->k_i = k_i;
    o->kp = k_p;
    o->ki_T = k_i * T_s;
    o->zT = zeta_f * T_s;
    o->rT2 = 0.5 * R_s * T_s;
    o->dL = L_d - L_q;
    o->theta_hat = o->w_hat = o->eps = o->accel = 0.0;
    o->psi_alpha = psi_f;
    o->psi_beta = 0.0;
    o->th_next = 0.0;
    o->ia1 = o->ib1 = 0.0;
    o->init = 1;
}

void cc_flux_reset(cc_flux_t *o, double theta0, double w0)
{
    o->th_next = cc_mod(theta0, CC_TWO_PI);
    o->theta_hat = o->th_next;
    o->w_hat = w0;
    o->eps = 0.0;
    o->accel = 0.0;
    o->init = 1;
}

void cc_flux_set_state(cc_flux_t *o, double psi_alpha, double psi_beta, double i_alpha,
                       double i_beta)
{
    o->psi_alpha = psi_alpha;
    o->psi_beta = psi_beta;
    o->ia1 = i_alpha;
    o->ib1 = i_beta;
    o->init = 0;
}

static double flux_k1T(const cc_flux_t *o, double w)
{
    double a = w >= 0.0 ? w : -w;
    if (a < o->w_min)
        a = o->w_min;
    double g = o->zT * a;
    return g < 0.5 ? g : 0.5;
}

/* the voltage model (trapezoid on the resistive drop), or the current model on the
 * first sample after a reset */
static void flux_predict(cc_flux_t *o, double i_a, double i_b, double u_a, double u_b,
                         double c, double s)
{
    if (o->init) {
        double i_d = c * i_a + s * i_b;
        double i_q = c * i_b - s * i_a;
        double p_d = o->psi_f + o->L_d * i_d;
        double p_q = o->L_q * i_q;
        o->psi_alpha = c * p_d - s * p_q;
        o->psi_beta = s * p_d + c * p_q;
        o->init = 0;
    } else {
        double T = o->T_s;
        double r = o->rT2;
        o->psi_alpha += T * u_a - r * (i_a + o->ia1);
        o->psi_beta += T * u_b - r * (i_b + o->ib1);
    }
    o->ia1 = i_a;
    o->ib1 = i_b;
}

static void flux_error(const cc_flux_t *o, double i_alpha, double i_beta, double c, double s,
                       double *e_d, double *e_q, double *a_d, double *a_q, double *den)
{
    double i_d = c * i_alpha + s * i_beta;
    double i_q = c * i_beta - s * i_alpha;
    double pa = o->psi_alpha;
    double pb = o->psi_beta;
    *e_d = o->psi_f + o->L_d * i_d - (c * pa + s * pb);
    *e_q = o->L_q * i_q - (c * pb - s * pa);
    *a_d = o->psi_f + o->dL * i_d;
    *a_q = -o->dL * i_q;
    *den = *a_d * *a_d + *a_q * *a_q;
}

void cc_flux_step(cc_flux_t *o, double i_alpha, double i_beta, double u_alpha, double u_beta)
{
    double th = o->th_next;
    double c = cos(th);
    double s = sin(th);
    flux_predict(o, i_alpha, i_beta, u_alpha, u_beta, c, s);
    double pa = o->psi_alpha;
    double pb = o->psi_beta;
    double e_d, e_q, a_d, a_q, den, x, eps;
    flux_error(o, i_alpha, i_beta, c, s, &e_d, &e_q, &a_d, &a_q, &den);
    if (den > 0.0) {
        double inv = 1.0 / den;
        x = (e_d * a_d + e_q * a_q) * inv;
        eps = (e_d * a_q - e_q * a_d) * inv;
    } else {
        x = eps = 0.0;
    }
    double g = 2.0 * flux_k1T(o, o->w_hat) * x;
    double cd = g * a_d;
    double cq = g * a_q;
    o->psi_alpha = pa + c * cd - s * cq;
    o->psi_beta = pb + s * cd + c * cq;
    double w_i = o->w_hat + o->ki_T * eps;
    o->w_hat = w_i;
    o->eps = eps;
    o->accel = o->k_i * eps;
    o->theta_hat = th;
    th += o->T_s * (w_i + o->kp * eps);
    if (th >= CC_TWO_PI || th < 0.0)
        th = cc_mod(th, CC_TWO_PI);
    o->th_next = th;
}

void cc_flux_step_slaved(cc_flux_t *o, double i_alpha, double i_beta, double u_alpha,
                         double u_beta, double theta, double w)
{
    double c = cos(theta);
    double s = sin(theta);
    flux_predict(o, i_alpha, i_beta, u_alpha, u_beta, c, s);
    double pa = o->psi_alpha;
    double pb = o->psi_beta;
    double e_d, e_q, a_d, a_q, den;
    flux_error(o, i_alpha, i_beta, c, s, &e_d, &e_q, &a_d, &a_q, &den);
    o->eps = den > 0.0 ? (e_d * a_q - e_q * a_d) / den : 0.0;
    o->accel = 0.0;
    double g = flux_k1T(o, w);
    o->psi_alpha = pa + g * (c * e_d - s * e_q);
    o->psi_beta = pb + g * (s * e_d + c * e_q);
    o->w_hat = w;
    double th = cc_mod(theta, CC_TWO_PI);
    o->theta_hat = th;
    th += o->T_s * w;
    if (th >= CC_TWO_PI || th < 0.0)
        th = cc_mod(th, CC_TWO_PI);
    o->th_next = th;
}
