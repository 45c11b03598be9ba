/* The plant's period step: machine, inverter, DC link and sensor instant,
 * one PWM period per call (plant_rt.Plant; DESIGN.md, "Timing model").
 *
 * Portable C99: no allocation, no global state. An instance (plant) holds
 * the derived constants and the states; plant_init makes it from the design
 * parameters (plant_pars), plant_set_pars changes the parameters between
 * two periods and keeps the states, plant_step advances one enabled period,
 * plant_step_n advances n periods with an array of duties.
 *
 * Average model (Holmes and Lipo 2003): the period-mean pole
 * voltages d_x u_dc plus the dead-time and device-drop errors
 * (plant_pwm.h), constant in alpha-beta over the period, integrated by
 * RK4 in substeps (plant_rk4.h). Switching model: the period is cut at every
 * edge and dead-interval end of the carrier timeline (plant_pwm.h), at the
 * substep grid and at the sensor instant; each sub-interval, over which
 * every pole voltage is constant, is one RK4 step. A diode that stops
 * conducting inside a dead interval clamps its phase to zero current (the
 * phase floats, plant_machine_f_float). The DC link (plant_dclink.h) takes
 * the current of the legs on the positive rail. A leg with an open-leg fault
 * (plant_leg.h, plant_set_legs) runs the same models with its devices
 * constrained; without one every result is unchanged.
 */
#ifndef PLANT_H
#define PLANT_H

#include "plant_dclink.h"
#include "plant_leg.h"
#include "plant_machine.h"
#include "plant_pwm.h"
#include "plant_rk4.h"
#include "plant_sensors.h"

#define PLANT_MAX_SUBSTEPS 64

/* Load torque at time t and speed w_m; returns 0, or nonzero on error. */
typedef int (*plant_load_fn)(void *ctx, double t, double w_m, double *tau);

/* Design parameters. */
typedef struct {
    plant_machine_pars machine;
    double T_s;      /* PWM period (s) */
    int substeps;    /* RK4 steps per period, 1..PLANT_MAX_SUBSTEPS */
    double t_delay;  /* sensor delay (s), in [0, T_s) */
    int switching;   /* the switching inverter model */
    int peak;        /* the carrier's peak falls on the period boundary */
    double u_dc;     /* DC source voltage (V) */
    double t_dead;   /* dead time (s) */
    double v_ce;     /* transistor drop (V) */
    double v_f;      /* diode drop (V) */
    double r_dc;     /* DC-link source resistance (ohm), 0: stiff link */
    double c_dc;     /* DC-link capacitance (F), 0: none */
} plant_pars;

/* Instance. */
typedef struct {
    plant_machine m;
    plant_pwm pwm;
    plant_dclink dc;
    plant_sensors sens;
    /* states */
    plant_state x;
    plant_trig trig; /* cos and sin of the last electrical angle (plant_trig_of) */
    double u_dc;
    int imposed; /* the speed is held (dynamometer) */
    /* outputs of the last period: mean stator voltage, the delayed sample */
    double u_al, u_be;
    double meas[4];
    /* period, integration grid, sensor instant */
    double T_s, h, i_eps, t_meas;
    int substeps;
    double v_ce, v_f, t_dead;
    int switching, drops, avg_general;
    double grid[PLANT_MAX_SUBSTEPS];
    int n_grid;
    double cuts[PLANT_MAX_SUBSTEPS];
    int n_cuts;
    double seg_a[PLANT_MAX_SUBSTEPS + 1], seg_b[PLANT_MAX_SUBSTEPS + 1];
    long seg_j[PLANT_MAX_SUBSTEPS + 1];
    int n_segs;
    /* load */
    plant_load_fn load;
    void *load_ctx;
    int load_const;
    double tau_const;
    int err; /* the load callback failed in this period */
    /* open-leg faults (plant_leg.h): PLANT_LEG_* per leg, and whether any is set */
    int leg[3];
    int any_leg;
    /* energy meter (off unless metering is set) */
    int metering;
    plant_meter meter;

    /* Periods that ended with |i_s| beyond the flux map's checked range
     * (PLANT_FLUX_RANGE i_max: plant_flux_cross_ext), and that range squared (A^2). */
    long n_out;
    double out_r2;
} plant;

/* Errors. */
enum { PLANT_OK = 0, PLANT_ERR_PARS = 1, PLANT_ERR_LOAD = 2 };

/* Make the instance: constants from p, states zero, u_dc = u_src, a
 * constant zero load, ideal sensors. Returns PLANT_ERR_PARS for a substep
 * count out of range. */
int plant_init(plant *pl, const plant_pars *p);

/* New parameters between two periods (a fault, a changed machine): the
 * constants are made again, the states and the PWM timeline are kept. The
 * period, the substeps, the sensor delay and the inverter model must be
 * those of plant_init (PLANT_ERR_PARS otherwise). Without a dynamic DC
 * link u_dc follows the new source voltage. */
int plant_set_pars(plant *pl, const plant_pars *p);

/* The open-leg faults of legs a, b, c (PLANT_LEG_*, plant_leg.h) from the
 * next period on; PLANT_ERR_PARS for a value out of range. */
int plant_set_legs(plant *pl, const int leg[3]);

/* One enabled period from t0 (s) with duties clamped to [0, 1]. */
int plant_step(plant *pl, double d_a, double d_b, double d_c, double t0);

/* One period from t0 (s) with all switches open: the legs are a diode
 * bridge. A conducting phase sits on the negative rail when its current
 * flows into the machine and on the positive rail otherwise; a phase whose
 * current is zero floats (its pole voltage solved from d i_x / dt = 0) and
 * conducts once that voltage leaves [0, u_dc]; with all currents zero the
 * bridge rectifies when the line back-EMF exceeds u_dc. Ideal diodes; the
 * conduction state is decided at the start of each substep and a current
 * that changes sign inside one is set to zero at its end. An open phase
 * (plant_leg.h) conducts through its diodes until its current is zero and
 * then never again. */
int plant_step_off(plant *pl, double t0);

/* Per-period output of plant_step_n. */
typedef struct {
    double i_d, i_q, w_m, th_m, u_dc, u_al, u_be;
} plant_out;

/* n enabled periods k0 .. k0 + n - 1 (t0 = k T_s), duties[3 k + x];
 * out (may be NULL) receives the states after each. Stops at an error and
 * returns it; *done receives the periods completed. */
int plant_step_n(plant *pl, long k0, long n, const double *duties, plant_out *out, long *done);

/* Phase back-EMF -w_e psi_d(0) sin(theta_e - phi_x) now (V). */
void plant_back_emf(const plant *pl, double e[3]);

/* The true phase currents now. */
void plant_currents(const plant *pl, double i[3]);

#endif
