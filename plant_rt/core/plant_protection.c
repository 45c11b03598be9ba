/* Protection comparators (plant_protection.h). */
#include "plant_protection.h"

int plant_protection_check(const plant_protection *p, double i_a, double i_b, double i_c,
                           double u_dc, double w_m)
{
    double i = p->i_trip;
    if (!(-i <= i_a && i_a <= i && -i <= i_b && i_b <= i && -i <= i_c && i_c <= i))
        return PLANT_FAULT_OVER_CURRENT;
    if (!(u_dc <= p->u_dc_trip)) return PLANT_FAULT_OVER_VOLTAGE;
    if (!(-p->w_m_trip <= w_m && w_m <= p->w_m_trip)) return PLANT_FAULT_OVER_SPEED;
    return PLANT_FAULT_NONE;
}
