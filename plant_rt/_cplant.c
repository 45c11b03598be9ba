/* The compiled engine of plant_rt.Plant: the per-period step in C.
 *
 * A second implementation of the enabled period of plant_rt/_plant.py
 * (average model: fast path, cross-saturation, dead time, device drops,
 * dynamic DC link, sensor delay; switching model: the carrier timeline of
 * plant_rt/_pwm.py, dead intervals with the diode clamp at the current zero,
 * the floating phase, device drops, DC link).  Every function mirrors the
 * Python method of the same name operation for operation, in the same order,
 * so that the two engines give the same trace bit for bit
 * (tests/test_plant_engine.py runs every shipped scenario on both).  Keep
 * them in step: a change of an equation in _plant.py or _pwm.py is a change
 * here.  Built with -ffp-contract=off (no fused multiply-add) for that
 * reason.
 *
 * The sensors of Plant.sample (plant_rt._sensors.Sensors: gain, offset,
 * noise from the plant's own random.Random, ADC) are mirrored the same way
 * in measure().  What stays in Python (plant_rt.Plant calls it and then
 * hands the state back with set_state): the disabled bridge
 * (enable=False), the energy meter and everything else outside step() and
 * sample().
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define LOW 0
#define HIGH 1
#define DEAD 2
#define OFF (-1)
#define MAX_PTS 12   /* change points of one leg in one period (at most 8) */

static double SQRT3, INV_SQRT3;
static double COS_PHI[3], SIN_PHI[3];
static const double RK4_O[4] = {0.0, 0.5, 0.5, 1.0};
static const double RK4_W[4] = {1.0, 2.0, 2.0, 1.0};

typedef struct {
    PyObject_HEAD
    /* states */
    double i_d, i_q, w_m, th_m, u_dc;
    /* outputs of the last period: mean stator voltage, the delayed sample */
    double u_al, u_be;
    double meas[4];
    /* machine */
    double n_p, R, L_d, L_q, psi_f, b, inv_J, k_tau;
    double sigma, i_sat, sig, inv_i_sat, sig_isat, c_dq, i_0;
    int sat, cross;
    /* period, integration grid, sensor instant */
    double T_s, h, i_eps, t_meas;
    int substeps;
    double *grid; Py_ssize_t n_grid;
    double *cuts; Py_ssize_t n_cuts;
    double *seg_a, *seg_b; long *seg_j; Py_ssize_t n_segs;
    /* inverter and DC link */
    double t_dead, v_ce, v_f, u_src, r_dc, c_dc;
    int switching, drops, dc_dyn, avg_general;
    /* PWM timeline (plant_rt._pwm.PwmTimeline) */
    int peak;
    int cmd[3];
    double dead_end[3];
    /* mechanics and load */
    int imposed;
    PyObject *load;
    int load_const;
    double tau_const;
    int err;  /* a load callback raised */
    /* sensors (plant_rt._sensors.Sensors) */
    double g[3], o[3], lsb_i, code_max, noise_i, gain_u, off_u, lsb_u, ucode_max, noise_u;
    PyObject *rng;
} Core;

/* ------------------------------------------------------------ helpers */
static double py_mod(double x, double m)
{
    /* Python's float %: the result takes the sign of the divisor */
    double mod = fmod(x, m);
    if (mod != 0.0) {
        if ((m < 0.0) != (mod < 0.0))
            mod += m;
    } else {
        mod = copysign(0.0, m);
    }
    return mod;
}

static double clamp_duty(double d)
{
    if (d > 1.0) return 1.0;
    if (d >= 0.0) return d;
    return 0.0;
}

static double dead_time_error(double i_x, double u_dc, double t_dead, double T_s)
{
    if (i_x > 0.0) return -u_dc * t_dead / T_s;
    if (i_x < 0.0) return u_dc * t_dead / T_s;
    return 0.0;
}

static double device_drop_error(double i_x, double d_x, double v_ce, double v_f)
{
    if (i_x > 0.0) return -(d_x * v_ce + (1.0 - d_x) * v_f);
    if (i_x < 0.0) return d_x * v_f + (1.0 - d_x) * v_ce;
    return 0.0;
}

static void currents_abc(Core *s, double out[3])
{
    double th_e = s->n_p * s->th_m;
    double c = cos(th_e), sn = sin(th_e);
    double i_al = c * s->i_d - sn * s->i_q;
    double i_be = sn * s->i_d + c * s->i_q;
    out[0] = i_al;
    out[1] = -0.5 * i_al + 0.5 * SQRT3 * i_be;
    out[2] = -0.5 * i_al - 0.5 * SQRT3 * i_be;
}

static double tau_load(Core *s, double t)
{
    if (s->imposed) return 0.0;
    if (s->load_const) return s->tau_const;
    if (s->err) return 0.0;
    PyObject *r = PyObject_CallMethod(s->load, "tau", "dd", t, s->w_m);
    if (r == NULL) { s->err = 1; return 0.0; }
    double v = PyFloat_AsDouble(r);
    Py_DECREF(r);
    if (v == -1.0 && PyErr_Occurred()) { s->err = 1; return 0.0; }
    return v;
}

/* plant_rt._machine.flux_d */
static void flux_d(Core *s, double i_d, double *psi_d, double *L_dd)
{
    if (!s->sat) {
        *psi_d = s->psi_f + s->L_d * i_d;
        *L_dd = s->L_d;
        return;
    }
    double x = i_d / s->i_sat;
    double r = sqrt(1.0 + x * x);
    *psi_d = s->psi_f + s->L_d * (i_d - s->sigma * s->i_sat * (r - 1.0));
    *L_dd = s->L_d * (1.0 - s->sigma * x / r);
}

/* plant_rt._machine.flux_dq with cross = True */
static void flux_dq(Core *s, double i_d, double i_q, double out[5])
{
    double psi_d, L_dd;
    flux_d(s, i_d, &psi_d, &L_dd);
    double L_q = s->L_q, c = s->c_dq;
    double i_0 = s->psi_f / s->L_d;
    double m = i_d + i_0;
    double g = i_d * (i_d + 2.0 * i_0);
    out[0] = psi_d - 0.5 * c * m * i_q * i_q;
    out[1] = (L_q - 0.5 * c * g) * i_q;
    out[2] = L_dd - 0.5 * c * i_q * i_q;
    out[3] = -c * m * i_q;
    out[4] = L_q - 0.5 * c * g;
}

