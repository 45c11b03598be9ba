/* The plant's period step (plant.h). */
#include "plant.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "plant_const.h"
#include "plant_rk4.h"

static int check_pars(const plant_pars *p)
{
    if (!(p->T_s > 0.0) || p->substeps < 1 || p->substeps > PLANT_MAX_SUBSTEPS) return 0;
    if (!(p->t_delay >= 0.0 && p->t_delay < p->T_s)) return 0;
    return 1;
}

/* The constants of the machine, the inverter and the DC link. */
static void set_constants(plant *pl, const plant_pars *p)
{
    plant_machine_init(&pl->m, &p->machine);
    plant_dclink_init(&pl->dc, p->u_dc, p->r_dc, p->c_dc);
    double i_max = p->machine.i_max;
    pl->i_eps = 1e-9 * (1.0 > i_max ? 1.0 : i_max);
    pl->v_ce = p->v_ce;
    pl->v_f = p->v_f;
    pl->t_dead = p->t_dead;
    pl->drops = p->v_ce > 0.0 || p->v_f > 0.0;
    pl->pwm.t_dead = p->t_dead;
    pl->avg_general = pl->dc.dynamic || pl->t_meas > 0.0;
    double r = PLANT_FLUX_RANGE * i_max;
    pl->out_r2 = r * r;
}

/* The period's end: count it when the current left the flux map's checked range. */
static void count_range(plant *pl)
{
    if (pl->x.i_d * pl->x.i_d + pl->x.i_q * pl->x.i_q > pl->out_r2) pl->n_out++;
}

int plant_init(plant *pl, const plant_pars *p)
{
    if (!check_pars(p)) return PLANT_ERR_PARS;
    memset(pl, 0, sizeof *pl);
    pl->T_s = p->T_s;
    pl->substeps = p->substeps;
    pl->h = p->T_s / p->substeps;
    pl->switching = p->switching != 0;
    /* the state at T_s - t_delay of each period is sampled at the next */
    pl->t_meas = p->t_delay > 0.0 ? p->T_s - p->t_delay : 0.0;
    plant_pwm_init(&pl->pwm, p->T_s, p->t_dead, p->peak);
    set_constants(pl, p);
    pl->u_dc = p->u_dc;
    /* the substep grid (load evaluated at each point) and the cuts of the
       switching model's sub-intervals: the grid after 0 and the sensor instant */
    pl->grid[0] = 0.0;
    for (int j = 1; j < p->substeps; j++) pl->grid[j] = j * pl->h;
    pl->n_grid = p->substeps;
    int nc = 0;
    for (int j = 1; j < p->substeps; j++) pl->cuts[nc++] = pl->grid[j];
    if (pl->t_meas > 0.0) {
        int dup = 0;
        for (int k = 0; k < nc; k++) dup |= pl->cuts[k] == pl->t_meas;
        if (!dup) {
            int k = nc++;
            while (k > 0 && pl->cuts[k - 1] > pl->t_meas) {
                pl->cuts[k] = pl->cuts[k - 1];
                k--;
            }
            pl->cuts[k] = pl->t_meas;
        }
    }
    pl->n_cuts = nc;
    /* the average model's segments: (t_start, t_end, grid index) */
    double t0 = 0.0;
    long j = 0;
    for (int k = 0; k <= nc; k++) {
        double t1 = k < nc ? pl->cuts[k] : p->T_s;
        while (j + 1 < pl->n_grid && t0 >= pl->grid[j + 1]) j++;
        pl->seg_a[k] = t0;
        pl->seg_b[k] = t1;
        pl->seg_j[k] = j;
        t0 = t1;
    }
    pl->n_segs = nc + 1;
    pl->load_const = 1;
    pl->tau_const = 0.0;
    return PLANT_OK;
}

int plant_set_pars(plant *pl, const plant_pars *p)
{
    if (!check_pars(p) || p->T_s != pl->T_s || p->substeps != pl->substeps
        || (p->t_delay > 0.0 ? p->T_s - p->t_delay : 0.0) != pl->t_meas
        || (p->switching != 0) != pl->switching || (p->peak != 0) != pl->pwm.peak)
        return PLANT_ERR_PARS;
    set_constants(pl, p);
    if (!pl->dc.dynamic) pl->u_dc = p->u_dc;
    return PLANT_OK;
}

int plant_set_legs(plant *pl, const int leg[3])
{
    for (int x = 0; x < 3; x++)
        if (leg[x] < PLANT_LEG_OK || leg[x] > PLANT_LEG_OPEN_LOWER) return PLANT_ERR_PARS;
    pl->any_leg = 0;
    for (int x = 0; x < 3; x++) {
        pl->leg[x] = leg[x];
        pl->any_leg |= leg[x] != PLANT_LEG_OK;
    }
    return PLANT_OK;
}

