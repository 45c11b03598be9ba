/* The DC link: a source u_src behind r_dc feeding a capacitor c_dc,
 *
 *     c_dc d u_dc / dt = (u_src - u_dc) / r_dc - i_dc
 *
 * (i_dc the current the legs on the positive rail draw), advanced exactly
 * over a step
 * of length h for a constant i_dc:
 *
 *     u_dc(h) = u_inf + (u_dc(0) - u_inf) exp(-h / (r_dc c_dc)),  u_inf = u_src - r_dc i_dc
 *
 * and algebraic without a capacitor, u_dc = u_src - r_dc i_dc.
 */
#ifndef PLANT_DCLINK_H
#define PLANT_DCLINK_H

typedef struct {
    double u_src, r_dc, c_dc;
    int dynamic; /* r_dc > 0 */
} plant_dclink;

void plant_dclink_init(plant_dclink *l, double u_src, double r_dc, double c_dc);

/* Advance *u_dc over h: mean inverter current i_dc, i_dc_end at the end (A). */
void plant_dclink_update(const plant_dclink *l, double *u_dc, double h, double i_dc,
                         double i_dc_end);

/* Without a capacitor: the link voltage for the current at hand. */
double plant_dclink_algebraic(const plant_dclink *l, double i_dc);

#endif
