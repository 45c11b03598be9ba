/* Sensing (plant_sensors.h). */
#include "plant_sensors.h"

#include <math.h>

#include "plant_const.h"

/* floor as Python's math.floor, which refuses NaN and infinity */
static int checked_floor(double x, double *out)
{
    if (isnan(x)) return PLANT_SENSE_NAN;
    if (isinf(x)) return PLANT_SENSE_INF;
    *out = floor(x);
    return PLANT_SENSE_OK;
}

static int quant_i(const plant_sensors *s, double x, double *out)
{
    double lsb = s->lsb_i;
    if (lsb == 0.0) {
        *out = x;
        return PLANT_SENSE_OK;
    }
    double code;
    int e = checked_floor(x / lsb + 0.5, &code);
    if (e) return e;
    double lo = -s->code_max - 1.0;
    code = code < s->code_max ? code : s->code_max;
    code = lo > code ? lo : code;
    *out = code * lsb;
    return PLANT_SENSE_OK;
}

int plant_sensors_measure(const plant_sensors *s, const double i[3], double u_dc, double out[4])
{
    double m[3];
    for (int k = 0; k < 3; k++) m[k] = s->g[k] * i[k] + s->o[k];
    double sd = s->noise_i;
    if (sd > 0.0)
        for (int k = 0; k < 3; k++) {
            double v;
            if (s->gauss(s->gauss_ctx, sd, &v)) return PLANT_SENSE_NOISE;
            m[k] += v;
        }
    for (int k = 0; k < 3; k++) {
        int e = quant_i(s, m[k], &out[k]);
        if (e) return e;
    }
    double mu = s->gain_u * u_dc + s->off_u;
    if (s->noise_u > 0.0) {
        double v;
        if (s->gauss(s->gauss_ctx, s->noise_u, &v)) return PLANT_SENSE_NOISE;
        mu += v;
    }
    double lsb = s->lsb_u;
    if (lsb != 0.0) {
        double code;
        int e = checked_floor(mu / lsb + 0.5, &code);
        if (e) return e;
        code = s->ucode_max < code ? s->ucode_max : code;
        code = 0.0 > code ? 0.0 : code;
        mu = code * lsb;
    }
    out[3] = mu;
    return PLANT_SENSE_OK;
}

double plant_encoder_angle(double theta_m, double w_m, double delay_s, long counts)
{
    double th = theta_m - w_m * delay_s;
    if (counts <= 0) return plant_py_mod(th, PLANT_TWO_PI);
    double n = (double)counts;
    double count = plant_py_mod(floor(th * n / PLANT_TWO_PI), n);
    return count * PLANT_TWO_PI / n;
}
