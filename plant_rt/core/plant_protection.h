/* The inverter's protection comparators (plant_rt._protection): a phase
 * current beyond +-i_trip, a DC-link voltage above u_dc_trip or a speed
 * beyond +-w_m_trip trips, checked in that order; NaN trips (a comparator
 * cannot be fooled by it). The latch, the first fault winning until a
 * reset, is the caller's (plant_rt.Protection).
 */
#ifndef PLANT_PROTECTION_H
#define PLANT_PROTECTION_H

/* Fault codes (plant_rt.FAULT_* are these, read from the binding). The
 * watchdog (a missing command) is the plant node's, not a comparator's. */
enum {
    PLANT_FAULT_NONE = 0,
    PLANT_FAULT_WATCHDOG = 1,
    PLANT_FAULT_OVER_CURRENT = 2,
    PLANT_FAULT_OVER_VOLTAGE = 3,
    PLANT_FAULT_OVER_SPEED = 4,
};

typedef struct {
    double i_trip, u_dc_trip, w_m_trip;
} plant_protection;

/* The fault the values trip, or PLANT_FAULT_NONE. */
int plant_protection_check(const plant_protection *p, double i_a, double i_b, double i_c,
                           double u_dc, double w_m);

#endif
