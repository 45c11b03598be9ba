/* Open-leg faults (plant_leg.h). */
#include "plant_leg.h"

#include <math.h>

#include "plant_const.h"

int plant_leg_gate(int f, int state)
{
    if (f == PLANT_LEG_OPEN_PHASE) return PLANT_DEAD;
    if (f == PLANT_LEG_OPEN_UPPER && state == PLANT_HIGH) return PLANT_DEAD;
    if (f == PLANT_LEG_OPEN_LOWER && state == PLANT_LOW) return PLANT_DEAD;
    return state;
}

void plant_leg_average(int f, double i_x, double eps, double v_norm, double d, double u_dc,
                       double v_f, plant_leg_avg *out)
{
    double v_low = -v_f, v_high = u_dc + v_f;
    out->flt = 0;
    out->cond = 0;
    out->lo = -HUGE_VAL;
    out->hi = HUGE_VAL;
    if (i_x > eps) {
        out->cond = 1;
        if (f == PLANT_LEG_OPEN_LOWER) {
            out->v = v_norm;
            out->pos = d;
        } else {
            out->v = v_low;
            out->pos = 0.0;
        }
        return;
    }
    if (i_x < -eps) {
        out->cond = -1;
        if (f == PLANT_LEG_OPEN_UPPER) {
            out->v = v_norm;
            out->pos = d;
        } else {
            out->v = v_high;
            out->pos = 1.0;
        }
        return;
    }
    out->flt = 1;
    out->v = 0.0;
    out->pos = 0.0;
    out->pos_lo = 0.0;
    out->pos_hi = 0.0;
    if (f == PLANT_LEG_OPEN_UPPER) {
        out->lo = v_low; /* the lower diode takes a positive current */
        out->hi = v_norm; /* the PWM mean drives a negative one */
        out->pos_hi = d;
    } else if (f == PLANT_LEG_OPEN_LOWER) {
        out->lo = v_norm;
        out->pos_lo = d;
        out->hi = v_high; /* the upper diode takes a negative current */
        out->pos_hi = 1.0;
    }
}
