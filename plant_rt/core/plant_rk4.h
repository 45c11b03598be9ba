/* Classic fourth-order Runge-Kutta step of the machine's states.
 *
 * The classic fourth-order method of Kutta (1901), as tabulated in Butcher,
 * Numerical Methods for Ordinary Differential Equations (Wiley, 2016): stage
 * offsets 0, h/2, h/2, h and weights 1, 2, 2, 1 over 6. The states are (i_d, i_q, w_m, theta_m); the
 * stator voltage is constant in alpha-beta over the step, so each stage
 * rotates it into d-q at its own rotor angle. One kernel for every flux map
 * and every stage kind: the stage derivative is chosen by a switch.
 */
#ifndef PLANT_RK4_H
#define PLANT_RK4_H

#include "plant_machine.h"

/* Energy integrals (J) and the charge of each phase in the last period
 * (A s), integrated with the states (plant_rt.EnergyMeter). */
typedef struct {
    double e_in, e_cu, e_em, e_fric, e_load;
    double q_a, q_b, q_c;
} plant_meter;

/* Stage kinds: the hot stage (plant_machine_stage), the general stage
 * (plant_machine_f) and the stage with one phase floating
 * (plant_machine_f_float). */
enum { PLANT_STAGE_HOT = 0, PLANT_STAGE_GENERAL = 1, PLANT_STAGE_FLOAT = 2 };

/* One step of length h. kind PLANT_STAGE_FLOAT needs the floating phase fx
 * (0..2) and the voltage (u_al, u_be) of the other legs; *ua, *ub (may be
 * NULL for the hot stage) receive the RK4-weighted mean stator voltage.
 * With a meter (general and floating stages only) the energy flows are
 * integrated with the stages' weights from the pole voltages v (v[fx]
 * replaced by the floating leg's voltage at each stage). */
void plant_rk4(const plant_machine *m, plant_state *s, int imposed, int kind, int fx, double h,
               double u_al, double u_be, double tau_L, double *ua, double *ub, plant_meter *meter,
               const double v[3]);

#endif
