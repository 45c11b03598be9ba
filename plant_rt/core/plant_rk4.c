/* Classic RK4 (Butcher 2016, eq. (235a)) on the states of plant_machine.h. */
#include "plant_rk4.h"

#include <math.h>

#include "plant_const.h"

static const double RK4_O[4] = {0.0, 0.5, 0.5, 1.0};
static const double RK4_W[4] = {1.0, 2.0, 2.0, 1.0};

void plant_rk4(const plant_machine *m, plant_state *s, int imposed, int kind, int fx, double h,
               double u_al, double u_be, double tau_L, double *ua, double *ub)
{
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
            double th_e = n_p * th;
            plant_machine_stage(m, i_d, i_q, w, cos(th_e), sin(th_e), u_al, u_be, tau_L, free_,
                                d);
            break;
        }
        case PLANT_STAGE_GENERAL:
            plant_machine_f(m, imposed, i_d, i_q, w, th, u_al, u_be, tau_L, d);
            ua_sum += wgt * u_al;
            ub_sum += wgt * u_be;
            break;
        default:
            plant_machine_f_float(m, imposed, i_d, i_q, w, th, u_al, u_be, fx, tau_L, d);
            ua_sum += wgt * (u_al + (2.0 / 3.0) * d[4] * PLANT_COS_PHI[fx]);
            ub_sum += wgt * (u_be + (2.0 / 3.0) * d[4] * PLANT_SIN_PHI[fx]);
            break;
        }
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
