/* A designed controller into the core (cc_design.h): each design call's _init calls. */
#include "cc_design.h"

#include <string.h>

int cc_design_init(cc_foc_t *c, cc_sup_t *sup, int kind)
{
    memset(c, 0, sizeof *c);
    memset(sup, 0, sizeof *sup);
    return cc_estim_init(&c->est, kind) < 0 ? CC_DESIGN_BAD_KIND : CC_DESIGN_OK;
}

void cc_design_foc(cc_foc_t *c, double n_p, double L_d, double L_q, double psi_f, double i_max,
                   double tau_max, double t_delay, long long n_align, long long n_settle,
                   double theta0, int raw, int align)
{
    cc_foc_init(c, n_p, L_d, L_q, psi_f, i_max, tau_max, t_delay, n_align, n_settle, theta0, raw,
                align);
}

void cc_design_pi(cc_foc_t *c, int which, double k_p, double k_i, double T_s, double k_t)
{
    cc_pi_init(which == 0 ? &c->pi_d : which == 1 ? &c->pi_q : &c->pi_w, k_p, k_i, T_s, k_t);
}

void cc_design_speed_filter(cc_foc_t *c, double b0, double b1, double a1)
{
    cc_fo_init(&c->lpf_w, b0, b1, a1);
}

void cc_design_polarity(cc_foc_t *c, double L_d, double T_s, double i_pulse, double u_frac)
{
    cc_polarity_init(&c->polarity, L_d, T_s, i_pulse, u_frac);
}

void cc_design_reference_model(cc_foc_t *c, double alpha_s, double n_p, double a_max, double T_s)
{
    cc_ref_init(&c->ref, alpha_s, n_p, a_max, T_s);
}

void cc_design_rotating(cc_foc_t *c, double V_h, double wT, double inv_norm, const double *pll,
                        const double *bpf, const double *lpf, const double *hpf,
                        const double *track, const double *quad)
{
    cc_rot_t *r = &c->est.rot;
    cc_rot_init(r, V_h, wT, inv_norm);
    cc_pll_init(&r->pll, pll[0], pll[1], pll[2]);
    cc_bq2_init(&r->bpf, bpf[0], bpf[1], bpf[2], bpf[3], bpf[4]);
    cc_fo_init(&r->lpf, lpf[0], lpf[1], lpf[2]);
    cc_fo2_init(&r->lpf_ab, lpf[0], lpf[1], lpf[2]);
    cc_fo2_init(&r->lpf_n, lpf[0], lpf[1], lpf[2]);
    if (quad != NULL)
        cc_bq2_init(&r->quad, quad[0], quad[1], quad[2], quad[3], quad[4]);
    else
        cc_bq2_init(&r->quad, 0.0, 0.0, 0.0, 0.0, 0.0);
    if (hpf != NULL)
        cc_fo2_init(&r->hpf, hpf[0], hpf[1], hpf[2]);
    else
        cc_fo2_init(&r->hpf, 0.0, 0.0, 0.0);
    if (track != NULL)
        cc_rot_tracking(r, track[0], track[1], track[2], track[3]);
}

void cc_design_mechanical(cc_foc_t *c, double T_s, double g1, double g2, double g3, double gt,
                          double l3)
{
    cc_rot_mechanical(&c->est.rot, T_s, g1, g2, g3, gt, l3);
}

void cc_design_measured(cc_foc_t *c, double amp_floor) { cc_rot_measured(&c->est.rot, amp_floor); }

void cc_design_accel_ff(cc_foc_t *c) { c->est.rot.accel_ff = 1; }

int cc_design_square_wave(cc_foc_t *c, int cic, long long M, double U_h, double t_comp,
                          double k_err, const double *obs)
{
    cc_sqw_t *q = &c->est.sqw;
    cc_est_t *e = c->est.kind == CC_EST_SQUARE_WAVE ? &c->est.out : &c->est.hyb.hf;
    if (cc_sqw_init(e, q, cic, M, U_h, t_comp, k_err) < 0)
        return CC_DESIGN_BAD_CIC;
    cc_luen_init(&q->obs, obs[0], obs[1], obs[2], obs[3], obs[4]);
    return CC_DESIGN_OK;
}

void cc_design_hybrid(cc_foc_t *c, const double *obs, const double *band, double T_s,
                      double n_p, double J)
{
    cc_estim_t *e = &c->est;
    cc_hyb_init(&e->out, &e->hyb, e->kind == CC_EST_HYBRID_SQUARE_WAVE, &e->rot, &e->sqw, T_s,
                n_p, J);
    cc_flux_init(&e->hyb.obs, obs[0], obs[1], obs[2], obs[3], obs[4], obs[5], obs[6], obs[7],
                 obs[8]);
    cc_band_init(&e->hyb.band, band[0], band[1], band[2], band[3]);
}

int cc_design_compensation(cc_foc_t *c, const double *dt, const double *cross,
                           const long long *n_offset, const double *hf)
{
    if (n_offset != NULL && *n_offset < 1)
        return CC_DESIGN_BAD_OFFSET;
    if (dt != NULL)
        cc_foc_dead_time(c, dt[0], dt[1], dt[2], dt[3], dt[4], dt[5] != 0.0, dt[6] != 0.0);
    if (cross != NULL)
        cc_foc_cross_saturation(c, cross[0], cross[1] != 0.0);
    if (n_offset != NULL)
        cc_foc_offset_calibration(c, *n_offset);
    if (hf != NULL)
        cc_rot_hf_model(&c->est.rot, hf[0], hf[1]);
    return CC_DESIGN_OK;
}

void cc_design_supervision(cc_sup_t *sup, double T_s, double i_rail, long long n_range,
                           double i_res, double du_stuck, long long n_stuck, double i_min,
                           double rho_open, long long n_open_min, long long n_open_max,
                           double u_uv, double u_ov, double u_hyst, long long n_dc)
{
    cc_sup_init(sup, T_s, i_rail, n_range, i_res, du_stuck, n_stuck, i_min, rho_open, n_open_min,
                n_open_max, u_uv, u_ov, u_hyst, n_dc);
}