void plant_currents(const plant *pl, double i[3])
{
    /* the memo is a cache of the state's angle, not state: reading the currents
     * through it changes no result (plant_trig) */
    plant_currents_abc(&pl->m, &pl->x, (plant_trig *)&pl->trig, i);
}

/* ---------------------------------------------------------------- helpers */
static double tau_load(plant *pl, double t)
{
    if (pl->imposed) return 0.0;
    if (pl->load_const) return pl->tau_const;
    if (pl->err) return 0.0;
    double v;
    if (pl->load(pl->load_ctx, t, pl->x.w_m, &v)) {
        pl->err = 1;
        return 0.0;
    }
    return v;
}

static void record_meas(plant *pl, const double i[3])
{
    pl->meas[0] = i[0];
    pl->meas[1] = i[1];
    pl->meas[2] = i[2];
    pl->meas[3] = pl->u_dc;
}

/* Clarke transform of the pole voltages (amplitude invariant). */
static double alpha(double v_a, double v_b, double v_c)
{
    return (2.0 * v_a - v_b - v_c) / 3.0;
}

static double beta(double v_b, double v_c)
{
    return (v_b - v_c) * PLANT_INV_SQRT3;
}

/* One RK4 step with constant pole voltages; the stator voltage in alpha-beta. */
static void rk4_const(plant *pl, double h, const double v[3], double tau_L, double *ua, double *ub)
{
    double u_al = alpha(v[0], v[1], v[2]);
    double u_be = beta(v[1], v[2]);
    if (pl->metering)
        plant_rk4(&pl->m, &pl->x, pl->imposed, PLANT_STAGE_GENERAL, -1, h, u_al, u_be, tau_L, ua,
                  ub, &pl->meter, v, &pl->trig);
    else
        plant_rk4(&pl->m, &pl->x, pl->imposed, PLANT_STAGE_HOT, -1, h, u_al, u_be, tau_L, ua, ub,
                  NULL, NULL, &pl->trig);
}

/* One RK4 step with phase fx floating: its pole voltage solved at each stage. */
static void rk4_float(plant *pl, double h, const double v[3], int fx, double tau_L, double *ua,
                      double *ub)
{
    double vs[3] = {v[0], v[1], v[2]};
    vs[fx] = 0.0;
    double u_al = alpha(vs[0], vs[1], vs[2]);
    double u_be = beta(vs[1], vs[2]);
    plant_rk4(&pl->m, &pl->x, pl->imposed, PLANT_STAGE_FLOAT, fx, h, u_al, u_be, tau_L, ua, ub,
              pl->metering ? &pl->meter : NULL, v, &pl->trig);
}

static double dw_open(const plant *pl, double tau_L, double w)
{
    return (-tau_L - pl->m.b * w) * pl->m.inv_J;
}

/* All currents zero: mechanics only (RK4), the terminal voltage is the
 * back-EMF j w_e psi_d(0) e^{j theta_e}, its Simpson mean over h. */
static void open_circuit(plant *pl, double h, double tau_L, double *ua_out, double *ub_out)
{
    double w0 = pl->x.w_m, th0 = pl->x.th_m, w1;
    if (!pl->imposed) {
        double k1 = dw_open(pl, tau_L, w0);
        double k2 = dw_open(pl, tau_L, w0 + 0.5 * h * k1);
        double k3 = dw_open(pl, tau_L, w0 + 0.5 * h * k2);
        double k4 = dw_open(pl, tau_L, w0 + h * k3);
        w1 = w0 + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
    } else {
        w1 = w0;
    }
    double th1 = th0 + 0.5 * h * (w0 + w1);
    if (pl->metering) {
        plant_meter *e = &pl->meter;
        double w_mid = 0.5 * (w0 + w1);
        if (!pl->imposed) {
            e->e_load += h * tau_L * w_mid;
            e->e_fric += h * pl->m.b * w_mid * w_mid;
        } else {
            e->e_load -= h * pl->m.b * w0 * w0;
            e->e_fric += h * pl->m.b * w0 * w0;
        }
    }
    double psi0, L0;
    plant_flux_d(&pl->m, 0.0, &psi0, &L0);
    double n_p = pl->m.n_p;
    double ua = 0.0, ub = 0.0;
    const double wg[3] = {1.0, 4.0, 1.0};
    double ths[3] = {th0, 0.5 * (th0 + th1), th1};
    double ws[3] = {w0, 0.5 * (w0 + w1), w1};
    for (int n = 0; n < 3; n++) {
        double amp = n_p * ws[n] * psi0;
        ua -= wg[n] * amp * sin(n_p * ths[n]);
        ub += wg[n] * amp * cos(n_p * ths[n]);
    }
    pl->x.w_m = w1;
    pl->x.th_m = th1;
    *ua_out = ua / 6.0;
    *ub_out = ub / 6.0;
}

static void dc_update(plant *pl, double h, double i_dc, double i_dc_end)
{
    plant_dclink_update(&pl->dc, &pl->u_dc, h, i_dc, i_dc_end);
}

