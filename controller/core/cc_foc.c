/* Field-oriented speed control and its start-up (cc_foc.h). */
#include "cc_foc.h"
#include "cc_math.h"
#include "cc_sensored.h"
#include "cc_svpwm.h"

#include <stddef.h>

void cc_foc_init(cc_foc_t *c, double n_p, double L_d, double L_q, double psi_f, double i_max,
                 double tau_max, double t_delay, long long n_align, long long n_settle,
                 double theta0, int raw_feedback, int align)
{
    c->n_p = n_p;
    c->L_d = L_d;
    c->L_q = L_q;
    c->psi_f = psi_f;
    c->k_tau = 1.5 * n_p * psi_f;
    c->i_max = i_max;
    c->tau_max = tau_max;
    c->t_delay = t_delay;
    c->n_align = n_align;
    c->n_settle = n_settle;
    c->theta0 = theta0;
    c->raw_feedback = raw_feedback;
    c->align = align;
    c->mode = CC_MODE_DISABLED;
    c->n_mode = 0;
    c->settled = 0;
    c->has_i_ref = 0;
    c->i_ref_d = c->i_ref_q = c->theta_pol = 0.0;
    c->w_m_ref = c->i_d_ref = c->i_q_ref = c->tau_ref = c->w_m_hat = 0.0;
    c->u_d = c->u_q = 0.0;
    c->u_a1 = c->u_b1 = c->u_a2 = c->u_b2 = 0.0;
    c->dead_time = c->hf_next = c->cross_sat = c->sal_own = c->calibrate = 0;
    c->k_dq = 0.0;
    cc_ref_init(&c->ref, 0.0, n_p, 0.0, 0.0); /* no acceleration until designed */
}

void cc_foc_dead_time(cc_foc_t *c, double T_s, double t_dead, double v_ce, double v_f,
                      double i_band, int sine, int hf_next)
{
    cc_deadtime_init(&c->dt, T_s, t_dead, v_ce, v_f, i_band, sine);
    c->dead_time = 1;
    c->hf_next = hf_next;
}

void cc_foc_cross_saturation(cc_foc_t *c, double k_dq, int sal_own)
{
    c->cross_sat = 1;
    c->k_dq = k_dq;
    c->sal_own = sal_own;
}

void cc_foc_offset_calibration(cc_foc_t *c, long long n)
{
    cc_offset_cal_init(&c->cal, n);
    c->calibrate = 1;
}

int cc_estim_init(cc_estim_t *e, int kind)
{
    if (kind < CC_EST_TT_DQ || kind > CC_EST_EXTERNAL)
        return -1;
    e->kind = kind;
    e->out.theta_hat = e->out.w_hat = e->out.err = e->out.i_alpha_f = e->out.i_beta_f = 0.0;
    e->hyb.square = kind == CC_EST_HYBRID_SQUARE_WAVE;
    e->hyb.rot = &e->rot;
    e->hyb.sqw = &e->sqw;
    e->ext.ctx = NULL;
    e->ext.update = NULL;
    e->ext.injection = NULL;
    e->ext.reset = NULL;
    e->ext.hf_current_next = NULL;
    e->ext.set_saliency_offset = NULL;
    return 0;
}

int cc_estim_reset(cc_estim_t *e, double theta0)
{
    switch (e->kind) {
    case CC_EST_EXTERNAL:
        return e->ext.reset(e->ext.ctx, theta0, &e->out) ? -1 : 0;
    case CC_EST_TT_DQ:
    case CC_EST_TT_AB:
    case CC_EST_SFHF:
    case CC_EST_SELF_DEMOD:
    case CC_EST_EPF:
        cc_rot_reset(&e->out, &e->rot, theta0);
        break;
    case CC_EST_SQUARE_WAVE:
        cc_sqw_reset(&e->out, &e->sqw, theta0);
        break;
    case CC_EST_HYBRID_TT_DQ:
    case CC_EST_HYBRID_SQUARE_WAVE:
        cc_hyb_reset(&e->out, &e->hyb, theta0);
        break;
    default: /* the angle comes from the sensor */
        e->out.theta_hat = theta0;
    }
    return 0;
}

