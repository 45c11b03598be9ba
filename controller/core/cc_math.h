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

#endif /* CC_MATH_H */
