/* Wen's demodulation filters, eqs. (11)-(13), in their discrete realisations.
 *
 * The coefficients come from the bilinear transform of the continuous
 * prototypes (controller/_filters.py, discretize); the band-pass centre can be
 * retuned every period (cc_bandpass_coefficients, eq. (11) pre-warped).
 *   first order, one or two signals (DF2T): y = b0 x + s;  s = b1 x - a1 y
 *   biquad on a pair of signals (DF2T):
 *     y = b0 x + p1;  p1 = b1 x - a1 y + p2;  p2 = b2 x - a2 y
 */
#ifndef CC_FILTERS_H
#define CC_FILTERS_H

typedef struct { double b0, b1, a1, s; } cc_fo_t;
typedef struct { double b0, b1, a1, s1, s2; } cc_fo2_t;
typedef struct { double b0, b1, b2, a1, a2, p1, p2, q1, q2; } cc_bq2_t;

void cc_fo_init(cc_fo_t *f, double b0, double b1, double a1);
void cc_fo_reset(cc_fo_t *f);
double cc_fo_step(cc_fo_t *f, double x);

void cc_fo2_init(cc_fo2_t *f, double b0, double b1, double a1);
void cc_fo2_reset(cc_fo2_t *f);
void cc_fo2_step(cc_fo2_t *f, double x_1, double x_2, double *y1, double *y2);

void cc_bq2_init(cc_bq2_t *f, double b0, double b1, double b2, double a1, double a2);
void cc_bq2_reset(cc_bq2_t *f);
void cc_bq2_step(cc_bq2_t *f, double x_1, double x_2, double *y1, double *y2);

/* (b0, a1, a2) of B s / (s^2 + B s + w_0^2), bilinear, pre-warped at w_0 (b1 = 0,
 * b2 = -b0): Wen eq. (11) centred on w_0 */
void cc_bandpass_coefficients(double w_0, double B, double T_s, double *b0, double *a1,
                              double *a2);

#endif
