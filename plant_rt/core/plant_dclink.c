/* DC link (plant_dclink.h). */
#include "plant_dclink.h"

#include <math.h>

void plant_dclink_init(plant_dclink *l, double u_src, double r_dc, double c_dc)
{
    l->u_src = u_src;
    l->r_dc = r_dc;
    l->c_dc = c_dc;
    l->dynamic = r_dc > 0.0;
}

void plant_dclink_update(const plant_dclink *l, double *u_dc, double h, double i_dc,
                         double i_dc_end)
{
    double r = l->r_dc;
    if (l->c_dc > 0.0) {
        double u_inf = l->u_src - r * i_dc;
        *u_dc = u_inf + (*u_dc - u_inf) * exp(-h / (r * l->c_dc));
    } else {
        *u_dc = l->u_src - r * i_dc_end;
    }
}

double plant_dclink_algebraic(const plant_dclink *l, double i_dc)
{
    return l->u_src - l->r_dc * i_dc;
}
