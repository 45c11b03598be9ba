/* Rotating HF injection, Wen eq. (3), and the PLL hand-off (cc_rotating.h). */
#include "cc_math.h"
#include "cc_rotating.h"

void cc_rot_init(cc_rot_t *r, double V_h, double wT, double inv_norm)
{
    r->V_h = V_h;
    r->wT = wT;
    r->inv_norm = inv_norm;
    r->f = 0.0;
    r->I_p = r->I_n = 0.0;
    r->k = 0;
    r->track = 0;
    r->w_h = r->T_s = r->B = r->w0_min = 0.0;
    r->accel_ff = 0;
    r->accel = 0.0;
    r->mech = 0;
    r->l3 = r->torque = 0.0;
    r->measured = 0;
    r->amp_floor = 0.0;
    cc_fo2_init(&r->lpf_m, 0.0, 0.0, 0.0);
}

void cc_rot_measured(cc_rot_t *r, double amp_floor)
{
    r->measured = 1;
    r->amp_floor = amp_floor;
    cc_fo2_init(&r->lpf_m, r->lpf.b0, r->lpf.b1, r->lpf.a1);
}

void cc_rot_mechanical(cc_rot_t *r, double T_s, double g1, double g2, double g3, double gt,
                       double l3)
{
    r->mech = 1;
    cc_luen_init(&r->luen, T_s, g1, g2, g3, gt);
    r->l3 = l3;
}

void cc_rot_tracking(cc_rot_t *r, double w_h, double T_s, double B, double w0_min)
{
    r->track = 1;
    r->w_h = w_h;
    r->T_s = T_s;
    r->B = B;
    r->w0_min = w0_min;
}

void cc_rot_reset(cc_est_t *e, cc_rot_t *r, double theta0)
{
    if (r->mech) {
        cc_luen_reset(&r->luen, theta0, 0.0, 0.0);
        e->theta_hat = r->luen.theta_hat;
    } else {
        cc_pll_reset(&r->pll, theta0, 0.0);
        e->theta_hat = r->pll.theta_hat;
    }
    e->w_hat = 0.0;
    e->err = 0.0;
    r->f = 0.0;
    cc_bq2_reset(&r->bpf);
    cc_fo_reset(&r->lpf);
    cc_fo2_reset(&r->lpf_ab);
    cc_fo2_reset(&r->hpf);
    cc_bq2_reset(&r->quad);
    cc_fo2_reset(&r->lpf_n);
    cc_fo2_reset(&r->lpf_m);
}

void cc_rot_publish(cc_est_t *e, cc_rot_t *r, double th, double f, double err, double i_af,
                    double i_bf)
{
    e->i_alpha_f = i_af;
    e->i_beta_f = i_bf;
    e->theta_hat = th;
    r->f = f;
    e->err = err;
    if (r->mech) {
        /* the rate this step gives the angle: the speed state before the step plus the
         * proportional correction */
        double w = r->luen.w_hat;
        cc_luen_step(&r->luen, err, r->torque);
        e->w_hat = w + r->l3 * err;
    } else {
        cc_pll_step(&r->pll, err, r->accel);
        e->w_hat = r->pll.w_hat;
    }
}

void cc_rot_injection(const cc_rot_t *r, double *u_a, double *u_b)
{
    double ph = ((double)r->k + 1.5) * r->wT;
    *u_a = r->V_h * cos(ph);
    *u_b = r->V_h * sin(ph);
}

void cc_rot_hf_model(cc_rot_t *r, double I_p, double I_n)
{
    r->I_p = I_p;
    r->I_n = I_n;
}

void cc_rot_hf_current_next(const cc_rot_t *r, double *i_a, double *i_b)
{
    double ph = ((double)r->k + 1.5) * r->wT;
    double ng = 2.0 * cc_rot_theta(r) - ph;
    *i_a = r->I_p * sin(ph) - r->I_n * sin(ng);
    *i_b = -r->I_p * cos(ph) + r->I_n * cos(ng);
}
