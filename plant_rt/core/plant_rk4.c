/* Classic RK4 (Kutta 1901; Butcher 2016) on the states of plant_machine.h. */
#include "plant_rk4.h"

#include <math.h>

#include "plant_const.h"

static const double RK4_O[4] = {0.0, 0.5, 0.5, 1.0};
static const double RK4_W[4] = {1.0, 2.0, 2.0, 1.0};

/* The energy flows of one stage over dt: terminals sum_x v_x i_x, copper
 * R_s sum_x i_x^2, air gap tau_e w_m, friction b w_m^2, load tau_L w_m. */
static void meter_stage(const plant_machine *m, plant_meter *e, int imposed, double i_d,
                        double i_q, double w_m, double th_m, const double vs[3], double tau_e,
                        double tau_L, double dt, plant_trig *t)
{
    double c, sn;
    plant_trig_of(t, m->n_p * th_m, &c, &sn);
    double i_al = c * i_d - sn * i_q;
    double i_be = sn * i_d + c * i_q;
    double i_a = i_al;
    double i_b = -0.5 * i_al + 0.5 * PLANT_SQRT3 * i_be;
    double i_c = -0.5 * i_al - 0.5 * PLANT_SQRT3 * i_be;
    e->e_in += dt * (vs[0] * i_a + vs[1] * i_b + vs[2] * i_c);
    e->e_cu += dt * m->R * (i_a * i_a + i_b * i_b + i_c * i_c);
    e->e_em += dt * tau_e * w_m;
    e->e_fric += dt * m->b * w_m * w_m;
    if (imposed) tau_L = tau_e - m->b * w_m;
    e->e_load += dt * tau_L * w_m;
    e->q_a += dt * i_a;
    e->q_b += dt * i_b;
    e->q_c += dt * i_c;
}

/* One classic RK4 step of length h (no subdivision). */
static void rk4_step(const plant_machine *m, plant_state *s, int imposed, int kind, int fx,
                     double h, double u_al, double u_be, double tau_L, double *ua, double *ub,
                     plant_meter *meter, const double v[3], plant_trig *t)
{
    double vs[3] = {0.0, 0.0, 0.0};
    if (meter) {
        vs[0] = v[0];
        vs[1] = v[1];
        vs[2] = v[2];
        if (kind == PLANT_STAGE_FLOAT) vs[fx] = 0.0;
    }
    int free_ = !imposed;
    double n_p = m->n_p;
    double i_d0 = s->i_d, i_q0 = s->i_q, w0 = s->w_m, th0 = s->th_m;
    double i_d = i_d0, i_q = i_q0, w = w0, th = th0;
    double s_d = 0.0, s_q = 0.0, s_w = 0.0, s_th = 0.0;
    double ua_sum = 0.0, ub_sum = 0.0;
    double d[5] = {0.0, 0.0, 0.0, 0.0, 0.0};
    for (int n = 0; n < 4; n++) {
        double o = RK4_O[n], wgt = RK4_W[n];
        if (o != 0.0) {
            i_d = i_d0 + o * h * d[0];
            i_q = i_q0 + o * h * d[1];
            th = th0 + o * h * w;
            w = w0 + o * h * d[2];
        }
        switch (kind) {
        case PLANT_STAGE_HOT: {
            double c, sn;
            plant_trig_of(t, n_p * th, &c, &sn);
            plant_machine_stage(m, i_d, i_q, w, c, sn, u_al, u_be, tau_L, free_, d);
            break;
        }
        case PLANT_STAGE_GENERAL:
            plant_machine_f(m, imposed, i_d, i_q, w, th, u_al, u_be, tau_L, t, d);
            ua_sum += wgt * u_al;
            ub_sum += wgt * u_be;
            break;
        default:
            plant_machine_f_float(m, imposed, i_d, i_q, w, th, u_al, u_be, fx, tau_L, t, d);
            vs[fx] = d[4];
            ua_sum += wgt * (u_al + (2.0 / 3.0) * d[4] * PLANT_COS_PHI[fx]);
            ub_sum += wgt * (u_be + (2.0 / 3.0) * d[4] * PLANT_SIN_PHI[fx]);
            break;
        }
        if (meter)
            meter_stage(m, meter, imposed, i_d, i_q, w, th, vs, d[3], tau_L, wgt * h / 6.0, t);
        s_d += wgt * d[0];
        s_q += wgt * d[1];
        s_w += wgt * d[2];
        s_th += wgt * w;
    }
    double h6 = h / 6.0;
    s->i_d = i_d0 + h6 * s_d;
    s->i_q = i_q0 + h6 * s_q;
    s->w_m = w0 + h6 * s_w;
    s->th_m = th0 + h6 * s_th;
    if (kind == PLANT_STAGE_HOT) {
        if (ua) *ua = u_al;
        if (ub) *ub = u_be;
    } else {
        *ua = ua_sum / 6.0;
        *ub = ub_sum / 6.0;
    }
}

