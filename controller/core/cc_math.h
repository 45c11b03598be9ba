/* Controller core: arithmetic shared by every block.
 *
 * The controller core (controller/core/) is plain C99: no Python.h, no
 * allocation, no global state.  Each block is an instance struct of its
 * derived constants and states, an _init from its design values and a
 * per-sample _step (the CMSIS-DSP controller style).  The gains and filter
 * coefficients are designed in Python (controller/_design.py and the
 * estimators' modules, each with its derivation) and handed to the _init
 * functions; controller/_cctl.c binds the core to Python and firmware/
 * builds on it.
 *
 * Build with -ffp-contract=off (no fused multiply-add): the operation order
 * written here is the one the paper suite's reference numbers were made with.
 */
#ifndef CC_MATH_H
#define CC_MATH_H

#include <float.h>
#include <math.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

#define CC_TWO_PI (2.0 * M_PI)
/* sqrt(3) as the nearest double (the value libm's sqrt(3.0) returns) */
#define CC_SQRT3 1.7320508075688772
#define CC_SQRT3_INV (1.0 / CC_SQRT3)
#define CC_SQRT3_HALF (0.5 * CC_SQRT3)

/* x mod m with the sign of the divisor (floored modulo, as Python's float %) */
static inline double cc_mod(double x, double m)
{
    double mod = fmod(x, m);
    if (mod != 0.0) {
        if ((m < 0.0) != (mod < 0.0))
            mod += m;
    } else {
        mod = copysign(0.0, m);
    }
    return mod;
}

static inline double cc_clip01(double d) { return d < 0.0 ? 0.0 : (d > 1.0 ? 1.0 : d); }

/* sqrt(x^2 + y^2) rounded as CPython's math.hypot(x, y) rounds it (the Python engine's
 * normalise = "measured"), bit for bit: CPython's vector_norm (Modules/mathmodule.c) for
 * two arguments.  max(|x|, |y|) is scaled by a power of two into [0.5, 1) (lossless);
 * each square is split exactly into hi + lo (Dekker's product, Veltkamp's split by
 * 2^27 + 1), the his summed from 1.0 with their rounding errors kept (Neumaier), the
 * square root taken, and one differential correction h += (sum - h^2) / (2 h) applied
 * with the residual sum - h^2 formed the same exact way.  Needs -ffp-contract=off: a
 * fused multiply-add breaks the exact split.  inf beats nan, as in CPython.
 *
 * One algorithm for every build (the CPython extension, the native node library, the
 * firmware), no build switch.  CPython's versions part only where max(|x|, |y|) <
 * 2^-1024 and the scale 2^-e overflows: 3.12 and later divide both by DBL_MIN and run
 * the same steps (the one here), 3.11 divides by the max and sums the plain squares.
 * The later one is taken because every interpreter after 3.11 has it and it is the one
 * without a second algorithm.  Why a 3.11 Python engine still gives the same trace: the
 * result there is below sqrt(2) 2^-1024 < DBL_MIN = 2^-1022 on both, and every caller
 * takes max(hypot, amp_floor) with amp_floor a tenth of a model HF amplitude (A or A^2:
 * 4.3e-3 A and 1.0e-3 A^2 on wen2023 at 50 V, below DBL_MIN only for V_h under about
 * 1e-150 V), so the floor wins on either algorithm and err is the same bits.
 * tests/test_cc_hypot.py: math.hypot bit for bit over the normal range on every
 * interpreter, over the subnormal range on 3.12+, and DBL_MIN hypot(x / DBL_MIN,
 * y / DBL_MIN) there on every interpreter. */
typedef struct {
    double hi, lo;
} cc_dl_t;

/* a + b = hi + lo exactly, |a| >= |b| (Dekker's fast two-sum) */
static inline cc_dl_t cc_dl_fast_sum(double a, double b)
{
    double x = a + b;
    cc_dl_t r = {x, (a - x) + b};
    return r;
}

/* x y = hi + lo exactly (Dekker's product on Veltkamp's split) */
static inline cc_dl_t cc_dl_mul(double x, double y)
{
    double t = x * 134217729.0;
    double xh = t - (t - x), xl = x - xh;
    t = y * 134217729.0;
    double yh = t - (t - y), yl = y - yh;
    double p = xh * yh;
    double q = xh * yl + xl * yh;
    double z = p + q;
    cc_dl_t r = {z, p - z + q + xl * yl};
    return r;
}

/* the norm of (a, b), 0 <= a, b <= m, m = max(a, b) normal-scalable (m >= 2^-1024) */
static inline double cc_norm2_scaled(double a, double b, double m)
{
    int e;
    (void)frexp(m, &e);
    double scale = ldexp(1.0, -e);
    double v[2] = {a * scale, b * scale};
    double csum = 1.0, frac1 = 0.0, frac2 = 0.0;
    cc_dl_t pr, sm;
    for (int i = 0; i < 2; i++) {
        pr = cc_dl_mul(v[i], v[i]);
        sm = cc_dl_fast_sum(csum, pr.hi);
        csum = sm.hi;
        frac1 += pr.lo;
        frac2 += sm.lo;
    }
    double h = sqrt(csum - 1.0 + (frac1 + frac2));
    pr = cc_dl_mul(-h, h);
    sm = cc_dl_fast_sum(csum, pr.hi);
    csum = sm.hi;
    frac1 += pr.lo;
    frac2 += sm.lo;
    double x = csum - 1.0 + (frac1 + frac2);
    h += x / (2.0 * h);
    return h / scale;
}

static inline double cc_hypot(double x, double y)
{
    double a = fabs(x), b = fabs(y);
    if (isinf(a) || isinf(b))
        return INFINITY;
    if (isnan(a) || isnan(b))
        return NAN;
    double m = a > b ? a : b;
    if (m == 0.0)
        return m;
    int e;
    (void)frexp(m, &e);
    if (e >= -1023)
        return cc_norm2_scaled(a, b, m);
    /* below 2^-1024: both scaled up by DBL_MIN (exact), as CPython 3.12+ */
    return DBL_MIN * cc_norm2_scaled(a / DBL_MIN, b / DBL_MIN, m / DBL_MIN);
}

#endif /* CC_MATH_H */