/* --------------------------------------------------- RK4 (Plant._rk4_*) */
static void rk4_fast(Core *s, double h, double u_al, double u_be, double tau_L)
{
    double n_p = s->n_p, R = s->R, L_d = s->L_d, L_q = s->L_q, psi_f = s->psi_f;
    double k_tau = s->k_tau, b = s->b, inv_J = s->inv_J;
    int sat = s->sat, free_ = !s->imposed;
    double i_d0 = s->i_d, i_q0 = s->i_q, w0 = s->w_m, th0 = s->th_m;
    double i_d = i_d0, i_q = i_q0, w = w0, th = th0;
    double s_d = 0.0, s_q = 0.0, s_w = 0.0, s_th = 0.0;
    double di_d = 0.0, di_q = 0.0, dw = 0.0;
    for (int n = 0; n < 4; n++) {
        double o = RK4_O[n], wgt = RK4_W[n];
        if (o != 0.0) {
            i_d = i_d0 + o * h * di_d;
            i_q = i_q0 + o * h * di_q;
            th = th0 + o * h * w;
            w = w0 + o * h * dw;
        }
        double th_e = n_p * th;
        double c = cos(th_e), sn = sin(th_e);
        double w_e = n_p * w;
        double psi_d, L_dd;
        if (sat) {
            double x = i_d * s->inv_i_sat;
            double r = sqrt(1.0 + x * x);
            psi_d = psi_f + L_d * (i_d - s->sig_isat * (r - 1.0));
            L_dd = L_d * (1.0 - s->sig * x / r);
        } else {
            psi_d = psi_f + L_d * i_d;
            L_dd = L_d;
        }
        di_d = (c * u_al + sn * u_be - R * i_d + w_e * L_q * i_q) / L_dd;
        di_q = (c * u_be - sn * u_al - R * i_q - w_e * psi_d) / L_q;
        dw = free_ ? (k_tau * (psi_d - L_q * i_d) * i_q - tau_L - b * w) * inv_J : 0.0;
        s_d += wgt * di_d;
        s_q += wgt * di_q;
        s_w += wgt * dw;
        s_th += wgt * w;
    }
    double h6 = h / 6.0;
    s->i_d = i_d0 + h6 * s_d;
    s->i_q = i_q0 + h6 * s_q;
    s->w_m = w0 + h6 * s_w;
    s->th_m = th0 + h6 * s_th;
}

static void rk4_cross(Core *s, double h, double u_al, double u_be, double tau_L)
{
    double n_p = s->n_p, R = s->R, L_d = s->L_d, L_q = s->L_q, psi_f = s->psi_f;
    double k_tau = s->k_tau, b = s->b, inv_J = s->inv_J, c_dq = s->c_dq, i_0 = s->i_0;
    int sat = s->sat, free_ = !s->imposed;
    double i_d0 = s->i_d, i_q0 = s->i_q, w0 = s->w_m, th0 = s->th_m;
    double i_d = i_d0, i_q = i_q0, w = w0, th = th0;
    double s_d = 0.0, s_q = 0.0, s_w = 0.0, s_th = 0.0;
    double di_d = 0.0, di_q = 0.0, dw = 0.0;
    for (int n = 0; n < 4; n++) {
        double o = RK4_O[n], wgt = RK4_W[n];
        if (o != 0.0) {
            i_d = i_d0 + o * h * di_d;
            i_q = i_q0 + o * h * di_q;
            th = th0 + o * h * w;
            w = w0 + o * h * dw;
        }
        double th_e = n_p * th;
        double c = cos(th_e), sn = sin(th_e);
        double w_e = n_p * w;
        double psi_d, L_dd;
        if (sat) {
            double x = i_d * s->inv_i_sat;
            double r = sqrt(1.0 + x * x);
            psi_d = psi_f + L_d * (i_d - s->sig_isat * (r - 1.0));
            L_dd = L_d * (1.0 - s->sig * x / r);
        } else {
            psi_d = psi_f + L_d * i_d;
            L_dd = L_d;
        }
        double m = i_d + i_0;
        double hq = 0.5 * c_dq * i_q;
        double L_qq = L_q - 0.5 * c_dq * i_d * (i_d + 2.0 * i_0);
        psi_d -= hq * m * i_q;
        double psi_q = L_qq * i_q;
        L_dd -= hq * i_q;
        double L_dq = -c_dq * m * i_q;
        double e_d = c * u_al + sn * u_be - R * i_d + w_e * psi_q;
        double e_q = c * u_be - sn * u_al - R * i_q - w_e * psi_d;
        double inv_det = 1.0 / (L_dd * L_qq - L_dq * L_dq);
        di_d = (L_qq * e_d - L_dq * e_q) * inv_det;
        di_q = (L_dd * e_q - L_dq * e_d) * inv_det;
        dw = free_ ? (k_tau * (psi_d * i_q - psi_q * i_d) - tau_L - b * w) * inv_J : 0.0;
        s_d += wgt * di_d;
        s_q += wgt * di_q;
        s_w += wgt * dw;
        s_th += wgt * w;
    }
    double h6 = h / 6.0;
    s->i_d = i_d0 + h6 * s_d;
    s->i_q = i_q0 + h6 * s_q;
    s->w_m = w0 + h6 * s_w;
    s->th_m = th0 + h6 * s_th;
}

/* Plant._f: out = (di_d, di_q, dw, tau_e) */
static void f_ab(Core *s, double i_d, double i_q, double w_m, double th_m,
                 double u_al, double u_be, double tau_L, double out[4])
{
    double n_p = s->n_p;
    double th_e = n_p * th_m;
    double c = cos(th_e), sn = sin(th_e);
    double u_d = c * u_al + sn * u_be;
    double u_q = c * u_be - sn * u_al;
    double w_e = n_p * w_m;
    if (s->cross) {
        double fl[5];
        flux_dq(s, i_d, i_q, fl);
        double psi_d = fl[0], psi_q = fl[1], L_dd = fl[2], L_dq = fl[3], L_qq = fl[4];
        double e_d = u_d - s->R * i_d + w_e * psi_q;
        double e_q = u_q - s->R * i_q - w_e * psi_d;
        double det = L_dd * L_qq - L_dq * L_dq;
        double tau_e = s->k_tau * (psi_d * i_q - psi_q * i_d);
        out[0] = (L_qq * e_d - L_dq * e_q) / det;
        out[1] = (L_dd * e_q - L_dq * e_d) / det;
        out[2] = s->imposed ? 0.0 : (tau_e - tau_L - s->b * w_m) * s->inv_J;
        out[3] = tau_e;
        return;
    }
    double L_q = s->L_q, psi_d, L_dd;
    if (s->sat) {
        double x = i_d * s->inv_i_sat;
        double r = sqrt(1.0 + x * x);
        psi_d = s->psi_f + s->L_d * (i_d - s->sig_isat * (r - 1.0));
        L_dd = s->L_d * (1.0 - s->sig * x / r);
    } else {
        psi_d = s->psi_f + s->L_d * i_d;
        L_dd = s->L_d;
    }
    double R = s->R;
    double tau_e = s->k_tau * (psi_d - L_q * i_d) * i_q;
    out[0] = (u_d - R * i_d + w_e * L_q * i_q) / L_dd;
    out[1] = (u_q - R * i_q - w_e * psi_d) / L_q;
    out[2] = s->imposed ? 0.0 : (tau_e - tau_L - s->b * w_m) * s->inv_J;
    out[3] = tau_e;
}