static int estim_step(cc_estim_t *e, const cc_meas_t *m, double i_alpha, double i_beta,
                      double torque, double u_alpha, double u_beta, int running,
                      double accel_ref)
{
    e->rot.torque = torque; /* the mechanical observer's feed-forward */
    switch (e->kind) {
    case CC_EST_EXTERNAL: {
        cc_est_in_t x = {m->k, i_alpha, i_beta, torque, u_alpha, u_beta, running, accel_ref};
        return e->ext.update(e->ext.ctx, &x, &e->out) ? -1 : 0;
    }
    case CC_EST_TT_DQ:
        cc_tt_dq_step(&e->out, &e->rot, m->k, i_alpha, i_beta, accel_ref);
        break;
    case CC_EST_TT_AB:
        cc_tt_ab_step(&e->out, &e->rot, m->k, i_alpha, i_beta);
        break;
    case CC_EST_SFHF:
        cc_sfhf_step(&e->out, &e->rot, m->k, i_alpha, i_beta);
        break;
    case CC_EST_SELF_DEMOD:
        cc_self_demod_step(&e->out, &e->rot, m->k, i_alpha, i_beta);
        break;
    case CC_EST_EPF:
        cc_epf_step(&e->out, &e->rot, m->k, i_alpha, i_beta);
        break;
    case CC_EST_SQUARE_WAVE:
        cc_sqw_step(&e->out, &e->sqw, i_alpha, i_beta, torque);
        break;
    case CC_EST_HYBRID_TT_DQ:
    case CC_EST_HYBRID_SQUARE_WAVE:
        cc_hyb_step(&e->out, &e->hyb, m->k, i_alpha, i_beta, u_alpha, u_beta, torque, running,
                    accel_ref);
        break;
    default:
        cc_sensored_step(&e->out, i_alpha, i_beta, m->theta_e, m->w_e);
    }
    return 0;
}

int cc_estim_injection(const cc_estim_t *e, double *u_a, double *u_b)
{
    switch (e->kind) {
    case CC_EST_EXTERNAL:
        return e->ext.injection(e->ext.ctx, u_a, u_b) ? -1 : 0;
    case CC_EST_TT_DQ:
    case CC_EST_TT_AB:
    case CC_EST_SFHF:
    case CC_EST_SELF_DEMOD:
    case CC_EST_EPF:
        cc_rot_injection(&e->rot, u_a, u_b);
        break;
    case CC_EST_SQUARE_WAVE:
        cc_sqw_injection(&e->sqw, u_a, u_b);
        break;
    case CC_EST_HYBRID_TT_DQ:
    case CC_EST_HYBRID_SQUARE_WAVE:
        cc_hyb_injection(&e->hyb, u_a, u_b);
        break;
    default:
        *u_a = 0.0;
        *u_b = 0.0;
    }
    return 0;
}

int cc_estim_hf_current_next(const cc_estim_t *e, double *i_a, double *i_b)
{
    switch (e->kind) {
    case CC_EST_EXTERNAL:
        if (e->ext.hf_current_next != NULL)
            return e->ext.hf_current_next(e->ext.ctx, i_a, i_b) ? -1 : 0;
        *i_a = 0.0;
        *i_b = 0.0;
        break;
    case CC_EST_TT_DQ:
    case CC_EST_TT_AB:
    case CC_EST_SFHF:
    case CC_EST_SELF_DEMOD:
    case CC_EST_EPF:
        cc_rot_hf_current_next(&e->rot, i_a, i_b);
        break;
    case CC_EST_HYBRID_TT_DQ:
    case CC_EST_HYBRID_SQUARE_WAVE:
        cc_hyb_hf_current_next(&e->hyb, i_a, i_b);
        break;
    default:
        *i_a = 0.0;
        *i_b = 0.0;
    }
    return 0;
}

void cc_foc_set_speed_ref(cc_foc_t *c, double w_m_ref) { c->w_m_ref = w_m_ref; }