/* ------------------------------------------------------ average model */
/* The fast path: stiff DC link, no sensor delay. */
static void step_fast(plant *pl, double d_a, double d_b, double d_c, double t0)
{
    double u_dc = pl->u_dc;
    double v_a = plant_clamp_duty(d_a) * u_dc;
    double v_b = plant_clamp_duty(d_b) * u_dc;
    double v_c = plant_clamp_duty(d_c) * u_dc;
    double t_dead = pl->t_dead;
    double i[3];
    if (t_dead > 0.0) {
        /* only a switching leg has dead time: one held at a rail keeps its switch on */
        plant_currents(pl, i);
        if (0.0 < v_a && v_a < u_dc) v_a += plant_dead_time_error(i[0], u_dc, t_dead, pl->T_s);
        if (0.0 < v_b && v_b < u_dc) v_b += plant_dead_time_error(i[1], u_dc, t_dead, pl->T_s);
        if (0.0 < v_c && v_c < u_dc) v_c += plant_dead_time_error(i[2], u_dc, t_dead, pl->T_s);
    }
    if (pl->drops) {
        /* v_x / u_dc is the leg's time on the positive rail after dead time */
        plant_currents(pl, i);
        double a = v_a + plant_device_drop_error(i[0], v_a / u_dc, pl->v_ce, pl->v_f);
        double b = v_b + plant_device_drop_error(i[1], v_b / u_dc, pl->v_ce, pl->v_f);
        double c = v_c + plant_device_drop_error(i[2], v_c / u_dc, pl->v_ce, pl->v_f);
        v_a = a;
        v_b = b;
        v_c = c;
    }
    double u_al = alpha(v_a, v_b, v_c);
    double u_be = beta(v_b, v_c);
    double h = pl->h;
    double v[3] = {v_a, v_b, v_c};
    for (int j = 0; j < pl->substeps; j++) {
        double tau_L = tau_load(pl, t0 + j * h);
        if (pl->metering) {
            double ua, ub;
            plant_rk4(&pl->m, &pl->x, pl->imposed, PLANT_STAGE_GENERAL, -1, h, u_al, u_be, tau_L,
                      &ua, &ub, &pl->meter, v, &pl->trig);
        } else {
            plant_rk4(&pl->m, &pl->x, pl->imposed, PLANT_STAGE_HOT, -1, h, u_al, u_be, tau_L, NULL,
                      NULL, NULL, NULL, &pl->trig);
        }
    }
    pl->u_al = u_al;
    pl->u_be = u_be;
}

/* With a dynamic DC link or a sensor delay: one RK4 step per segment, the
 * pole voltages recomputed on each from the link voltage at its start. */
static void step_average_general(plant *pl, double d_a, double d_b, double d_c, double t0)
{
    d_a = plant_clamp_duty(d_a);
    d_b = plant_clamp_duty(d_b);
    d_c = plant_clamp_duty(d_c);
    double t_dead = pl->t_dead, T = pl->T_s;
    double i[3];
    plant_currents(pl, i);
    if (t_dead > 0.0) {
        /* effective fractions on the positive rail after dead time */
        double r = t_dead / T;
        if (0.0 < d_a && d_a < 1.0) d_a += plant_dead_time_error(i[0], 1.0, r, 1.0);
        if (0.0 < d_b && d_b < 1.0) d_b += plant_dead_time_error(i[1], 1.0, r, 1.0);
        if (0.0 < d_c && d_c < 1.0) d_c += plant_dead_time_error(i[2], 1.0, r, 1.0);
    }
    double e_a = 0.0, e_b = 0.0, e_c = 0.0;
    if (pl->drops) {
        e_a = plant_device_drop_error(i[0], d_a, pl->v_ce, pl->v_f);
        e_b = plant_device_drop_error(i[1], d_b, pl->v_ce, pl->v_f);
        e_c = plant_device_drop_error(i[2], d_c, pl->v_ce, pl->v_f);
    }
    double h_grid = pl->h, s_al = 0.0, s_be = 0.0, tau_L = 0.0, i0 = 0.0;
    long j_load = -1;
    for (int n = 0; n < pl->n_segs; n++) {
        double ta = pl->seg_a[n], tb = pl->seg_b[n];
        long j = pl->seg_j[n];
        if (j != j_load) {
            tau_L = tau_load(pl, t0 + j * h_grid);
            j_load = j;
        }
        double h = tb - ta;
        if (pl->dc.dynamic) {
            i0 = d_a * i[0] + d_b * i[1] + d_c * i[2];
            if (pl->dc.c_dc == 0.0) pl->u_dc = plant_dclink_algebraic(&pl->dc, i0);
        }
        double u_dc = pl->u_dc;
        double v[3] = {d_a * u_dc + e_a, d_b * u_dc + e_b, d_c * u_dc + e_c};
        double u_al = alpha(v[0], v[1], v[2]);
        double u_be = beta(v[1], v[2]);
        double ua, ub;
        rk4_const(pl, h, v, tau_L, &ua, &ub);
        s_al += h * u_al;
        s_be += h * u_be;
        plant_currents(pl, i);
        if (pl->dc.dynamic) {
            double i1 = d_a * i[0] + d_b * i[1] + d_c * i[2];
            dc_update(pl, h, 0.5 * (i0 + i1), i1);
        }
        if (tb == pl->t_meas) record_meas(pl, i);
    }
    pl->u_al = s_al / T;
    pl->u_be = s_be / T;
}