/* Plant._f_float_cross: out = (di_d, di_q, dw, tau_e, v_x) */
static void f_float_cross(Core *s, double i_d, double i_q, double w_m, double c, double sn,
                          double u_d, double u_q, int x, double tau_L, double out[5])
{
    double w_e = s->n_p * w_m;
    double fl[5];
    flux_dq(s, i_d, i_q, fl);
    double psi_d = fl[0], psi_q = fl[1], L_dd = fl[2], L_dq = fl[3], L_qq = fl[4];
    double R = s->R;
    double e_d = u_d - R * i_d + w_e * psi_q;
    double e_q = u_q - R * i_q - w_e * psi_d;
    double det = L_dd * L_qq - L_dq * L_dq;
    double f_d = (L_qq * e_d - L_dq * e_q) / det;
    double f_q = (L_dd * e_q - L_dq * e_d) / det;
    double c_x = c * COS_PHI[x] + sn * SIN_PHI[x];
    double s_x = sn * COS_PHI[x] - c * SIN_PHI[x];
    double y_d = (L_qq * c_x + L_dq * s_x) / det;
    double y_q = (-L_dq * c_x - L_dd * s_x) / det;
    double a = c_x * f_d - s_x * f_q - w_e * (i_d * s_x + i_q * c_x);
    double g = (2.0 / 3.0) * (c_x * y_d - s_x * y_q);
    double v_x = -a / g;
    double tau_e = s->k_tau * (psi_d * i_q - psi_q * i_d);
    out[0] = f_d + (2.0 / 3.0) * v_x * y_d;
    out[1] = f_q + (2.0 / 3.0) * v_x * y_q;
    out[2] = s->imposed ? 0.0 : (tau_e - tau_L - s->b * w_m) * s->inv_J;
    out[3] = tau_e;
    out[4] = v_x;
}

/* Plant._f_float: out = (di_d, di_q, dw, tau_e, v_x) */
static void f_float(Core *s, double i_d, double i_q, double w_m, double th_m,
                    double u_al0, double u_be0, int x, double tau_L, double out[5])
{
    double n_p = s->n_p;
    double th_e = n_p * th_m;
    double c = cos(th_e), sn = sin(th_e);
    double u_d = c * u_al0 + sn * u_be0;
    double u_q = c * u_be0 - sn * u_al0;
    double w_e = n_p * w_m;
    if (s->cross) {
        f_float_cross(s, i_d, i_q, w_m, c, sn, u_d, u_q, x, tau_L, out);
        return;
    }
    double L_q = s->L_q, psi_d, L_dd;
    flux_d(s, i_d, &psi_d, &L_dd);
    double R = s->R;
    double f_d = (u_d - R * i_d + w_e * L_q * i_q) / L_dd;
    double f_q = (u_q - R * i_q - w_e * psi_d) / L_q;
    double c_x = c * COS_PHI[x] + sn * SIN_PHI[x];
    double s_x = sn * COS_PHI[x] - c * SIN_PHI[x];
    double a = c_x * f_d - s_x * f_q - w_e * (i_d * s_x + i_q * c_x);
    double g = (2.0 / 3.0) * (c_x * c_x / L_dd + s_x * s_x / L_q);
    double v_x = -a / g;
    double tau_e = s->k_tau * (psi_d - L_q * i_d) * i_q;
    out[0] = f_d + (2.0 / 3.0) * v_x * c_x / L_dd;
    out[1] = f_q - (2.0 / 3.0) * v_x * s_x / L_q;
    out[2] = s->imposed ? 0.0 : (tau_e - tau_L - s->b * w_m) * s->inv_J;
    out[3] = tau_e;
    out[4] = v_x;
}

/* Plant._rk4 without the meter: general step, optional floating phase fx */
static void rk4_general(Core *s, double h, double v_a, double v_b, double v_c, int fx,
                        double tau_L, double *ua, double *ub)
{
    double vs[3] = {v_a, v_b, v_c};
    if (fx >= 0) vs[fx] = 0.0;
    double u_al = (2.0 * vs[0] - vs[1] - vs[2]) / 3.0;
    double u_be = (vs[1] - vs[2]) * INV_SQRT3;
    double x0[4] = {s->i_d, s->i_q, s->w_m, s->th_m};
    double offsets[4] = {0.0, 0.5 * h, 0.5 * h, h};
    double k_prev[4] = {0.0, 0.0, 0.0, 0.0};
    double acc[4] = {0.0, 0.0, 0.0, 0.0};
    double ua_sum = 0.0, ub_sum = 0.0;
    for (int n = 0; n < 4; n++) {
        double o = offsets[n];
        double xs[4];
        for (int m = 0; m < 4; m++) xs[m] = x0[m] + o * k_prev[m];
        double d[5];
        double ua_n, ub_n;
        if (fx >= 0) {
            f_float(s, xs[0], xs[1], xs[2], xs[3], u_al, u_be, fx, tau_L, d);
            ua_n = u_al + (2.0 / 3.0) * d[4] * COS_PHI[fx];
            ub_n = u_be + (2.0 / 3.0) * d[4] * SIN_PHI[fx];
        } else {
            f_ab(s, xs[0], xs[1], xs[2], xs[3], u_al, u_be, tau_L, d);
            ua_n = u_al;
            ub_n = u_be;
        }
        double wgt = RK4_W[n];
        ua_sum += wgt * ua_n;
        ub_sum += wgt * ub_n;
        k_prev[0] = d[0];
        k_prev[1] = d[1];
        k_prev[2] = d[2];
        k_prev[3] = xs[2];
        for (int m = 0; m < 4; m++) acc[m] += wgt * k_prev[m];
    }
    double h6 = h / 6.0;
    s->i_d = x0[0] + h6 * acc[0];
    s->i_q = x0[1] + h6 * acc[1];
    s->w_m = x0[2] + h6 * acc[2];
    s->th_m = x0[3] + h6 * acc[3];
    *ua = ua_sum / 6.0;
    *ub = ub_sum / 6.0;
}

