/* The hybrids' hand-over band and blend (cc_hybrid.h). */
#include "cc_hybrid.h"
#include "cc_math.h"

void cc_band_init(cc_band_t *b, double w_lo, double w_mid, double w_hi, double h)
{
    b->w_lo = w_lo;
    b->w_mid = w_mid;
    b->w_hi = w_hi;
    b->h = h;
}

double cc_band_play(const cc_band_t *b, double y, double w)
{
    double s = w >= 0.0 ? w : -w;
    if (s < y)
        return s;
    if (s - b->h > y)
        return s - b->h;
    return y;
}

void cc_band_weights(const cc_band_t *b, double y, double *lam_out, double *g_out)
{
    double lam = (y - b->w_lo) / (b->w_mid - b->w_lo);
    double g = (b->w_hi - y) / (b->w_hi - b->w_mid);
    *lam_out = lam <= 0.0 ? 0.0 : (lam >= 1.0 ? 1.0 : lam);
    *g_out = g <= 0.0 ? 0.0 : (g >= 1.0 ? 1.0 : g);
}

void cc_hyb_init(cc_est_t *e, cc_hyb_t *h, int square, cc_rot_t *rot, cc_sqw_t *sqw,
                 double T_s, double n_p, double J)
{
    h->square = square;
    h->rot = rot;
    h->sqw = sqw;
    h->tr_T_s = T_s;
    h->tr_k_x = -n_p / J;
    h->hf.theta_hat = h->hf.w_hat = h->hf.err = h->hf.i_alpha_f = h->hf.i_beta_f = 0.0;
    e->theta_hat = e->w_hat = e->err = e->i_alpha_f = e->i_beta_f = 0.0;
    h->weight = 0.0;
    h->gain = 1.0;
    h->y = 0.0;
    h->saliency_offset = 0.0;
}

void cc_hyb_reset(cc_est_t *e, cc_hyb_t *h, double theta0)
{
    if (h->square)
        cc_sqw_reset(&h->hf, h->sqw, theta0);
    else
        cc_rot_reset(&h->hf, h->rot, theta0);
    cc_flux_reset(&h->obs, theta0, 0.0);
    e->theta_hat = h->hf.theta_hat;
    e->w_hat = 0.0;
    e->err = 0.0;
    h->weight = 0.0;
    h->gain = 1.0;
    h->y = 0.0;
}

/* the tracker's smooth speed: the PLL's integrator, or the Luenberger observer's speed
 * (square-wave's, or tt-dq's with observer = "mechanical") */
static double tracker_w_smooth(const cc_hyb_t *h)
{
    if (h->square)
        return h->sqw->obs.w_hat;
    return h->rot->mech ? h->rot->luen.w_hat : h->rot->pll.w_i;
}

/* a Luenberger tracker released without an acceleration error: its load state is what
 * the model dw/dt = n_p tau / J + x lacks */
static void luen_sync(const cc_hyb_t *h, cc_luen_t *o, double theta, double w, double accel,
                      double torque)
{
    cc_luen_reset(o, theta, w, accel + h->tr_k_x * torque);
}

static void tracker_sync(cc_hyb_t *h, double theta, double w, double accel, double torque)
{
    if (h->square) {
        luen_sync(h, &h->sqw->obs, theta, w, accel, torque);
    } else if (h->rot->mech) { /* tt-dq's mechanical observer: one period ahead */
        luen_sync(h, &h->rot->luen, theta + h->tr_T_s * w, w, accel, torque);
    } else { /* tt-dq's PLL: one period ahead */
        cc_pll_t *p = &h->rot->pll;
        p->theta_hat = cc_mod(theta + h->tr_T_s * w, CC_TWO_PI);
        p->w_hat = w;
        p->w_i = w;
    }
}

void cc_hyb_step(cc_est_t *e, cc_hyb_t *h, long long k, double i_alpha, double i_beta,
                 double u_alpha, double u_beta, double torque, int running,
                 double accel_ref)
{
    cc_est_t *hf = &h->hf;
    cc_flux_t *obs = &h->obs;
    if (h->square)
        cc_sqw_step(hf, h->sqw, i_alpha, i_beta, torque);
    else
        cc_tt_dq_step(hf, h->rot, k, i_alpha, i_beta, accel_ref);
    double lam = h->weight;
    double off = h->saliency_offset;
    double th, w, w_s, err;
    if (lam == 0.0) {
        w_s = tracker_w_smooth(h);
        th = off != 0.0 ? cc_mod(hf->theta_hat - off, CC_TWO_PI) : hf->theta_hat;
        cc_flux_step_slaved(obs, i_alpha, i_beta, u_alpha, u_beta, th, w_s);
        w = hf->w_hat;
        err = hf->err;
    } else {
        cc_flux_step(obs, i_alpha, i_beta, u_alpha, u_beta);
        double w_o = obs->w_hat;
        if (lam == 1.0) {
            th = obs->theta_hat;
            w = w_o;
            w_s = w_o;
            err = obs->eps;
            tracker_sync(h, th + off, w_o, obs->accel, torque);
        } else {
            double th_h = hf->theta_hat - off;
            double d = cc_mod(obs->theta_hat - th_h + M_PI, CC_TWO_PI) - M_PI;
            th = cc_mod(th_h + lam * d, CC_TWO_PI);
            double w_h = hf->w_hat;
            w = w_h + lam * (w_o - w_h);
            double w_t = tracker_w_smooth(h);
            w_s = w_t + lam * (w_o - w_t);
            double e_h = hf->err;
            err = e_h + lam * (obs->eps - e_h);
        }
    }
    e->theta_hat = th;
    e->w_hat = w;
    e->err = err;
    double g = h->gain;
    if (g == 1.0) {
        e->i_alpha_f = hf->i_alpha_f;
        e->i_beta_f = hf->i_beta_f;
    } else if (g == 0.0) {
        e->i_alpha_f = i_alpha;
        e->i_beta_f = i_beta;
    } else {
        e->i_alpha_f = i_alpha + g * (hf->i_alpha_f - i_alpha);
        e->i_beta_f = i_beta + g * (hf->i_beta_f - i_beta);
    }
    /* held below the band during the start-up at standstill (not running) */
    double y = running ? cc_band_play(&h->band, h->y, w_s) : 0.0;
    h->y = y;
    cc_band_weights(&h->band, y, &h->weight, &h->gain);
}

void cc_hyb_injection(const cc_hyb_t *h, double *u_a, double *u_b)
{
    double g = h->gain;
    if (g == 0.0) {
        *u_a = 0.0;
        *u_b = 0.0;
        return;
    }
    if (h->square)
        cc_sqw_injection(h->sqw, u_a, u_b);
    else
        cc_rot_injection(h->rot, u_a, u_b);
    if (g != 1.0) {
        *u_a = g * *u_a;
        *u_b = g * *u_b;
    }
}

void cc_hyb_hf_current_next(const cc_hyb_t *h, double *i_a, double *i_b)
{
    if (h->square) { /* the square wave predicts none */
        *i_a = 0.0;
        *i_b = 0.0;
        return;
    }
    double h_a, h_b;
    cc_rot_hf_current_next(h->rot, &h_a, &h_b);
    *i_a = h->gain * h_a;
    *i_b = h->gain * h_b;
}
