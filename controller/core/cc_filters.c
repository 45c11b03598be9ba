/* Wen's demodulation filters, eqs. (11)-(13) (cc_filters.h). */
#include <math.h>

#include "cc_filters.h"

void cc_fo_init(cc_fo_t *f, double b0, double b1, double a1)
{
    f->b0 = b0;
    f->b1 = b1;
    f->a1 = a1;
    f->s = 0.0;
}

void cc_fo_reset(cc_fo_t *f) { f->s = 0.0; }

double cc_fo_step(cc_fo_t *f, double x)
{
    double y = f->b0 * x + f->s;
    f->s = f->b1 * x - f->a1 * y;
    return y;
}

void cc_fo2_init(cc_fo2_t *f, double b0, double b1, double a1)
{
    f->b0 = b0;
    f->b1 = b1;
    f->a1 = a1;
    cc_fo2_reset(f);
}

void cc_fo2_reset(cc_fo2_t *f) { f->s1 = f->s2 = 0.0; }

void cc_fo2_step(cc_fo2_t *f, double x_1, double x_2, double *y1, double *y2)
{
    double y_1 = f->b0 * x_1 + f->s1;
    double y_2 = f->b0 * x_2 + f->s2;
    f->s1 = f->b1 * x_1 - f->a1 * y_1;
    f->s2 = f->b1 * x_2 - f->a1 * y_2;
    *y1 = y_1;
    *y2 = y_2;
}

void cc_bq2_init(cc_bq2_t *f, double b0, double b1, double b2, double a1, double a2)
{
    f->b0 = b0;
    f->b1 = b1;
    f->b2 = b2;
    f->a1 = a1;
    f->a2 = a2;
    cc_bq2_reset(f);
}

void cc_bq2_reset(cc_bq2_t *f) { f->p1 = f->p2 = f->q1 = f->q2 = 0.0; }

void cc_bq2_step(cc_bq2_t *f, double x_1, double x_2, double *y1, double *y2)
{
    double y_1 = f->b0 * x_1 + f->p1;
    double y_2 = f->b0 * x_2 + f->q1;
    f->p1 = f->b1 * x_1 - f->a1 * y_1 + f->p2;
    f->q1 = f->b1 * x_2 - f->a1 * y_2 + f->q2;
    f->p2 = f->b2 * x_1 - f->a2 * y_1;
    f->q2 = f->b2 * x_2 - f->a2 * y_2;
    *y1 = y_1;
    *y2 = y_2;
}

void cc_bandpass_coefficients(double w_0, double B, double T_s, double *b0, double *a1,
                              double *a2)
{
    double c = w_0 / tan(0.5 * w_0 * T_s);
    double cc = c * c;
    double ww = w_0 * w_0;
    double bc = B * c;
    double inv = 1.0 / (cc + bc + ww);
    *b0 = bc * inv;
    *a1 = 2.0 * (ww - cc) * inv;
    *a2 = (cc - bc + ww) * inv;
}