/* ------------------------------------------- average model, open legs */
static void dead_with_clamp(plant *pl, double h, const double v[3], const int cond[3],
                            double tau_L, const double i_abc[3], double *ua_out, double *ub_out,
                            double i_out[3]);

/* The pole voltages of one average-model interval with open-leg faults
 * (plant_leg.h): healthy legs at de u_dc + e, faulted legs by
 * plant_leg_average. */
static void legs_average(const plant *pl, const double de[3], const double e[3],
                         const double i[3], double u_dc, plant_leg_avg la[3])
{
    for (int x = 0; x < 3; x++) {
        double v_norm = de[x] * u_dc + e[x];
        if (pl->leg[x] == PLANT_LEG_OK) {
            la[x].v = v_norm;
            la[x].cond = 0;
            la[x].flt = 0;
            la[x].pos = de[x];
        } else {
            plant_leg_average(pl->leg[x], i[x], pl->i_eps, v_norm, de[x], u_dc, pl->v_f, &la[x]);
        }
    }
}

/* The average model with an open-leg fault: one RK4 step per segment of
 * the general grid; a faulted leg whose current reaches zero inside a
 * segment is clamped there (dead_with_clamp) and floats for its rest; a
 * floating leg whose solved voltage leaves [lo, hi] conducts at that bound
 * (plant_leg_average); two floating legs leave no current path. */
static void step_average_legs(plant *pl, double d_a, double d_b, double d_c, double t0)
{
    double de[3] = {plant_clamp_duty(d_a), plant_clamp_duty(d_b), plant_clamp_duty(d_c)};
    double t_dead = pl->t_dead, T = pl->T_s;
    double i[3], e[3] = {0.0, 0.0, 0.0};
    plant_currents(pl, i);
    for (int x = 0; x < 3; x++) {
        if (t_dead > 0.0 && 0.0 < de[x] && de[x] < 1.0)
            de[x] += plant_dead_time_error(i[x], 1.0, t_dead / T, 1.0);
        if (pl->drops) e[x] = plant_device_drop_error(i[x], de[x], pl->v_ce, pl->v_f);
    }
    double h_grid = pl->h, s_al = 0.0, s_be = 0.0, tau_L = 0.0;
    long j_load = -1;
    for (int n = 0; n < pl->n_segs; n++) {
        double ta = pl->seg_a[n], tb = pl->seg_b[n];
        long j = pl->seg_j[n];
        if (j != j_load) {
            tau_L = tau_load(pl, t0 + j * h_grid);
            j_load = j;
        }
        double h = tb - ta;
        plant_leg_avg la[3];
        legs_average(pl, de, e, i, pl->u_dc, la);
        double i0 = la[0].pos * i[0] + la[1].pos * i[1] + la[2].pos * i[2];
        if (pl->dc.dynamic && pl->dc.c_dc == 0.0) {
            pl->u_dc = plant_dclink_algebraic(&pl->dc, i0);
            legs_average(pl, de, e, i, pl->u_dc, la);
        }
        double v[3] = {la[0].v, la[1].v, la[2].v};
        int cond[3] = {la[0].cond, la[1].cond, la[2].cond};
        int fl[3], n_float = 0;
        for (int x = 0; x < 3; x++)
            if (la[x].flt) fl[n_float++] = x;
        double ua, ub, i_new[3];
        if (n_float >= 2) {
            /* no current path: the currents stay zero over the segment */
            pl->x.i_d = 0.0;
            pl->x.i_q = 0.0;
            open_circuit(pl, h, tau_L, &ua, &ub);
            i_new[0] = i_new[1] = i_new[2] = 0.0;
        } else {
            int fx = -1;
            if (n_float == 1) {
                int x = fl[0];
                double vf[3] = {v[0], v[1], v[2]}, d[5];
                vf[x] = 0.0;
                plant_machine_f_float(&pl->m, pl->imposed, pl->x.i_d, pl->x.i_q, pl->x.w_m,
                                      pl->x.th_m, alpha(vf[0], vf[1], vf[2]), beta(vf[1], vf[2]),
                                      x, tau_L, &pl->trig, d);
                if (d[4] < la[x].lo) {
                    v[x] = la[x].lo;
                    la[x].pos = la[x].pos_lo;
                } else if (d[4] > la[x].hi) {
                    v[x] = la[x].hi;
                    la[x].pos = la[x].pos_hi;
                } else {
                    fx = x;
                }
            }
            if (fx >= 0) {
                rk4_float(pl, h, v, fx, tau_L, &ua, &ub);
                plant_zero_phase(&pl->m, &pl->x, fx);
                plant_currents(pl, i_new);
            } else if (cond[0] == 0 && cond[1] == 0 && cond[2] == 0) {
                rk4_const(pl, h, v, tau_L, &ua, &ub);
                plant_currents(pl, i_new);
            } else {
                dead_with_clamp(pl, h, v, cond, tau_L, i, &ua, &ub, i_new);
            }
        }
        s_al += h * ua;
        s_be += h * ub;
        if (pl->dc.dynamic) {
            double i1 = la[0].pos * i_new[0] + la[1].pos * i_new[1] + la[2].pos * i_new[2];
            dc_update(pl, h, 0.5 * (i0 + i1), i1);
        }
        memcpy(i, i_new, sizeof i_new);
        if (tb == pl->t_meas) record_meas(pl, i);
    }
    pl->u_al = s_al / T;
    pl->u_be = s_be / T;
}