void cc_foc_set_current_ref(cc_foc_t *c, int on, double i_d, double i_q)
{
    c->has_i_ref = on;
    c->i_ref_d = on ? i_d : 0.0;
    c->i_ref_q = on ? i_q : 0.0;
    cc_pi_reset(&c->pi_w);
}

static int foc_restart(cc_foc_t *c)
{
    cc_pi_reset(&c->pi_d);
    cc_pi_reset(&c->pi_q);
    cc_pi_reset(&c->pi_w);
    cc_fo_reset(&c->lpf_w);
    cc_ref_reset(&c->ref, 0.0);
    if (cc_estim_reset(&c->est, c->theta0))
        return CC_ERR_ESTIMATOR;
    c->i_d_ref = c->i_q_ref = c->tau_ref = 0.0;
    c->u_a1 = c->u_b1 = c->u_a2 = c->u_b2 = 0.0;
    c->n_mode = 0;
    c->settled = 0;
    if (c->calibrate)
        cc_offset_cal_restart(&c->cal);
    c->mode = c->align ? CC_MODE_ALIGN : CC_MODE_RUN;
    return CC_OK;
}

int cc_foc_set_enable(cc_foc_t *c, int enable)
{
    if (enable && c->mode == CC_MODE_DISABLED)
        return foc_restart(c);
    if (!enable)
        c->mode = CC_MODE_DISABLED;
    return CC_OK;
}

static void set_out(cc_out_t *o, long long k, const double d[3], int enable, double th,
                    double w, double err, long long mode, double i_d, double i_q)
{
    o->k = k;
    o->d_a = d[0];
    o->d_b = d[1];
    o->d_c = d[2];
    o->enable = enable;
    o->theta_hat = th;
    o->w_hat = w;
    o->err = err;
    o->mode = mode;
    o->i_d = i_d;
    o->i_q = i_q;
}

/* the output of every period that applies a voltage (the polarity pulses and the control
 * periods): the duties of the stationary command (u_a, u_b) for period k + 1, the command
 * kept for two periods (EstimatorInput.u_alpha), and, with the dead-time feed-forward, the
 * duties corrected for the phase currents (i_a, -i_a/2 + h, -i_a/2 - h) expected, with
 * h = sqrt(3)/2 i_beta as the caller forms it */
static void output_step(cc_foc_t *c, double u_a, double u_b, double u_dc, double i_a, double h,
                        double d[3])
{
    cc_svpwm(u_a, u_b, u_dc, d);
    c->u_a2 = c->u_a1;
    c->u_b2 = c->u_b1;
    c->u_a1 = u_a;
    c->u_b1 = u_b;
    if (c->dead_time)
        cc_deadtime_duties(&c->dt, d, i_a, -0.5 * i_a + h, -0.5 * i_a - h, u_dc);
}

/* the polarity test's period: a pulse along the estimated d axis */
static int polarity_step(cc_foc_t *c, long long k, double i_alpha, double i_beta, double u_dc,
                         cc_out_t *o)
{
    double th = c->theta_pol;
    double co = cos(th);
    double si = sin(th);
    double i_d = co * i_alpha + si * i_beta;
    double i_q = co * i_beta - si * i_alpha;
    cc_polarity_t *pt = &c->polarity;
    double u_d = cc_polarity_step(pt, i_d);
    if (pt->done) {
        double th_new = pt->flip ? cc_mod(th + M_PI, CC_TWO_PI) : th;
        if (cc_estim_reset(&c->est, th_new))
            return CC_ERR_ESTIMATOR;
        cc_pi_reset(&c->pi_d);
        cc_pi_reset(&c->pi_q);
        c->mode = CC_MODE_ALIGN;
        c->settled = 1;
        c->n_mode = 0;
    }
    /* the pulses get the same feed-forward as every other voltage, the sign the present
     * pulse current's, along the pulse axis */
    double d[3];
    output_step(c, co * u_d, si * u_d, u_dc, co * i_d, CC_SQRT3_HALF * si * i_d, d);
    set_out(o, k, d, 1, th, 0.0, 0.0, CC_MODE_POLARITY, i_d, i_q);
    return CC_OK;
}