/* Plant._rk4_const without the meter */
static void rk4_const(Core *s, double h, double v_a, double v_b, double v_c, double tau_L,
                      double *ua, double *ub)
{
    double u_al = (2.0 * v_a - v_b - v_c) / 3.0;
    double u_be = (v_b - v_c) * INV_SQRT3;
    if (s->cross)
        rk4_cross(s, h, u_al, u_be, tau_L);
    else
        rk4_fast(s, h, u_al, u_be, tau_L);
    *ua = u_al;
    *ub = u_be;
}

static void zero_phase(Core *s, int x)
{
    double th_e = s->n_p * s->th_m;
    double c = cos(th_e), sn = sin(th_e);
    double c_x = c * COS_PHI[x] + sn * SIN_PHI[x];
    double s_x = sn * COS_PHI[x] - c * SIN_PHI[x];
    double i_x = s->i_d * c_x - s->i_q * s_x;
    s->i_d -= i_x * c_x;
    s->i_q += i_x * s_x;
}

static double dw_open(Core *s, double tau_L, double w)
{
    return (-tau_L - s->b * w) * s->inv_J;
}

/* Plant._open_circuit without the meter */
static void open_circuit(Core *s, double h, double tau_L, double *ua_out, double *ub_out)
{
    double w0 = s->w_m, th0 = s->th_m, w1;
    if (!s->imposed) {
        double k1 = dw_open(s, tau_L, w0);
        double k2 = dw_open(s, tau_L, w0 + 0.5 * h * k1);
        double k3 = dw_open(s, tau_L, w0 + 0.5 * h * k2);
        double k4 = dw_open(s, tau_L, w0 + h * k3);
        w1 = w0 + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
    } else {
        w1 = w0;
    }
    double th1 = th0 + 0.5 * h * (w0 + w1);
    double psi0, L0;
    flux_d(s, 0.0, &psi0, &L0);
    double n_p = s->n_p;
    double ua = 0.0, ub = 0.0;
    double wg[3] = {1.0, 4.0, 1.0};
    double ths[3] = {th0, 0.5 * (th0 + th1), th1};
    double ws[3] = {w0, 0.5 * (w0 + w1), w1};
    for (int n = 0; n < 3; n++) {
        double amp = n_p * ws[n] * psi0;
        ua -= wg[n] * amp * sin(n_p * ths[n]);
        ub += wg[n] * amp * cos(n_p * ths[n]);
    }
    s->w_m = w1;
    s->th_m = th1;
    *ua_out = ua / 6.0;
    *ub_out = ub / 6.0;
}

static void dc_update(Core *s, double h, double i_dc, double i_dc_end)
{
    double r = s->r_dc;
    if (s->c_dc > 0.0) {
        double u_inf = s->u_src - r * i_dc;
        s->u_dc = u_inf + (s->u_dc - u_inf) * exp(-h / (r * s->c_dc));
    } else {
        s->u_dc = s->u_src - r * i_dc_end;
    }
}

static void record_meas(Core *s, const double i[3])
{
    s->meas[0] = i[0];
    s->meas[1] = i[1];
    s->meas[2] = i[2];
    s->meas[3] = s->u_dc;
}

/* ------------------------------------------------ average model periods */
static void step_fast(Core *s, double d_a, double d_b, double d_c, double t0)
{
    double u_dc = s->u_dc;
    double v_a = clamp_duty(d_a) * u_dc;
    double v_b = clamp_duty(d_b) * u_dc;
    double v_c = clamp_duty(d_c) * u_dc;
    double t_dead = s->t_dead;
    double i[3];
    if (t_dead > 0.0) {
        currents_abc(s, i);
        if (0.0 < v_a && v_a < u_dc) v_a += dead_time_error(i[0], u_dc, t_dead, s->T_s);
        if (0.0 < v_b && v_b < u_dc) v_b += dead_time_error(i[1], u_dc, t_dead, s->T_s);
        if (0.0 < v_c && v_c < u_dc) v_c += dead_time_error(i[2], u_dc, t_dead, s->T_s);
    }
    if (s->drops) {
        currents_abc(s, i);
        double a = v_a + device_drop_error(i[0], v_a / u_dc, s->v_ce, s->v_f);
        double b = v_b + device_drop_error(i[1], v_b / u_dc, s->v_ce, s->v_f);
        double c = v_c + device_drop_error(i[2], v_c / u_dc, s->v_ce, s->v_f);
        v_a = a;
        v_b = b;
        v_c = c;
    }
    double u_al = (2.0 * v_a - v_b - v_c) / 3.0;
    double u_be = (v_b - v_c) * INV_SQRT3;
    double h = s->h;
    for (int j = 0; j < s->substeps; j++) {
        double tau_L = tau_load(s, t0 + j * h);
        if (s->cross)
            rk4_cross(s, h, u_al, u_be, tau_L);
        else
            rk4_fast(s, h, u_al, u_be, tau_L);
    }
    s->u_al = u_al;
    s->u_be = u_be;
}

static void step_average_general(Core *s, double d_a, double d_b, double d_c, double t0)
{
    d_a = clamp_duty(d_a);
    d_b = clamp_duty(d_b);
    d_c = clamp_duty(d_c);
    double t_dead = s->t_dead, T = s->T_s;
    double i[3];
    currents_abc(s, i);
    if (t_dead > 0.0) {
        double r = t_dead / T;
        if (0.0 < d_a && d_a < 1.0) d_a += dead_time_error(i[0], 1.0, r, 1.0);
        if (0.0 < d_b && d_b < 1.0) d_b += dead_time_error(i[1], 1.0, r, 1.0);
        if (0.0 < d_c && d_c < 1.0) d_c += dead_time_error(i[2], 1.0, r, 1.0);
    }
    double e_a = 0.0, e_b = 0.0, e_c = 0.0;
    if (s->drops) {
        e_a = device_drop_error(i[0], d_a, s->v_ce, s->v_f);
        e_b = device_drop_error(i[1], d_b, s->v_ce, s->v_f);
        e_c = device_drop_error(i[2], d_c, s->v_ce, s->v_f);
    }
    double h_grid = s->h, s_al = 0.0, s_be = 0.0, tau_L = 0.0, i0 = 0.0;
    long j_load = -1;
    for (Py_ssize_t n = 0; n < s->n_segs; n++) {
        double ta = s->seg_a[n], tb = s->seg_b[n];
        long j = s->seg_j[n];
        if (j != j_load) {
            tau_L = tau_load(s, t0 + j * h_grid);
            j_load = j;
        }
        double h = tb - ta;
        if (s->dc_dyn) {
            i0 = d_a * i[0] + d_b * i[1] + d_c * i[2];
            if (s->c_dc == 0.0) s->u_dc = s->u_src - s->r_dc * i0;
        }
        double u_dc = s->u_dc;
        double v_a = d_a * u_dc + e_a;
        double v_b = d_b * u_dc + e_b;
        double v_c = d_c * u_dc + e_c;
        double u_al = (2.0 * v_a - v_b - v_c) / 3.0;
        double u_be = (v_b - v_c) * INV_SQRT3;
        if (s->cross)
            rk4_cross(s, h, u_al, u_be, tau_L);
        else
            rk4_fast(s, h, u_al, u_be, tau_L);
        s_al += h * u_al;
        s_be += h * u_be;
        currents_abc(s, i);
        if (s->dc_dyn) {
            double i1 = d_a * i[0] + d_b * i[1] + d_c * i[2];
            dc_update(s, h, 0.5 * (i0 + i1), i1);
        }
        if (tb == s->t_meas) record_meas(s, i);
    }
    s->u_al = s_al / T;
    s->u_be = s_be / T;
}

