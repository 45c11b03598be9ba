/* Constants shared by the blocks of the plant core (plain C99, no state).
 *
 * The values are the doubles Python computes for math.sqrt(3.0),
 * 1.0 / math.sqrt(3.0) and 2.0 * math.pi (printed by repr, which round
 * trips), so that the core rounds as the reference model does.
 */
#ifndef PLANT_CONST_H
#define PLANT_CONST_H

#define PLANT_SQRT3 1.7320508075688772
#define PLANT_INV_SQRT3 0.5773502691896258
#define PLANT_TWO_PI 6.283185307179586

/* Phase axes a, b, c at 0, +120 and -120 degrees (cos, sin). */
static const double PLANT_COS_PHI[3] = {1.0, -0.5, -0.5};
static const double PLANT_SIN_PHI[3] = {0.0, 0.5 * PLANT_SQRT3, -0.5 * PLANT_SQRT3};

/* Gate states of a leg over a sub-interval (plant_pwm.h). */
#define PLANT_LOW 0
#define PLANT_HIGH 1
#define PLANT_DEAD 2
#define PLANT_OFF (-1) /* command after a disabled period: neither switch */

/* Python's float %: the result takes the sign of the divisor. */
double plant_py_mod(double x, double m);

#endif
