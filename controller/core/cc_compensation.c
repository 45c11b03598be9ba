/* The drive's countermeasures (cc_compensation.h; controller/_compensation.py). */
#include "cc_compensation.h"
#include "cc_math.h"

#define CC_TWO_OVER_PI (2.0 / M_PI)

void cc_deadtime_init(cc_deadtime_t *dt, double T_s, double t_dead, double v_ce, double v_f,
                      double i_band, int sine)
{
    dt->k_dt = t_dead / T_s;
    dt->v_ce = v_ce;
    dt->v_f = v_f;
    dt->i_band = i_band;
    dt->sine = sine;
}

double cc_smooth_sign(double i_x, double i_band, int sine)
{
    if (i_x >= i_band)
        return i_x > 0.0 ? 1.0 : 0.0;
    if (i_x <= -i_band)
        return i_x < 0.0 ? -1.0 : 0.0;
    double r = i_x / i_band;
    return sine ? CC_TWO_OVER_PI * asin(r) : r;
}

double cc_deadtime_voltage(const cc_deadtime_t *dt, double i_x, double u_dc, double d_x)
{
    double s = cc_smooth_sign(i_x, dt->i_band, dt->sine);
    double on = d_x * dt->v_ce + (1.0 - d_x) * dt->v_f;  /* i > 0: upper transistor, lower diode */
    double off = d_x * dt->v_f + (1.0 - d_x) * dt->v_ce; /* i < 0: upper diode, lower transistor */
    return -s * dt->k_dt * u_dc - 0.5 * (1.0 + s) * on + 0.5 * (1.0 - s) * off;
}

void cc_deadtime_duties(const cc_deadtime_t *dt, double d[3], double i_a, double i_b,
                        double i_c, double u_dc)
{
    double inv = 1.0 / u_dc;
    double d_a = d[0] - cc_deadtime_voltage(dt, i_a, u_dc, d[0]) * inv;
    double d_b = d[1] - cc_deadtime_voltage(dt, i_b, u_dc, d[1]) * inv;
    double d_c = d[2] - cc_deadtime_voltage(dt, i_c, u_dc, d[2]) * inv;
    d[0] = d_a > 1.0 ? 1.0 : (d_a < 0.0 ? 0.0 : d_a);
    d[1] = d_b > 1.0 ? 1.0 : (d_b < 0.0 ? 0.0 : d_b);
    d[2] = d_c > 1.0 ? 1.0 : (d_c < 0.0 ? 0.0 : d_c);
}

double cc_cross_saturation_offset(double k_dq, double i_q, double L_d, double L_q)
{
    return -0.5 * atan2(2.0 * k_dq * i_q, L_q - L_d);
}

void cc_offset_cal_init(cc_offset_cal_t *cal, long long n)
{
    cal->n = n;
    cal->o_a = cal->o_b = cal->o_c = 0.0;
    cc_offset_cal_restart(cal);
}

void cc_offset_cal_restart(cc_offset_cal_t *cal)
{
    cal->k = 0;
    cal->s_a = cal->s_b = cal->s_c = 0.0;
}

void cc_offset_cal_add(cc_offset_cal_t *cal, double i_a, double i_b, double i_c)
{
    cal->s_a += i_a;
    cal->s_b += i_b;
    cal->s_c += i_c;
    cal->k += 1;
    if (cal->k == cal->n) {
        double inv = 1.0 / (double)cal->n;
        cal->o_a = cal->s_a * inv;
        cal->o_b = cal->s_b * inv;
        cal->o_c = cal->s_c * inv;
    }
}