/* ------------------------------------------ PWM timeline (plant_rt._pwm) */
/* PwmTimeline._leg: change points (t, state) of leg x, the first at t = 0 */
static int pwm_leg(Core *s, int x, double d, double *pt, int *ps)
{
    double T = s->T_s, t_d = s->t_dead;
    double pe[3];
    int pn[3];
    int np;
    if (d >= 1.0) {
        pe[0] = 0.0; pn[0] = HIGH; np = 1;
    } else if (d <= 0.0) {
        pe[0] = 0.0; pn[0] = LOW; np = 1;
    } else if (s->peak) {
        pe[0] = 0.0; pn[0] = LOW;
        pe[1] = 0.5 * (1.0 - d) * T; pn[1] = HIGH;
        pe[2] = 0.5 * (1.0 + d) * T; pn[2] = LOW;
        np = 3;
    } else {
        pe[0] = 0.0; pn[0] = HIGH;
        pe[1] = 0.5 * d * T; pn[1] = LOW;
        pe[2] = T - 0.5 * d * T; pn[2] = HIGH;
        np = 3;
    }
    double tol = 1e-9 * T;
    int level = s->cmd[x];
    double du = s->dead_end[x];
    int n = 0;
    pt[n] = 0.0;
    ps[n] = du > tol ? DEAD : level;
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
            state = DEAD;
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
    s->cmd[x] = level;
    s->dead_end[x] = du > T + tol ? du - T : 0.0;
    return n;
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* ------------------------------------------------------ switching model */
/* Plant._dead_with_clamp without the meter */
static void dead_with_clamp(Core *s, double h, const double v[3], const int cond[3], double tau_L,
                            const double i_abc[3], double *ua_out, double *ub_out, double i_out[3])
{
    double saved[4] = {s->i_d, s->i_q, s->w_m, s->th_m};
    double ua, ub;
    rk4_const(s, h, v[0], v[1], v[2], tau_L, &ua, &ub);
    double i_new[3];
    currents_abc(s, i_new);
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
    s->i_d = saved[0];
    s->i_q = saved[1];
    s->w_m = saved[2];
    s->th_m = saved[3];
    double h1 = frac * h;
    double ua1 = ua, ub1 = ub;
    if (h1 > 0.0) rk4_const(s, h1, v[0], v[1], v[2], tau_L, &ua1, &ub1);
    zero_phase(s, first);
    double h2 = h - h1;
    double ua2, ub2;
    rk4_general(s, h2, v[0], v[1], v[2], first, tau_L, &ua2, &ub2);
    zero_phase(s, first);
    *ua_out = (h1 * ua1 + h2 * ua2) / h;
    *ub_out = (h1 * ub1 + h2 * ub2) / h;
    currents_abc(s, i_out);
}

/* Plant._sw_interval without the meter; i_abc in: at the start, out: at the end */
static void sw_interval(Core *s, double h, const int states[3], double tau_L, double i_abc[3],
                        double *ua, double *ub)
{
    double v_ce = s->v_ce, v_f = s->v_f, eps = s->i_eps;
    double i_dc0 = 0.0;
    if (s->dc_dyn) {
        for (int x = 0; x < 3; x++)
            if (states[x] == HIGH || (states[x] == DEAD && i_abc[x] < -eps)) i_dc0 += i_abc[x];
        if (s->c_dc == 0.0) s->u_dc = s->u_src - s->r_dc * i_dc0;
    }
    double u_dc = s->u_dc;
    double v[3] = {0.0, 0.0, 0.0};
    int cond[3] = {0, 0, 0};
    int upper[3] = {0, 0, 0};
    int floating[3];
    int n_float = 0;
    for (int x = 0; x < 3; x++) {
        int st = states[x];
        double i = i_abc[x];
        if (st == HIGH) {
            upper[x] = 1;
            v[x] = i > eps ? u_dc - v_ce : (i < -eps ? u_dc + v_f : u_dc);
        } else if (st == DEAD) {
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
        s->i_d = 0.0;
        s->i_q = 0.0;
        open_circuit(s, h, tau_L, ua, ub);
        if (s->dc_dyn) dc_update(s, h, 0.0, 0.0);
        i_abc[0] = i_abc[1] = i_abc[2] = 0.0;
        return;
    }
    int fx = -1;
    if (n_float) {
        int x = floating[0];
        double u_al0 = (2.0 * v[0] - v[1] - v[2]) / 3.0;
        double u_be0 = (v[1] - v[2]) * INV_SQRT3;
        double d[5];
        f_float(s, s->i_d, s->i_q, s->w_m, s->th_m, u_al0, u_be0, x, tau_L, d);
        double v_x = d[4];
        if (v_x > u_dc + v_f) {
            v[x] = u_dc + v_f;
            cond[x] = -1;
            upper[x] = 1;
        } else if (v_x < -v_f) {
            v[x] = -v_f;
            cond[x] = 1;
        } else {
            fx = x;
        }
    }
    double i_new[3];
    if (fx >= 0) {
        rk4_general(s, h, v[0], v[1], v[2], fx, tau_L, ua, ub);
        zero_phase(s, fx);
        currents_abc(s, i_new);
    } else if (cond[0] == 0 && cond[1] == 0 && cond[2] == 0) {
        rk4_const(s, h, v[0], v[1], v[2], tau_L, ua, ub);
        currents_abc(s, i_new);
    } else {
        dead_with_clamp(s, h, v, cond, tau_L, i_abc, ua, ub, i_new);
    }
    if (s->dc_dyn) {
        double i_dc1 = 0.0;
        for (int x = 0; x < 3; x++)
            if (upper[x]) i_dc1 += i_new[x];
        dc_update(s, h, 0.5 * (i_dc0 + i_dc1), i_dc1);
    }
    memcpy(i_abc, i_new, sizeof i_new);
}

/* Plant._step_switching, with PwmTimeline.period inlined */
static void step_switching(Core *s, double d_a, double d_b, double d_c, double t0)
{
    double T = s->T_s;
    double pt[3][MAX_PTS];
    int ps[3][MAX_PTS];
    int np[3];
    double dd[3] = {clamp_duty(d_a), clamp_duty(d_b), clamp_duty(d_c)};
    for (int x = 0; x < 3; x++) np[x] = pwm_leg(s, x, dd[x], pt[x], ps[x]);
    /* sorted(set): T, every change point after 0, the cuts */
    double tbuf[1 + 3 * MAX_PTS + 64];
    double *times = tbuf;
    Py_ssize_t cap = 1 + 3 * MAX_PTS + s->n_cuts;
    if (cap > (Py_ssize_t)(sizeof tbuf / sizeof tbuf[0])) {
        times = PyMem_Malloc(cap * sizeof(double));
        if (times == NULL) {
            s->err = 1;
            PyErr_NoMemory();
            return;
        }
    }
    Py_ssize_t nt = 0;
    times[nt++] = T;
    for (int x = 0; x < 3; x++)
        for (int k = 0; k < np[x]; k++)
            if (pt[x][k] > 0.0) times[nt++] = pt[x][k];
    for (Py_ssize_t k = 0; k < s->n_cuts; k++) times[nt++] = s->cuts[k];
    qsort(times, nt, sizeof(double), cmp_double);
    int ja = 0, jb = 0, jc = 0;
    int st[3] = {ps[0][0], ps[1][0], ps[2][0]};
    Py_ssize_t j = 0;
    double tau_L = tau_load(s, t0);
    double i_abc[3];
    currents_abc(s, i_abc);
    double s_al = 0.0, s_be = 0.0, t_a = 0.0;
    for (Py_ssize_t n = 0; n < nt; n++) {
        double t1 = times[n];
        if (n > 0 && t1 == times[n - 1]) continue; /* the set removed it */
        while (ja + 1 < np[0] && pt[0][ja + 1] <= t_a) st[0] = ps[0][++ja];
        while (jb + 1 < np[1] && pt[1][jb + 1] <= t_a) st[1] = ps[1][++jb];
        while (jc + 1 < np[2] && pt[2][jc + 1] <= t_a) st[2] = ps[2][++jc];
        if (!(t1 > t_a)) continue;
        double ta = t_a, tb = t1;
        t_a = t1;
        while (j + 1 < s->n_grid && ta >= s->grid[j + 1]) {
            j++;
            tau_L = tau_load(s, t0 + s->grid[j]);
        }
        double h = tb - ta, ua, ub;
        sw_interval(s, h, st, tau_L, i_abc, &ua, &ub);
        s_al += h * ua;
        s_be += h * ub;
        if (tb == s->t_meas) record_meas(s, i_abc);
    }
    if (times != tbuf) PyMem_Free(times);
    s->u_al = s_al / T;
    s->u_be = s_be / T;
}

/* ---------------------------------------------------------- Python type */
static int get_d(PyObject *o, const char *name, double *out)
{
    PyObject *v = PyObject_GetAttrString(o, name);
    if (v == NULL) return -1;
    *out = PyFloat_AsDouble(v);
    Py_DECREF(v);
    return (*out == -1.0 && PyErr_Occurred()) ? -1 : 0;
}

static int get_b(PyObject *o, const char *name, int *out)
{
    PyObject *v = PyObject_GetAttrString(o, name);
    if (v == NULL) return -1;
    *out = PyObject_IsTrue(v);
    Py_DECREF(v);
    return *out < 0 ? -1 : 0;
}

/* a tuple of floats into a new array */
static int get_arr(PyObject *o, const char *name, double **out, Py_ssize_t *n)
{
    PyObject *v = PyObject_GetAttrString(o, name);
    if (v == NULL) return -1;
    PyObject *seq = PySequence_Fast(v, "expected a sequence");
    Py_DECREF(v);
    if (seq == NULL) return -1;
    *n = PySequence_Fast_GET_SIZE(seq);
    *out = PyMem_Malloc((*n + 1) * sizeof(double));
    if (*out == NULL) { Py_DECREF(seq); PyErr_NoMemory(); return -1; }
    for (Py_ssize_t k = 0; k < *n; k++) {
        (*out)[k] = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(seq, k));
        if ((*out)[k] == -1.0 && PyErr_Occurred()) { Py_DECREF(seq); return -1; }
    }
    Py_DECREF(seq);
    return 0;
}

static int core_set_load(Core *s, PyObject *load, PyObject *tau_const)
{
    Py_XINCREF(load);
    Py_XSETREF(s->load, load);
    if (tau_const == Py_None) {
        s->load_const = 0;
        return 0;
    }
    s->tau_const = PyFloat_AsDouble(tau_const);
    if (s->tau_const == -1.0 && PyErr_Occurred()) return -1;
    s->load_const = 1;
    return 0;
}

/* Core(plant, tau_const): the constants and the state of a plant_rt.Plant */
static int Core_init(Core *s, PyObject *args, PyObject *kw)
{
    PyObject *p, *tau_const;
    if (!PyArg_ParseTuple(args, "OO", &p, &tau_const)) return -1;
    double substeps;
    if (get_d(p, "_i_d", &s->i_d) || get_d(p, "_i_q", &s->i_q) || get_d(p, "_w_m", &s->w_m)
        || get_d(p, "_th_m", &s->th_m) || get_d(p, "_u_dc", &s->u_dc)
        || get_d(p, "_n_p", &s->n_p) || get_d(p, "_R", &s->R) || get_d(p, "_L_d", &s->L_d)
        || get_d(p, "_L_q", &s->L_q) || get_d(p, "_psi_f", &s->psi_f) || get_d(p, "_b", &s->b)
        || get_d(p, "_inv_J", &s->inv_J) || get_d(p, "_k_tau", &s->k_tau)
        || get_d(p, "_sat_sigma", &s->sigma) || get_d(p, "_sat_i_sat", &s->i_sat)
        || get_d(p, "_sig", &s->sig) || get_d(p, "_inv_i_sat", &s->inv_i_sat)
        || get_d(p, "_sig_isat", &s->sig_isat) || get_d(p, "_c_dq", &s->c_dq)
        || get_d(p, "_i_0", &s->i_0) || get_d(p, "T_s", &s->T_s) || get_d(p, "_h", &s->h)
        || get_d(p, "_i_eps", &s->i_eps) || get_d(p, "_t_meas", &s->t_meas)
        || get_d(p, "substeps", &substeps) || get_d(p, "_t_dead", &s->t_dead)
        || get_d(p, "_v_ce", &s->v_ce) || get_d(p, "_v_f", &s->v_f)
        || get_d(p, "_u_src", &s->u_src) || get_d(p, "_r_dc", &s->r_dc)
        || get_d(p, "_c_dc", &s->c_dc) || get_b(p, "saturation", &s->sat)
        || get_b(p, "cross_saturation", &s->cross) || get_b(p, "_switching", &s->switching)
        || get_b(p, "_drops", &s->drops) || get_b(p, "_dc_dyn", &s->dc_dyn)
        || get_b(p, "_avg_general", &s->avg_general) || get_b(p, "_pwm_peak", &s->peak))
        return -1;
    PyObject *w_imp = PyObject_GetAttrString(p, "_w_imp");
    if (w_imp == NULL) return -1;
    s->imposed = w_imp != Py_None;
    Py_DECREF(w_imp);
    s->substeps = (int)substeps;
    PyMem_Free(s->grid);
    PyMem_Free(s->cuts);
    s->grid = s->cuts = NULL;
    if (get_arr(p, "_grid", &s->grid, &s->n_grid) || get_arr(p, "_cuts", &s->cuts, &s->n_cuts))
        return -1;
    /* the segments of the general average model: (t_start, t_end, grid index) */
    PyObject *segs = PyObject_GetAttrString(p, "_segs");
    if (segs == NULL) return -1;
    PyObject *seq = PySequence_Fast(segs, "_segs must be a sequence");
    Py_DECREF(segs);
    if (seq == NULL) return -1;
    Py_ssize_t n = PySequence_Fast_GET_SIZE(seq);
    PyMem_Free(s->seg_a);
    PyMem_Free(s->seg_b);
    PyMem_Free(s->seg_j);
    s->seg_a = PyMem_Malloc((n + 1) * sizeof(double));
    s->seg_b = PyMem_Malloc((n + 1) * sizeof(double));
    s->seg_j = PyMem_Malloc((n + 1) * sizeof(long));
    s->n_segs = n;
    if (!s->seg_a || !s->seg_b || !s->seg_j) {
        Py_DECREF(seq);
        PyErr_NoMemory();
        return -1;
    }
    for (Py_ssize_t k = 0; k < n; k++) {
        PyObject *t = PySequence_Fast_GET_ITEM(seq, k);
        if (!PyArg_ParseTuple(t, "ddl", &s->seg_a[k], &s->seg_b[k], &s->seg_j[k])) {
            Py_DECREF(seq);
            return -1;
        }
    }
    Py_DECREF(seq);
    int level = s->peak ? LOW : HIGH;
    for (int x = 0; x < 3; x++) {
        s->cmd[x] = level;
        s->dead_end[x] = 0.0;
    }
    s->u_al = s->u_be = 0.0;
    s->meas[0] = s->meas[1] = s->meas[2] = s->meas[3] = 0.0;
    PyObject *load = PyObject_GetAttrString(p, "_load");
    if (load == NULL) return -1;
    int r = core_set_load(s, load, tau_const);
    Py_DECREF(load);
    return r;
}

/* ------------------------------------------------------------- sensors */
static int gauss(Core *s, double sd, double *out)
{
    PyObject *r = PyObject_CallMethod(s->rng, "gauss", "dd", 0.0, sd);
    if (r == NULL) return -1;
    double v = PyFloat_AsDouble(r);
    Py_DECREF(r);
    if (v == -1.0 && PyErr_Occurred()) return -1;
    *out += v;
    return 0;
}

/* math.floor(x) as Python does it, which raises for NaN and infinity */
static int py_floor(double x, double *out)
{
    if (isnan(x)) {
        PyErr_SetString(PyExc_ValueError, "cannot convert float NaN to integer");
        return -1;
    }
    if (isinf(x)) {
        PyErr_SetString(PyExc_OverflowError, "cannot convert float infinity to integer");
        return -1;
    }
    *out = floor(x);
    return 0;
}

/* Sensors._quant_i */
static int quant_i(Core *s, double x, double *out)
{
    double lsb = s->lsb_i;
    if (lsb == 0.0) {
        *out = x;
        return 0;
    }
    double code;
    if (py_floor(x / lsb + 0.5, &code) < 0) return -1;
    double lo = -s->code_max - 1.0;
    code = code < s->code_max ? code : s->code_max;
    code = lo > code ? lo : code;
    *out = code * lsb;
    return 0;
}

static PyObject *Core_set_sensors(Core *s, PyObject *args)
{
    PyObject *rng;
    if (!PyArg_ParseTuple(args, "ddddddddddddddO", &s->g[0], &s->g[1], &s->g[2], &s->o[0],
                          &s->o[1], &s->o[2], &s->lsb_i, &s->code_max, &s->noise_i, &s->gain_u,
                          &s->off_u, &s->lsb_u, &s->ucode_max, &s->noise_u, &rng))
        return NULL;
    Py_INCREF(rng);
    Py_XSETREF(s->rng, rng);
    Py_RETURN_NONE;
}

/* Sensors.currents and Sensors.voltage of the true values (i_a, i_b, i_c, u_dc),
   or of the present state without arguments */
static PyObject *Core_measure(Core *s, PyObject *const *args, Py_ssize_t nargs)
{
    double i[3], u;
    if (nargs == 4) {
        for (int k = 0; k < 3; k++) {
            i[k] = PyFloat_AsDouble(args[k]);
            if (i[k] == -1.0 && PyErr_Occurred()) return NULL;
        }
        u = PyFloat_AsDouble(args[3]);
        if (u == -1.0 && PyErr_Occurred()) return NULL;
    } else if (nargs == 0) {
        currents_abc(s, i);
        u = s->u_dc;
    } else {
        PyErr_SetString(PyExc_TypeError, "measure() or measure(i_a, i_b, i_c, u_dc)");
        return NULL;
    }
    if (s->rng == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "measure() before set_sensors()");
        return NULL;
    }
    double m[3];
    for (int k = 0; k < 3; k++) m[k] = s->g[k] * i[k] + s->o[k];
    double sd = s->noise_i;
    if (sd > 0.0)
        for (int k = 0; k < 3; k++)
            if (gauss(s, sd, &m[k]) < 0) return NULL;
    double q[3];
    for (int k = 0; k < 3; k++)
        if (quant_i(s, m[k], &q[k]) < 0) return NULL;
    double mu = s->gain_u * u + s->off_u;
    if (s->noise_u > 0.0 && gauss(s, s->noise_u, &mu) < 0) return NULL;
    double lsb = s->lsb_u;
    if (lsb != 0.0) {
        double code;
        if (py_floor(mu / lsb + 0.5, &code) < 0) return NULL;
        code = s->ucode_max < code ? s->ucode_max : code;
        code = 0.0 > code ? 0.0 : code;
        mu = code * lsb;
    }
    return Py_BuildValue("(dddd)", q[0], q[1], q[2], mu);
}

