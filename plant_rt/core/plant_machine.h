/* The IPMSM in the rotor d-q frame and its flux map.
 *
 * Wen et al. eq. (1) and Xue et al. eq. (1), written on flux linkages
 * (amplitude-invariant transformation, d axis on the magnet's north):
 *
 *     d psi_d / dt = u_d - R_s i_d + w_e psi_q
 *     d psi_q / dt = u_q - R_s i_q - w_e psi_d
 *     tau_e = 1.5 n_p (psi_d i_q - psi_q i_d)
 *     J d w_m / dt = tau_e - tau_L - b w_m
 *
 * Flux map (plant_rt._machine: SaturationPars, CrossSaturationPars):
 *
 *     psi_d(i_d) = psi_f + L_d (i_d - sigma i_sat (sqrt(1 + x^2) - 1)),  x = i_d / i_sat
 *     L_dd(i_d)  = L_d (1 - sigma x / sqrt(1 + x^2))
 *
 * and, with cross-saturation, the co-energy terms in c_dq (flux_dq).
 */
#ifndef PLANT_MACHINE_H
#define PLANT_MACHINE_H

/* Design parameters (plant_rt.MotorPars). */
typedef struct {
    double n_p;       /* pole pairs */
    double R_s;       /* stator resistance (ohm) */
    double L_d, L_q;  /* unsaturated inductances (H) */
    double psi_f;     /* PM flux linkage (Wb) */
    double J;         /* inertia (kg m^2) */
    double b;         /* viscous friction (N m s) */
    double i_max;     /* rated peak current (A) */
    double sat_sigma; /* SaturationPars.sigma */
    double sat_i_sat; /* SaturationPars.i_sat (A) */
    double c_dq;      /* CrossSaturationPars.c_dq (H/A^2) */
    int saturation;   /* the saturated d-axis model */
    int cross;        /* the cross-saturation model */
} plant_machine_pars;

/* Flux-map variant of the per-stage derivative. */
enum { PLANT_FLUX_LINEAR = 0, PLANT_FLUX_SAT = 1, PLANT_FLUX_CROSS = 2 };

/* Instance: derived constants. */
typedef struct {
    double n_p, R, L_d, L_q, psi_f, b, inv_J, k_tau;
    double sigma, i_sat, sig, inv_i_sat, sig_isat, c_dq, i_0;
    int sat, cross;
    int variant; /* PLANT_FLUX_* for the hot stage */
} plant_machine;

/* The mechanical and electrical states. */
typedef struct {
    double i_d, i_q; /* A */
    double w_m;      /* rad/s */
    double th_m;     /* rad */
} plant_state;

void plant_machine_init(plant_machine *m, const plant_machine_pars *p);

/* The saturated d-axis flux (the one home of the equation above); x is the
 * normalised current i_d / i_sat, formed by the caller (by the reciprocal on
 * the integration stages, by division in plant_flux_d). */
void plant_flux_d_sat(const plant_machine *m, double i_d, double x, double *psi_d, double *L_dd);

/* psi_d and L_dd of the d-axis model in use (x = i_d / i_sat). */
void plant_flux_d(const plant_machine *m, double i_d, double *psi_d, double *L_dd);

/* flux_dq with cross = 1: out = (psi_d, psi_q, L_dd, L_dq, L_qq). */
void plant_flux_dq(const plant_machine *m, double i_d, double i_q, double out[5]);

/* The state derivative of one RK4 stage for a voltage fixed in alpha-beta,
 * variant m->variant: d = (di_d, di_q, dw). */
void plant_machine_stage(const plant_machine *m, double i_d, double i_q, double w, double c,
                         double sn, double u_al, double u_be, double tau_L, int free_,
                         double d[3]);

/* Plant._f: out = (di_d, di_q, dw, tau_e). */
void plant_machine_f(const plant_machine *m, int imposed, double i_d, double i_q, double w_m,
                     double th_m, double u_al, double u_be, double tau_L, double out[4]);

/* Plant._f_float: phase x floating; out = (di_d, di_q, dw, tau_e, v_x). */
void plant_machine_f_float(const plant_machine *m, int imposed, double i_d, double i_q,
                           double w_m, double th_m, double u_al0, double u_be0, int x,
                           double tau_L, double out[5]);

/* Phase currents from the d-q currents at the rotor angle. */
void plant_currents_abc(const plant_machine *m, const plant_state *s, double out[3]);

/* Remove phase x's current by projecting i_dq onto its null line. */
void plant_zero_phase(const plant_machine *m, plant_state *s, int x);

#endif
