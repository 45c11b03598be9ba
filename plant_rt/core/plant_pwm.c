/* PWM timeline, dead time and device drops (plant_pwm.h). */
#include "plant_pwm.h"

#include "plant_const.h"

void plant_pwm_init(plant_pwm *p, double T_s, double t_dead, int peak)
{
    p->T_s = T_s;
    p->t_dead = t_dead;
    p->peak = peak != 0;
    int level = p->peak ? PLANT_LOW : PLANT_HIGH;
    for (int x = 0; x < 3; x++) {
        p->cmd[x] = level;
        p->dead_end[x] = 0.0;
    }
}

void plant_pwm_disable(plant_pwm *p)
{
    for (int x = 0; x < 3; x++) {
        p->cmd[x] = PLANT_OFF;
        p->dead_end[x] = 0.0;
    }
}

int plant_pwm_leg(plant_pwm *p, int x, double d, double *pt, int *ps)
{
    double T = p->T_s, t_d = p->t_dead;
    double pe[3];
    int pn[3];
    int np;
    if (d >= 1.0) {
        pe[0] = 0.0; pn[0] = PLANT_HIGH; np = 1;
    } else if (d <= 0.0) {
        pe[0] = 0.0; pn[0] = PLANT_LOW; np = 1;
    } else if (p->peak) {
        pe[0] = 0.0; pn[0] = PLANT_LOW;
        pe[1] = 0.5 * (1.0 - d) * T; pn[1] = PLANT_HIGH;
        pe[2] = 0.5 * (1.0 + d) * T; pn[2] = PLANT_LOW;
        np = 3;
    } else {
        pe[0] = 0.0; pn[0] = PLANT_HIGH;
        pe[1] = 0.5 * d * T; pn[1] = PLANT_LOW;
        pe[2] = T - 0.5 * d * T; pn[2] = PLANT_HIGH;
        np = 3;
    }
    double tol = 1e-9 * T;
    int level = p->cmd[x];
    double du = p->dead_end[x];
    int n = 0;
    pt[n] = 0.0;
    ps[n] = du > tol ? PLANT_DEAD : level;
    n++;
    for (int k = 0; k < np; k++) {
        double e = pe[k];
        int nw = pn[k];
        if (nw == level) continue;
        if (tol < du && du < e - tol) {
            pt[n] = du; ps[n] = level; n++;
        }
        level = nw;
        int state;
        if (t_d > 0.0) {
            du = e + t_d;
            state = PLANT_DEAD;
        } else {
            du = 0.0;
            state = nw;
        }
        if (pt[n - 1] == e) {
            ps[n - 1] = state;
        } else {
            pt[n] = e; ps[n] = state; n++;
        }
    }
    if (tol < du && du < T - tol) {
        pt[n] = du; ps[n] = level; n++;
        du = 0.0;
    }
    p->cmd[x] = level;
    p->dead_end[x] = du > T + tol ? du - T : 0.0;
    return n;
}

double plant_clamp_duty(double d)
{
    if (d > 1.0) return 1.0;
    if (d >= 0.0) return d;
    return 0.0;
}

double plant_dead_time_error(double i_x, double u_dc, double t_dead, double T_s)
{
    if (i_x > 0.0) return -u_dc * t_dead / T_s;
    if (i_x < 0.0) return u_dc * t_dead / T_s;
    return 0.0;
}

double plant_device_drop_error(double i_x, double d_x, double v_ce, double v_f)
{
    if (i_x > 0.0) return -(d_x * v_ce + (1.0 - d_x) * v_f);
    if (i_x < 0.0) return d_x * v_f + (1.0 - d_x) * v_ce;
    return 0.0;
}