static void Core_dealloc(Core *s)
{
    Py_XDECREF(s->load);
    Py_XDECREF(s->rng);
    PyMem_Free(s->grid);
    PyMem_Free(s->cuts);
    PyMem_Free(s->seg_a);
    PyMem_Free(s->seg_b);
    PyMem_Free(s->seg_j);
    Py_TYPE(s)->tp_free((PyObject *)s);
}

static PyObject *Core_step(Core *s, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, "step(d_a, d_b, d_c, t0) takes 4 arguments");
        return NULL;
    }
    double v[4];
    for (int k = 0; k < 4; k++) {
        v[k] = PyFloat_AsDouble(args[k]);
        if (v[k] == -1.0 && PyErr_Occurred()) return NULL;
    }
    s->err = 0;
    if (s->switching)
        step_switching(s, v[0], v[1], v[2], v[3]);
    else if (s->avg_general)
        step_average_general(s, v[0], v[1], v[2], v[3]);
    else
        step_fast(s, v[0], v[1], v[2], v[3]);
    if (s->err) return NULL;
    s->th_m = py_mod(s->th_m, 2.0 * M_PI);
    return Py_BuildValue("(ddddddd)", s->i_d, s->i_q, s->w_m, s->th_m, s->u_dc, s->u_al, s->u_be);
}