/* the alignment's end: to the polarity test, or (settled) to the speed loop */
static void advance_mode(cc_foc_t *c, double i_alpha, double i_beta, double u_dc)
{
    if (c->mode != CC_MODE_ALIGN)
        return;
    c->n_mode += 1;
    if (!c->settled && c->n_mode >= c->n_align) {
        double th = c->est.out.theta_hat;
        double i_d0 = cos(th) * i_alpha + sin(th) * i_beta;
        cc_polarity_start(&c->polarity, u_dc, i_d0);
        c->theta_pol = th;
        c->mode = CC_MODE_POLARITY;
        c->n_mode = 0;
    } else if (c->settled && c->n_mode >= c->n_settle) {
        cc_pi_reset(&c->pi_w);
        c->mode = CC_MODE_RUN;
        c->n_mode = 0;
    }
}

int cc_foc_step(cc_foc_t *c, const cc_meas_t *m, cc_out_t *o)
{
    long long mode = c->mode;
    cc_est_t *e = &c->est.out;
    if (mode == CC_MODE_DISABLED) {
        static const double half[3] = {0.5, 0.5, 0.5};
        set_out(o, m->k, half, 0, cc_mod(e->theta_hat, CC_TWO_PI), e->w_hat, 0.0, mode, 0.0,
                0.0);
        return CC_OK;
    }
    double i_a = m->i_a;
    double i_b = m->i_b;
    double i_c = m->i_c;
    if (c->calibrate) { /* the offsets, PWM disabled, then removed from every sample */
        cc_offset_cal_t *cal = &c->cal;
        if (cal->k < cal->n) {
            static const double half[3] = {0.5, 0.5, 0.5};
            cc_offset_cal_add(cal, i_a, i_b, i_c);
            set_out(o, m->k, half, 0, cc_mod(e->theta_hat, CC_TWO_PI), 0.0, 0.0, CC_MODE_ALIGN,
                    0.0, 0.0);
            return CC_OK;
        }
        i_a -= cal->o_a;
        i_b -= cal->o_b;
        i_c -= cal->o_c;
    }
    if (m->u_dc == 0.0)
        return CC_ERR_U_DC;
    if (c->est.kind == CC_EST_SENSORED && mode != CC_MODE_POLARITY && !m->has_truth)
        return CC_ERR_NO_TRUTH;
    /* measure (amplitude-invariant Clarke) */
    double i_alpha = (2.0 * i_a - i_b - i_c) / 3.0;
    double i_beta = (i_b - i_c) * CC_SQRT3_INV;
    double u_dc = m->u_dc;
    if (mode == CC_MODE_POLARITY)
        return polarity_step(c, m->k, i_alpha, i_beta, u_dc, o);
    if (c->sal_own) { /* the hybrid corrects its injection estimate only */
        double off = cc_cross_saturation_offset(c->k_dq, c->i_q_ref, c->L_d, c->L_q);
        if (c->est.kind != CC_EST_EXTERNAL)
            c->est.hyb.saliency_offset = off;
        else if (c->est.ext.set_saliency_offset != NULL
                 && c->est.ext.set_saliency_offset(c->est.ext.ctx, off))
            return CC_ERR_ESTIMATOR;
    }
    /* the speed loop's designed acceleration, from the reference alone */
    double accel = mode == CC_MODE_RUN && !c->has_i_ref ? cc_ref_step(&c->ref, c->w_m_ref) : 0.0;
    if (estim_step(&c->est, m, i_alpha, i_beta, c->tau_ref, c->u_a2, c->u_b2,
                   mode == CC_MODE_RUN, accel))
        return CC_ERR_ESTIMATOR;
    double th = e->theta_hat;
    if (c->cross_sat && !c->sal_own)
        th -= cc_cross_saturation_offset(c->k_dq, c->i_q_ref, c->L_d, c->L_q);
    double w = e->w_hat;
    double co = cos(th);
    double si = sin(th);
    double i_af = e->i_alpha_f;
    double i_bf = e->i_beta_f;
    double i_d = co * i_af + si * i_bf;
    double i_q = co * i_bf - si * i_af;
    double i_d_pi, i_q_pi;
    if (c->raw_feedback) {
        i_d_pi = co * i_alpha + si * i_beta;
        i_q_pi = co * i_beta - si * i_alpha;
    } else {
        i_d_pi = i_d;
        i_q_pi = i_q;
    }
    /* speed loop */
    double w_m = cc_fo_step(&c->lpf_w, w / c->n_p);
    c->w_m_hat = w_m;
    double i_d_ref, i_q_ref, tau;
    if (mode == CC_MODE_RUN && c->has_i_ref) {
        i_d_ref = c->i_ref_d;
        i_q_ref = c->i_ref_q;
        tau = c->k_tau * i_q_ref;
    } else if (mode == CC_MODE_RUN) {
        double tau_u = cc_pi_output(&c->pi_w, c->w_m_ref, w_m, 0.0);
        double tau_max = c->tau_max;
        tau = tau_u > tau_max ? tau_max : (tau_u < -tau_max ? -tau_max : tau_u);
        i_d_ref = 0.0;
        i_q_ref = tau / c->k_tau;
        double r2 = c->i_max * c->i_max - i_d_ref * i_d_ref;
        double i_q_max = sqrt(0.0 > r2 ? 0.0 : r2);
        if (i_q_ref > i_q_max)
            i_q_ref = i_q_max;
        else if (i_q_ref < -i_q_max)
            i_q_ref = -i_q_max;
        tau = c->k_tau * i_q_ref;
    } else {
        i_d_ref = i_q_ref = tau = 0.0;
    }
    /* current loop with decoupling (estimated speed, filtered) */
    double w_e = c->n_p * w_m;
    double u_d = cc_pi_output(&c->pi_d, i_d_ref, i_d_pi, -w_e * c->L_q * i_q);
    double u_q = cc_pi_output(&c->pi_q, i_q_ref, i_q_pi, w_e * (c->L_d * i_d + c->psi_f));
    double u_ah, u_bh;
    if (cc_estim_injection(&c->est, &u_ah, &u_bh))
        return CC_ERR_ESTIMATOR;
    double u_lim = u_dc * CC_SQRT3_INV - sqrt(u_ah * u_ah + u_bh * u_bh);
    double u_dl = u_d, u_ql = u_q;
    cc_limit_magnitude(&u_dl, &u_ql, u_lim);
    /* inverse Park at the mid-point of period k + 1, then the HF voltage */
    double th_u = th + c->t_delay * w;
    double c_u = cos(th_u);
    double s_u = sin(th_u);
    double u_a = c_u * u_dl - s_u * u_ql + u_ah;
    double u_b = s_u * u_dl + c_u * u_ql + u_bh;
    /* phase currents expected at the mid-point of period k + 1 (the dead-time
     * feed-forward): the reference, plus the injection's HF current where the estimator
     * predicts it */
    double i_ar = 0.0, i_br = 0.0;
    if (c->dead_time) {
        i_ar = c_u * i_d_ref - s_u * i_q_ref;
        i_br = s_u * i_d_ref + c_u * i_q_ref;
        if (c->hf_next) {
            double h_a, h_b;
            if (cc_estim_hf_current_next(&c->est, &h_a, &h_b))
                return CC_ERR_ESTIMATOR;
            i_ar += h_a;
            i_br += h_b;
        }
    }
    double d[3];
    output_step(c, u_a, u_b, u_dc, i_ar, CC_SQRT3_HALF * i_br, d);
    /* the speed reported is the filtered estimate the speed loop uses */
    set_out(o, m->k, d, 1, cc_mod(th, CC_TWO_PI), w_m * c->n_p, e->err, mode, i_d, i_q);
    /* update the states with the realised outputs */
    cc_pi_update(&c->pi_d, u_dl);
    cc_pi_update(&c->pi_q, u_ql);
    c->u_d = u_dl;
    c->u_q = u_ql;
    if (mode == CC_MODE_RUN && !c->has_i_ref)
        cc_pi_update(&c->pi_w, tau);
    c->i_d_ref = i_d_ref;
    c->i_q_ref = i_q_ref;
    c->tau_ref = tau;
    advance_mode(c, i_alpha, i_beta, u_dc);
    return CC_OK;
}
