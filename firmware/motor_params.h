/*
 * Motor, inverter and loop parameters of the reference controller.
 *
 * The defaults are the bench's `wen2023` plant preset (Wen et al. 2023,
 * Table 4, completed as documented in the preset): the controller's own copy
 * of the motor model, as a drive firmware would have it.  Build with
 * -DMOTOR_R_S=... etc. to change one without editing this file.
 * All units SI: ohm, henry, weber (V s), kg m^2, ampere, newton metre, second.
 */
#ifndef MOTOR_PARAMS_H
#define MOTOR_PARAMS_H

/* PWM (= control) frequency [Hz]: one PhaseSamples frame and one PwmDuty
 * frame per period. */
#ifndef PWM_FREQ_HZ
#define PWM_FREQ_HZ 10000.0
#endif

/* Pole pairs. */
#ifndef MOTOR_N_P
#define MOTOR_N_P 4
#endif

/* Stator resistance [ohm]. */
#ifndef MOTOR_R_S
#define MOTOR_R_S 2.8
#endif

/* d- and q-axis inductances [H] (interior PM: L_d < L_q). */
#ifndef MOTOR_L_D
#define MOTOR_L_D 57e-3
#endif
#ifndef MOTOR_L_Q
#define MOTOR_L_Q 82e-3
#endif

/* Permanent-magnet flux linkage [V s]. */
#ifndef MOTOR_PSI_F
#define MOTOR_PSI_F 0.30
#endif

/* Total inertia of rotor and load [kg m^2]. */
#ifndef MOTOR_J
#define MOTOR_J 0.003
#endif

/* Peak phase-current limit [A]. */
#ifndef MOTOR_I_MAX
#define MOTOR_I_MAX 8.0
#endif

/* Torque limit [N m]: 1.5 x the rated 7.5 N m. */
#ifndef MOTOR_TAU_MAX
#define MOTOR_TAU_MAX 11.25
#endif

/* Current-loop bandwidth alpha_c [rad/s]: 2 pi 100 Hz, 1/100 of the PWM rate,
 * so the one-period computation delay costs little phase margin. */
#ifndef ALPHA_C
#define ALPHA_C (2.0 * 3.14159265358979323846 * 100.0)
#endif

/* Speed-loop bandwidth alpha_s [rad/s]: 2 pi 5 Hz = alpha_c / 20, well
 * separated from the current loop. */
#ifndef ALPHA_S
#define ALPHA_S (2.0 * 3.14159265358979323846 * 5.0)
#endif

#endif /* MOTOR_PARAMS_H */
