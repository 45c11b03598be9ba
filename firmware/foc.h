/*
 * Sensored field-oriented speed control of a PMSM for the reference firmware:
 * the bench's own controller core (controller/core/, shipped by `bench codegen`
 * in core/), run with its sensored estimator.
 *
 * This file adds no control arithmetic: the Clarke and Park transforms, the
 * PIs, the limits, the decoupling, the delay compensation and the SVPWM are
 * cc_foc_step()'s, the code the bench's in-process and node controllers run.
 * What is the firmware's own is the gain design from two bandwidths (foc.c)
 * and the mapping of an encoder reading to the core's measurement.
 *
 * No I/O, no dynamic allocation, no global state: one foc_t per drive, one
 * foc_step() per PWM period.  ref_controller.c feeds it from CAN frames; a
 * drive firmware feeds it from its ADC and encoder interrupts.
 */
#ifndef FOC_H
#define FOC_H

#include <stdbool.h>

#include "cc_foc.h"

/* The core's controller and the period it runs at. */
typedef struct {
    cc_foc_t core;
    double T_s; /* control period [s] */
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

#endif /* FOC_H */