/* ------------------------------------------------------ switching model */
/* A sub-interval with diode-conducting dead legs: integrate it; if a
 * diode's current has reversed, redo the step up to the (linearly
 * interpolated) zero of the first such phase, clamp that phase to zero and
 * integrate the rest with it floating. */
static void dead_with_clamp(plant *pl, double h, const double v[3], const int cond[3],
                            double tau_L, const double i_abc[3], double *ua_out, double *ub_out,
                            double i_out[3])
{
    plant_state saved = pl->x;
    plant_meter saved_meter = pl->meter;
    double ua, ub;
    rk4_const(pl, h, v, tau_L, &ua, &ub);
    double i_new[3];
    plant_currents(pl, i_new);
    int first = -1;
    double frac = 1.0;
    for (int x = 0; x < 3; x++) {
        int c = cond[x];
        if (c != 0 && i_new[x] * c < 0.0) {
            double f = i_abc[x] / (i_abc[x] - i_new[x]);
            if (f < frac) {
                frac = f;
                first = x;
            }
        }
    }
    if (first < 0) {
        *ua_out = ua;
        *ub_out = ub;
        memcpy(i_out, i_new, sizeof i_new);
        return;
    }
    pl->x = saved;
    pl->meter = saved_meter;
    double h1 = frac * h;
    double ua1 = ua, ub1 = ub;
    if (h1 > 0.0) rk4_const(pl, h1, v, tau_L, &ua1, &ub1);
    plant_zero_phase(&pl->m, &pl->x, first);
    double h2 = h - h1;
    double ua2, ub2;
    rk4_float(pl, h2, v, first, tau_L, &ua2, &ub2);
    plant_zero_phase(&pl->m, &pl->x, first);
    *ua_out = (h1 * ua1 + h2 * ua2) / h;
    *ub_out = (h1 * ub1 + h2 * ub2) / h;
    plant_currents(pl, i_out);
}

/* One sub-interval with constant gate states (plant.h); i_abc in: at the
 * start, out: at the end. Pole voltages:
 *   upper on: u_dc - v_ce (i > 0) or u_dc + v_f (i < 0)
 *   lower on: -v_f (i > 0) or +v_ce (i < 0)
 *   dead:     -v_f (i > 0, lower diode) or u_dc + v_f (i < 0, upper diode), else floating */