static PyObject *Core_set_state(Core *s, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 6) {
        PyErr_SetString(PyExc_TypeError, "set_state(i_d, i_q, w_m, th_m, u_dc, imposed)");
        return NULL;
    }
    double v[5];
    for (int k = 0; k < 5; k++) {
        v[k] = PyFloat_AsDouble(args[k]);
        if (v[k] == -1.0 && PyErr_Occurred()) return NULL;
    }
    int imposed = PyObject_IsTrue(args[5]);
    if (imposed < 0) return NULL;
    s->i_d = v[0];
    s->i_q = v[1];
    s->w_m = v[2];
    s->th_m = v[3];
    s->u_dc = v[4];
    s->imposed = imposed;
    Py_RETURN_NONE;
}

static PyObject *Core_set_load(Core *s, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "set_load(load, tau_const)");
        return NULL;
    }
    if (core_set_load(s, args[0], args[1]) < 0) return NULL;
    Py_RETURN_NONE;
}

static PyObject *Core_meas(Core *s, PyObject *unused)
{
    return Py_BuildValue("(dddd)", s->meas[0], s->meas[1], s->meas[2], s->meas[3]);
}

static PyObject *Core_pwm_disable(Core *s, PyObject *unused)
{
    for (int x = 0; x < 3; x++) {
        s->cmd[x] = OFF;
        s->dead_end[x] = 0.0;
    }
    Py_RETURN_NONE;
}