/* The electromechanical mode's rate bound w_em (rad/s) at state s (plant_rk4.h). */
static double em_rate(const plant_machine *m, const plant_state *s)
{
    double fl[5];
    if (m->cross) {
        plant_flux_dq(m, s->i_d, s->i_q, fl);
    } else {
        plant_flux_d(m, s->i_d, &fl[0], &fl[2]);
        fl[1] = m->L_q * s->i_q;
        fl[3] = 0.0;
        fl[4] = m->L_q;
    }
    double mid = 0.5 * (fl[2] + fl[4]), hd = 0.5 * (fl[2] - fl[4]);
    double rad = sqrt(hd * hd + fl[3] * fl[3]);
    double L_lo = mid - rad, L_hi = mid + rad;
    if (!(L_lo > 0.0)) return HUGE_VAL;
    double psi = sqrt(fl[0] * fl[0] + fl[1] * fl[1]);
    double i_s = sqrt(s->i_d * s->i_d + s->i_q * s->i_q);
    return sqrt(m->n_p * m->k_tau * m->inv_J * psi * (psi + L_hi * i_s) / L_lo);
}

int plant_rk4_substeps(const plant_machine *m, const plant_state *s, int imposed, double h)
{
    double x = fabs(m->n_p * s->w_m) * h / PLANT_RK4_WH_MAX;
    if (!imposed && s->i_d * s->i_d + s->i_q * s->i_q > m->x_lim * m->x_lim)
        x += em_rate(m, s) * h / PLANT_RK4_WH_MAX;
    if (!(x > 1.0)) return 1; /* also a NaN state: one step, as before */
    if (x >= (double)PLANT_RK4_MAX_SPLIT) return PLANT_RK4_MAX_SPLIT;
    int n = (int)x; /* ceil(x) for 1 < x < PLANT_RK4_MAX_SPLIT */
    return n < x ? n + 1 : n;
}

void plant_rk4(const plant_machine *m, plant_state *s, int imposed, int kind, int fx, double h,
               double u_al, double u_be, double tau_L, double *ua, double *ub, plant_meter *meter,
               const double v[3], plant_trig *t)
{
    int n = plant_rk4_substeps(m, s, imposed, h);
    if (n == 1) {
        rk4_step(m, s, imposed, kind, fx, h, u_al, u_be, tau_L, ua, ub, meter, v, t);
        return;
    }
    /* n equal steps; the interval's mean stator voltage is the mean of theirs. */
    double hn = h / n, ua_sum = 0.0, ub_sum = 0.0;
    for (int k = 0; k < n; k++) {
        double ua_k = u_al, ub_k = u_be;
        rk4_step(m, s, imposed, kind, fx, hn, u_al, u_be, tau_L, &ua_k, &ub_k, meter, v, t);
        ua_sum += ua_k;
        ub_sum += ub_k;
    }
    if (ua) *ua = ua_sum / n;
    if (ub) *ub = ub_sum / n;
}