static void sw_interval(plant *pl, double h, const int states[3], double tau_L, double i_abc[3],
                        double *ua, double *ub)
{
    double v_ce = pl->v_ce, v_f = pl->v_f, eps = pl->i_eps;
    double i_dc0 = 0.0;
    if (pl->dc.dynamic) {
        /* legs on the positive rail: upper switch on, or dead with the upper diode conducting */
        for (int x = 0; x < 3; x++)
            if (states[x] == PLANT_HIGH || (states[x] == PLANT_DEAD && i_abc[x] < -eps))
                i_dc0 += i_abc[x];
        if (pl->dc.c_dc == 0.0) pl->u_dc = plant_dclink_algebraic(&pl->dc, i_dc0);
    }
    double u_dc = pl->u_dc;
    double v[3] = {0.0, 0.0, 0.0};
    int cond[3] = {0, 0, 0}; /* a dead leg's diode: +1 lower, -1 upper */
    int upper[3] = {0, 0, 0};
    int floating[3];
    int n_float = 0;
    for (int x = 0; x < 3; x++) {
        int st = states[x];
        double i = i_abc[x];
        if (st == PLANT_HIGH) {
            upper[x] = 1;
            v[x] = i > eps ? u_dc - v_ce : (i < -eps ? u_dc + v_f : u_dc);
        } else if (st == PLANT_DEAD) {
            if (i > eps) {
                v[x] = -v_f;
                cond[x] = 1;
            } else if (i < -eps) {
                v[x] = u_dc + v_f;
                cond[x] = -1;
                upper[x] = 1;
            } else {
                floating[n_float++] = x;
            }
        } else {
            v[x] = i > eps ? -v_f : (i < -eps ? v_ce : 0.0);
        }
    }
    if (n_float >= 2) {
        /* no current path: the currents stay zero for the rest of the dead interval */
        pl->x.i_d = 0.0;
        pl->x.i_q = 0.0;
        open_circuit(pl, h, tau_L, ua, ub);
        if (pl->dc.dynamic) dc_update(pl, h, 0.0, 0.0);
        i_abc[0] = i_abc[1] = i_abc[2] = 0.0;
        return;
    }
    int fx = -1;
    if (n_float) {
        int x = floating[0];
        double d[5];
        plant_machine_f_float(&pl->m, pl->imposed, pl->x.i_d, pl->x.i_q, pl->x.w_m, pl->x.th_m,
                              alpha(v[0], v[1], v[2]), beta(v[1], v[2]), x, tau_L,
                              &pl->trig, d);
        double v_x = d[4];
        if (pl->leg[x] == PLANT_LEG_OPEN_PHASE) { /* open: no diode takes it again */
            fx = x;
        } else if (v_x > u_dc + v_f) { /* the upper diode takes the current */
            v[x] = u_dc + v_f;
            cond[x] = -1;
            upper[x] = 1;
        } else if (v_x < -v_f) { /* the lower diode takes it */
            v[x] = -v_f;
            cond[x] = 1;
        } else {
            fx = x;
        }
    }
    double i_new[3];
    if (fx >= 0) {
        rk4_float(pl, h, v, fx, tau_L, ua, ub);
        plant_zero_phase(&pl->m, &pl->x, fx);
        plant_currents(pl, i_new);
    } else if (cond[0] == 0 && cond[1] == 0 && cond[2] == 0) {
        rk4_const(pl, h, v, tau_L, ua, ub);
        plant_currents(pl, i_new);
    } else {
        dead_with_clamp(pl, h, v, cond, tau_L, i_abc, ua, ub, i_new);
    }
    if (pl->dc.dynamic) {
        double i_dc1 = 0.0;
        for (int x = 0; x < 3; x++)
            if (upper[x]) i_dc1 += i_new[x];
        dc_update(pl, h, 0.5 * (i_dc0 + i_dc1), i_dc1);
    }
    memcpy(i_abc, i_new, sizeof i_new);
}

/* The times ascending, in place, by insertion (a few dozen at most, each leg's already in
 * order): cheaper than qsort's calls through a comparator at this size. The times are
 * finite and positive (plant_clamp_duty maps NaN to 0, only change points after 0 enter),
 * so the ascending order is unique and the result is qsort's, bit for bit. */
static void sort_times(double *a, int n)
{
    for (int i = 1; i < n; i++) {
        double x = a[i];
        int j = i;
        while (j > 0 && a[j - 1] > x) {
            a[j] = a[j - 1];
            j--;
        }
        a[j] = x;
    }
}

static void step_switching(plant *pl, double d_a, double d_b, double d_c, double t0)
{
    double T = pl->T_s;
    double pt[3][PLANT_MAX_PTS];
    int ps[3][PLANT_MAX_PTS];
    int np[3];
    double dd[3] = {plant_clamp_duty(d_a), plant_clamp_duty(d_b), plant_clamp_duty(d_c)};
    for (int x = 0; x < 3; x++) np[x] = plant_pwm_leg(&pl->pwm, x, dd[x], pt[x], ps[x]);
    /* sorted(set): T, every change point after 0, the cuts */
    double times[1 + 3 * PLANT_MAX_PTS + PLANT_MAX_SUBSTEPS];
    int nt = 0;
    times[nt++] = T;
    for (int x = 0; x < 3; x++)
        for (int k = 0; k < np[x]; k++)
            if (pt[x][k] > 0.0) times[nt++] = pt[x][k];
    for (int k = 0; k < pl->n_cuts; k++) times[nt++] = pl->cuts[k];
    sort_times(times, nt);
    int ja = 0, jb = 0, jc = 0;
    int st[3] = {ps[0][0], ps[1][0], ps[2][0]};
    int j = 0;
    double tau_L = tau_load(pl, t0);
    double i_abc[3];
    plant_currents(pl, i_abc);
    double s_al = 0.0, s_be = 0.0, t_a = 0.0;
    for (int n = 0; n < nt; n++) {
        double t1 = times[n];
        if (n > 0 && t1 == times[n - 1]) continue; /* the set removed it */
        while (ja + 1 < np[0] && pt[0][ja + 1] <= t_a) st[0] = ps[0][++ja];
        while (jb + 1 < np[1] && pt[1][jb + 1] <= t_a) st[1] = ps[1][++jb];
        while (jc + 1 < np[2] && pt[2][jc + 1] <= t_a) st[2] = ps[2][++jc];
        if (!(t1 > t_a)) continue;
        double ta = t_a, tb = t1;
        t_a = t1;
        while (j + 1 < pl->n_grid && ta >= pl->grid[j + 1]) {
            j++;
            tau_L = tau_load(pl, t0 + pl->grid[j]);
        }
        double h = tb - ta, ua, ub;
        if (pl->any_leg) {
            int sg[3];
            for (int x = 0; x < 3; x++) sg[x] = plant_leg_gate(pl->leg[x], st[x]);
            sw_interval(pl, h, sg, tau_L, i_abc, &ua, &ub);
        } else {
            sw_interval(pl, h, st, tau_L, i_abc, &ua, &ub);
        }
        s_al += h * ua;
        s_be += h * ub;
        if (tb == pl->t_meas) record_meas(pl, i_abc);
    }
    pl->u_al = s_al / T;
    pl->u_be = s_be / T;
}

