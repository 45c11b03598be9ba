/*
 * Sensored field-oriented speed control of a PMSM: the control law only.
 *
 * No I/O, no dynamic allocation, no global state: one foc_t per drive, one
 * foc_step() per PWM period.  ref_controller.c feeds it from CAN frames; a
 * drive firmware feeds it from its ADC and encoder interrupts.
 */
#ifndef FOC_H
#define FOC_H

#include <stdbool.h>

/* Two-degree-of-freedom PI controller with anti-windup:
 *     u   = k_t r - k_p y + u_i                      (output, before limiting)
 *     u_i = u_i + T_s k_i [ (r - y) + (u_lim - u) / k_t ]
 * where u_lim is the output actually applied (after limiting). */
typedef struct {
    double k_p;  /* proportional gain on the measurement */
    double k_i;  /* integral gain */
    double k_t;  /* reference gain */
    double T_s;  /* sampling period [s] */
    double u_i;  /* integral state */
    double e;    /* last error r - y */
    double u;    /* last unlimited output */
} pi_ctrl_t;

/* Controller parameters and state. */
typedef struct {
    /* motor model and period */
    double T_s;     /* control period [s] */
    double n_p;     /* pole pairs */
    double R_s;     /* stator resistance [ohm] */
    double L_d;     /* d inductance [H] */
    double L_q;     /* q inductance [H] */
    double psi_f;   /* PM flux linkage [V s] */
    double i_max;   /* current limit, peak [A] */
    double tau_max; /* torque limit [N m] */
    double k_tau;   /* torque constant 1.5 n_p psi_f [N m / A] */
    /* loops */
    pi_ctrl_t pi_d; /* d current [A -> V] */
    pi_ctrl_t pi_q; /* q current [A -> V] */
    pi_ctrl_t pi_w; /* mechanical speed [rad/s -> N m] */
    /* commands */
    double w_m_ref; /* mechanical speed reference [rad/s] */
    bool enabled;
} foc_t;

/* One period's measurements (the sample instant t = k T_s). */
typedef struct {
    double i_a, i_b; /* phase currents [A] (i_c = -i_a - i_b) */
    double u_dc;     /* DC-link voltage [V] */
    double theta_e;  /* electrical rotor angle [rad] */
    double w_m;      /* mechanical rotor speed [rad/s] */
} foc_input_t;

/* Duties for the next period and the internals worth logging. */
typedef struct {
    double d_a, d_b, d_c; /* phase duty cycles, 0..1 */
    bool enable;          /* false: all switches open */
    double i_d, i_q;      /* measured currents, rotor frame [A] */
    double i_q_ref;       /* q current reference [A] */
} foc_output_t;

/* Gains from the bandwidths alpha_c, alpha_s (see foc.c) and the motor model. */
void foc_init(foc_t *f, double T_s, double n_p, double R_s, double L_d, double L_q,
              double psi_f, double J, double i_max, double tau_max, double alpha_c,
              double alpha_s);

/* Mechanical speed reference [rad/s]. */
void foc_set_speed_ref(foc_t *f, double w_m_ref);

/* Enable (integrators reset) or disable (switches open) the inverter. */
void foc_enable(foc_t *f, bool enable);

/* Duties for period k + 1 from the measurements of period k. */
void foc_step(foc_t *f, const foc_input_t *in, foc_output_t *out);

/* Min-max (space-vector) PWM: duties 0..1 for the voltage (u_alpha, u_beta). */
void svpwm(double u_alpha, double u_beta, double u_dc, double *d_a, double *d_b, double *d_c);

#endif /* FOC_H */
