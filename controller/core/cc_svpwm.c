/* Space-vector PWM, min-max injection (cc_svpwm.h). */
#include "cc_math.h"
#include "cc_svpwm.h"

void cc_svpwm(double u_alpha, double u_beta, double u_dc, double d[3])
{
    double u_a = u_alpha;
    double u_b = -0.5 * u_alpha + CC_SQRT3_HALF * u_beta;
    double u_c = -0.5 * u_alpha - CC_SQRT3_HALF * u_beta;
    double hi, lo;
    if (u_a > u_b) {
        hi = u_a;
        lo = u_b;
    } else {
        hi = u_b;
        lo = u_a;
    }
    if (u_c > hi)
        hi = u_c;
    else if (u_c < lo)
        lo = u_c;
    double k = 1.0 / u_dc;
    double off = 0.5 - 0.5 * (hi + lo) * k;
    d[0] = off + u_a * k;
    d[1] = off + u_b * k;
    d[2] = off + u_c * k;
    if ((hi - lo) * k > 1.0 - 1e-12) {
        d[0] = cc_clip01(d[0]);
        d[1] = cc_clip01(d[1]);
        d[2] = cc_clip01(d[2]);
    }
}

void cc_limit_magnitude(double *x_1, double *x_2, double x_max)
{
    double m2 = *x_1 * *x_1 + *x_2 * *x_2;
    if (m2 > x_max * x_max) {
        double r = x_max / sqrt(m2);
        *x_1 *= r;
        *x_2 *= r;
    }
}