/* -------------------------------------------------- the disabled bridge */
void plant_back_emf(const plant *pl, double e[3])
{
    double psi0, L0;
    plant_flux_d(&pl->m, 0.0, &psi0, &L0);
    double th_e = pl->m.n_p * pl->x.th_m;
    double amp = -pl->m.n_p * pl->x.w_m * psi0;
    e[0] = amp * sin(th_e);
    e[1] = amp * sin(th_e - PLANT_TWO_PI / 3.0);
    e[2] = amp * sin(th_e + PLANT_TWO_PI / 3.0);
}

/* One RK4 step of the diode bridge: general stage, or phase fx floating. */
static void rk4_bridge(plant *pl, double h, const double vs[3], int fx, double tau_L, double *ua,
                       double *ub)
{
    if (fx >= 0) {
        rk4_float(pl, h, vs, fx, tau_L, ua, ub);
        return;
    }
    plant_rk4(&pl->m, &pl->x, pl->imposed, PLANT_STAGE_GENERAL, -1, h, alpha(vs[0], vs[1], vs[2]),
              beta(vs[1], vs[2]), tau_L, ua, ub, pl->metering ? &pl->meter : NULL, vs, &pl->trig);
}

/* One substep with all switches open; the mean stator voltage in alpha-beta. */
static void substep_off(plant *pl, double h, double tau_L, double *ua, double *ub)
{
    double u_dc = pl->u_dc, eps = pl->i_eps;
    double i[3];
    plant_currents(pl, i);
    int sgn[3] = {0, 0, 0};
    for (int x = 0; x < 3; x++) {
        if (i[x] > eps)
            sgn[x] = 1;
        else if (i[x] < -eps)
            sgn[x] = -1;
    }
    int n_cond = (sgn[0] != 0) + (sgn[1] != 0) + (sgn[2] != 0);
    int fx = -1;
    if (n_cond < 2) {
        /* all currents zero: open circuit unless the line back-EMF exceeds u_dc */
        pl->x.i_d = 0.0;
        pl->x.i_q = 0.0;
        double e[3];
        plant_back_emf(pl, e);
        /* an open phase takes no part in the bridge */
        int hi = -1, lo = -1;
        for (int x = 0; x < 3; x++) {
            if (pl->leg[x] == PLANT_LEG_OPEN_PHASE) continue;
            if (hi < 0 || e[x] > e[hi]) hi = x;
            if (lo < 0 || e[x] < e[lo]) lo = x;
        }
        if (hi < 0 || hi == lo || e[hi] - e[lo] <= u_dc) {
            open_circuit(pl, h, tau_L, ua, ub);
            return;
        }
        sgn[0] = sgn[1] = sgn[2] = 0;
        sgn[hi] = -1;
        sgn[lo] = 1;
        fx = 3 - hi - lo;
    } else if (n_cond == 2) {
        fx = sgn[0] == 0 ? 0 : (sgn[1] == 0 ? 1 : 2);
    }
    double vs[3];
    for (int x = 0; x < 3; x++) vs[x] = sgn[x] > 0 ? 0.0 : u_dc;
    if (fx >= 0 && n_cond == 2 && pl->leg[fx] != PLANT_LEG_OPEN_PHASE) {
        /* is the floating phase's pole voltage inside the rails? */
        double vf[3] = {vs[0], vs[1], vs[2]};
        vf[fx] = 0.0;
        double d[5];
        plant_machine_f_float(&pl->m, pl->imposed, pl->x.i_d, pl->x.i_q, pl->x.w_m, pl->x.th_m,
                              alpha(vf[0], vf[1], vf[2]), beta(vf[1], vf[2]), fx, tau_L,
                              &pl->trig, d);
        double v_x = d[4];
        if (v_x > u_dc) {
            sgn[fx] = -1;
            fx = -1;
        } else if (v_x < 0.0) {
            sgn[fx] = 1;
            fx = -1;
        }
        for (int x = 0; x < 3; x++) vs[x] = sgn[x] > 0 ? 0.0 : u_dc;
    }
    rk4_bridge(pl, h, vs, fx, tau_L, ua, ub);
    /* current zeros within the substep */
    double i_new[3];
    plant_currents(pl, i_new);
    int flipped[3], n_flip = 0, n_sgn = 0;
    for (int x = 0; x < 3; x++) {
        if (sgn[x] != 0) {
            n_sgn++;
            if (i_new[x] * sgn[x] <= 0.0) flipped[n_flip++] = x;
        }
    }
    if (n_sgn - n_flip < 2) {
        pl->x.i_d = 0.0;
        pl->x.i_q = 0.0;
    } else {
        for (int k = 0; k < n_flip; k++) plant_zero_phase(&pl->m, &pl->x, flipped[k]);
        if (fx >= 0) plant_zero_phase(&pl->m, &pl->x, fx);
    }
}

