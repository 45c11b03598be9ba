/* Open-leg faults of the inverter: an open phase and an open switch.
 *
 * A leg's fault (plant.leg[x]) changes which devices can conduct; the
 * machine's equations stay those of plant_machine.h, constrained as below.
 * The semantics of the power stage are those of a voltage-source inverter
 * with antiparallel (freewheeling) diodes (Mohan, Undeland and Robbins,
 * Power Electronics, 3rd ed., Wiley 2003, ch. 8); the open-circuit fault
 * classes are those of Kastha and Bose, "Investigation of fault modes of
 * voltage-fed inverter system for induction motor drive", IEEE Trans. Ind.
 * Appl. 30(4), 1994 (single-switch open, single-phase open).
 *
 * PLANT_LEG_OPEN_PHASE: the phase's connection opens. Both switches of the
 * leg turn off at the opening; the current that was flowing commutates to
 * the leg's freewheeling diode that carries it (i_x > 0: the lower diode,
 * pole voltage -v_f; i_x < 0: the upper diode, u_dc + v_f), so the whole
 * DC-link voltage opposes it and it falls to zero, typically within
 * L i_x / u_dc (a fraction of a period); at its zero the phase is open and
 * its current is held at zero for the rest of the fault, whatever its
 * terminal voltage (the conductor is open, no diode can take it again).
 * With a star-connected machine the two remaining phases carry i and -i.
 * The reduced model is the d-q model under the constraint i_x = 0
 * (plant_machine_f_float): leg x adds (2/3) v_x e^{j phi_x} to the stator
 * voltage, v_x solved from d i_x / dt = 0, so v_x is the open terminal's
 * voltage (the induced voltage there, referred to the negative rail); the
 * d-q currents stay on the line i_d cos(theta_e - phi_x) - i_q sin(theta_e
 * - phi_x) = 0.
 *
 * PLANT_LEG_OPEN_UPPER / _LOWER: one switch never conducts; its antiparallel
 * diode does. When the gate calls for the open device the leg has no
 * switch on, as in a dead interval: its pole voltage follows the current's
 * sign (i_x > 0 through the lower diode, -v_f; i_x < 0 through the upper
 * diode, u_dc + v_f), and at zero current it floats. So with the upper
 * switch open a positive phase current is only possible through the lower
 * diode, which pins the leg to the negative rail: the leg can source no
 * positive current against the machine's voltage (and symmetrically for
 * the lower switch). In the switching model the gate timeline is changed
 * (plant_leg_gate); in the average model the leg's period mean is
 * plant_leg_average's.
 */
#ifndef PLANT_LEG_H
#define PLANT_LEG_H

enum {
    PLANT_LEG_OK = 0,
    PLANT_LEG_OPEN_PHASE = 1,
    PLANT_LEG_OPEN_UPPER = 2,
    PLANT_LEG_OPEN_LOWER = 3
};

/* The gate state (PLANT_LOW, _HIGH, _DEAD) a leg with fault f is in when
 * its gate calls for state: an on-interval of the open device, and every
 * interval of an open phase, is a dead interval. */
int plant_leg_gate(int f, int state);

/* What a faulted leg does over an average-model interval. */
typedef struct {
    double v;  /* pole voltage (V) when the leg conducts */
    int cond;  /* +1: the current may only fall to zero from above, -1 from below, 0: free */
    int flt;   /* the current is zero and the leg floats: v is solved from d i_x / dt = 0 */
    double lo, hi; /* a floating leg conducts at lo below / hi above (+-HUGE_VAL: never) */
    double pos_lo, pos_hi; /* its fraction on the positive rail when it does */
    double pos; /* the fraction of the interval the leg is on the positive rail */
} plant_leg_avg;

/* The average model of leg x with fault f (not PLANT_LEG_OK) for current
 * i_x (eps: zero within it): v_norm is the healthy leg's mean pole voltage
 * for the effective duty d (dead time and drops included), v_f the diode
 * drop.
 *   open phase: i > 0 -> -v_f (cond +1), i < 0 -> u_dc + v_f (cond -1),
 *     i = 0 -> floats, never conducts (lo = -inf, hi = +inf);
 *   open upper: i > 0 -> -v_f for the whole period (cond +1), i < 0 ->
 *     v_norm (cond -1: the current cannot cross zero through the open
 *     switch), i = 0 -> floats in [-v_f, v_norm]: below it the lower diode
 *     takes a positive current, above it the leg's PWM mean drives it
 *     negative;
 *   open lower: mirror: i < 0 -> u_dc + v_f (cond -1), i > 0 -> v_norm
 *     (cond +1), i = 0 -> floats in [v_norm, u_dc + v_f]. */
void plant_leg_average(int f, double i_x, double eps, double v_norm, double d, double u_dc,
                       double v_f, plant_leg_avg *out);

#endif