static PyMethodDef Core_methods[] = {
    {"step", (PyCFunction)(void (*)(void))Core_step, METH_FASTCALL,
     "step(d_a, d_b, d_c, t0) -> (i_d, i_q, w_m, th_m, u_dc, u_al, u_be): one enabled period"},
    {"set_state", (PyCFunction)(void (*)(void))Core_set_state, METH_FASTCALL,
     "set_state(i_d, i_q, w_m, th_m, u_dc, imposed): take over the plant's state"},
    {"set_load", (PyCFunction)(void (*)(void))Core_set_load, METH_FASTCALL,
     "set_load(load, tau_const): the load profile; tau_const a float for a constant load"},
    {"meas", (PyCFunction)Core_meas, METH_NOARGS,
     "meas() -> (i_a, i_b, i_c, u_dc) recorded at the sensor instant of the last period"},
    {"set_sensors", (PyCFunction)Core_set_sensors, METH_VARARGS,
     "set_sensors(g_a, g_b, g_c, o_a, o_b, o_c, lsb_i, code_max, noise_i, gain_u_dc, "
     "offset_u_dc, lsb_u, ucode_max, noise_u, rng): the constants of plant_rt._sensors.Sensors"},
    {"measure", (PyCFunction)(void (*)(void))Core_measure, METH_FASTCALL,
     "measure([i_a, i_b, i_c, u_dc]) -> measured (i_a, i_b, i_c, u_dc), as Sensors does"},
    {"pwm_disable", (PyCFunction)Core_pwm_disable, METH_NOARGS,
     "all switches were opened for a period (PwmTimeline.disable)"},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject CoreType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "plant_rt._cplant.Core",
    .tp_doc = "Core(plant, tau_const): the compiled per-period step of a plant_rt.Plant",
    .tp_basicsize = sizeof(Core),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Core_init,
    .tp_dealloc = (destructor)Core_dealloc,
    .tp_methods = Core_methods,
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "plant_rt._cplant",
    "The compiled engine of plant_rt.Plant (see the comment at the top of _cplant.c).", -1, NULL,
};

PyMODINIT_FUNC PyInit__cplant(void)
{
    SQRT3 = sqrt(3.0);
    INV_SQRT3 = 1.0 / SQRT3;
    COS_PHI[0] = 1.0; COS_PHI[1] = -0.5; COS_PHI[2] = -0.5;
    SIN_PHI[0] = 0.0; SIN_PHI[1] = 0.5 * SQRT3; SIN_PHI[2] = -0.5 * SQRT3;
    if (PyType_Ready(&CoreType) < 0) return NULL;
    PyObject *m = PyModule_Create(&module);
    if (m == NULL) return NULL;
    Py_INCREF(&CoreType);
    if (PyModule_AddObject(m, "Core", (PyObject *)&CoreType) < 0) {
        Py_DECREF(&CoreType);
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