static double neg_part(double x)
{
    return 0.0 < x ? 0.0 : x; /* Python's min(x, 0.0) */
}

/* The DC link receives i_dc = sum_x min(i_x, 0) (negative: it charges). */
static void step_off_general(plant *pl, double t0)
{
    double T = pl->T_s, h_grid = pl->h, s_al = 0.0, s_be = 0.0, tau_L = 0.0;
    long j_load = -1;
    double i[3];
    plant_currents(pl, i);
    for (int n = 0; n < pl->n_segs; n++) {
        double ta = pl->seg_a[n], tb = pl->seg_b[n];
        long j = pl->seg_j[n];
        if (j != j_load) {
            tau_L = tau_load(pl, t0 + j * h_grid);
            j_load = j;
        }
        double h = tb - ta;
        double i0 = neg_part(i[0]) + neg_part(i[1]) + neg_part(i[2]);
        if (pl->dc.dynamic && pl->dc.c_dc == 0.0) pl->u_dc = plant_dclink_algebraic(&pl->dc, i0);
        double ua, ub;
        substep_off(pl, h, tau_L, &ua, &ub);
        s_al += h * ua;
        s_be += h * ub;
        plant_currents(pl, i);
        if (pl->dc.dynamic) {
            double i1 = neg_part(i[0]) + neg_part(i[1]) + neg_part(i[2]);
            dc_update(pl, h, 0.5 * (i0 + i1), i1);
        }
        if (tb == pl->t_meas) record_meas(pl, i);
    }
    pl->u_al = s_al / T;
    pl->u_be = s_be / T;
}

int plant_step_off(plant *pl, double t0)
{
    pl->err = 0;
    pl->meter.q_a = pl->meter.q_b = pl->meter.q_c = 0.0;
    plant_pwm_disable(&pl->pwm);
    if (!(pl->dc.dynamic || pl->t_meas > 0.0)) {
        double h = pl->h, sa = 0.0, sb = 0.0;
        for (int j = 0; j < pl->substeps; j++) {
            double ua, ub;
            substep_off(pl, h, tau_load(pl, t0 + j * h), &ua, &ub);
            sa += ua;
            sb += ub;
        }
        pl->u_al = sa / pl->substeps;
        pl->u_be = sb / pl->substeps;
    } else {
        step_off_general(pl, t0);
    }
    if (pl->err) return PLANT_ERR_LOAD;
    pl->x.th_m = plant_py_mod(pl->x.th_m, PLANT_TWO_PI);
    count_range(pl);
    return PLANT_OK;
}

/* ---------------------------------------------------------- the period */
int plant_step(plant *pl, double d_a, double d_b, double d_c, double t0)
{
    pl->err = 0;
    pl->meter.q_a = pl->meter.q_b = pl->meter.q_c = 0.0;
    if (pl->switching)
        step_switching(pl, d_a, d_b, d_c, t0);
    else if (pl->any_leg)
        step_average_legs(pl, d_a, d_b, d_c, t0);
    else if (pl->avg_general)
        step_average_general(pl, d_a, d_b, d_c, t0);
    else
        step_fast(pl, d_a, d_b, d_c, t0);
    if (pl->err) return PLANT_ERR_LOAD;
    pl->x.th_m = plant_py_mod(pl->x.th_m, PLANT_TWO_PI);
    count_range(pl);
    return PLANT_OK;
}

int plant_step_n(plant *pl, long k0, long n, const double *duties, plant_out *out, long *done)
{
    long k;
    int e = PLANT_OK;
    for (k = 0; k < n; k++) {
        const double *d = duties + 3 * k;
        e = plant_step(pl, d[0], d[1], d[2], (double)(k0 + k) * pl->T_s);
        if (e) break;
        if (out) {
            plant_out *o = out + k;
            o->i_d = pl->x.i_d;
            o->i_q = pl->x.i_q;
            o->w_m = pl->x.w_m;
            o->th_m = pl->x.th_m;
            o->u_dc = pl->u_dc;
            o->u_al = pl->u_al;
            o->u_be = pl->u_be;
        }
    }
    if (done) *done = k;
    return e;
}
