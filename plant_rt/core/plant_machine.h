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
 * and, with cross-saturation, the co-energy terms in c_dq (plant_flux_cross).
 */
#ifndef PLANT_MACHINE_H
#define PLANT_MACHINE_H

#include <math.h>
#include <stdint.h>
#include <string.h>

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

/* The flux map's checked range, |i_s| <= PLANT_FLUX_RANGE i_max (plant_rt.cross_saturation_check
 * proves the cross-saturated map positive definite there; a plant counts the periods it
 * spends beyond it), and the width beyond it, as a fraction of the range, over which the
 * cross map's currents are limited (plant_flux_cross_ext, where both are derived). */
#define PLANT_FLUX_RANGE 2.0
#define PLANT_FLUX_FADE 0.25

/* Flux-map variant of the per-stage derivative. */
enum { PLANT_FLUX_LINEAR = 0, PLANT_FLUX_SAT = 1, PLANT_FLUX_CROSS = 2 };

/* Instance: derived constants. */
typedef struct {
    double n_p, R, L_d, L_q, psi_f, b, inv_J, k_tau;
    double sigma, i_sat, sig, inv_i_sat, sig_isat, c_dq, i_0;
    double x_lim, x_w; /* the cross map's range edge and fade width (plant_flux_cross_ext) */
    int sat, cross;
    int variant; /* PLANT_FLUX_* for the hot stage */
} plant_machine;

/* The mechanical and electrical states. */
typedef struct {
    double i_d, i_q; /* A */
    double w_m;      /* rad/s */
    double th_m;     /* rad */
} plant_state;

/* The cosine and sine of the last electrical angle turned into them, kept by the
 * plant so that an angle already computed is not computed again: the sensors' angle
 * at the end of a period is the first RK4 stage's of the next, and with the speed
 * held the two middle stages share one angle, and a metered stage's energy flows are
 * taken at that stage's angle. The memo is keyed by the angle's bits
 * and filled by the same cos() and sin() calls as before, so every result is the
 * same bits as computing each time (the compiler may pair the two calls into one
 * sincos, as it did where they were written out). Zeroed: empty. */
typedef struct {
    uint64_t key; /* the bits of the angle of c and s */
    int full;     /* c and s hold a result */
    double c, s;
} plant_trig;

/* cos(th_e) and sin(th_e), from the memo t when it holds th_e (t may be NULL). */
static inline void plant_trig_of(plant_trig *t, double th_e, double *c, double *s)
{
    if (t == NULL) {
        *c = cos(th_e);
        *s = sin(th_e);
        return;
    }
    uint64_t key;
    memcpy(&key, &th_e, sizeof key);
    if (!t->full || t->key != key) {
        t->c = cos(th_e);
        t->s = sin(th_e);
        t->key = key;
        t->full = 1;
    }
    *c = t->c;
    *s = t->s;
}

void plant_machine_init(plant_machine *m, const plant_machine_pars *p);

/* The saturated d-axis flux (the one home of the equation above); x is the
 * normalised current i_d / i_sat, formed by the caller (by the reciprocal on
 * the integration stages, by division in plant_flux_d), inline on the hot
 * path. SaturationPars: psi_d = psi_f + L_d (i_d - sigma i_sat (sqrt(1 + x^2) - 1)),
 * L_dd = d psi_d / d i_d = L_d (1 - sigma x / sqrt(1 + x^2)). */
static inline void plant_flux_d_sat(const plant_machine *m, double i_d, double x, double *psi_d, double *L_dd)
{
    double r = sqrt(1.0 + x * x);
    *psi_d = m->psi_f + m->L_d * (i_d - m->sig_isat * (r - 1.0));
    *L_dd = m->L_d * (1.0 - m->sig * x / r);
}

/* The cross-saturation's co-energy terms (CrossSaturationPars, the one home of these
 * equations: the hot stage and plant_flux_dq), c = c_dq, i_0 = psi_f / L_d:
 *   psi_d += -c/2 (i_d + i_0) i_q^2,        L_dd += -c/2 i_q^2,
 *   L_qq = L_q - c/2 i_d (i_d + 2 i_0),     psi_q = L_qq i_q,
 *   L_dq = d psi_d / d i_q = d psi_q / d i_d = -c (i_d + i_0) i_q;
 * psi_d and L_dd come in as the d-axis model's and go out with the terms added.
 * Used inside |i_d|, |i_q| <= x_lim = 2 i_max, a square around the checked disc
 * |i_s| <= 2 i_max; beyond it plant_flux_cross_ext continues the map (see there).
 * plant_rt.cross_saturation_check proves the disc and, on a wider grid, the rest of
 * the plane positive definite. */
void plant_flux_cross_ext(const plant_machine *m, double i_d, double i_q, double *psi_d,
                          double *L_dd, double *psi_q, double *L_dq, double *L_qq);

static inline void plant_flux_cross(const plant_machine *m, double i_d, double i_q,
                                    double *psi_d, double *L_dd, double *psi_q,
                                    double *L_dq, double *L_qq)
{
    if (fabs(i_d) > m->x_lim || fabs(i_q) > m->x_lim) {
        plant_flux_cross_ext(m, i_d, i_q, psi_d, L_dd, psi_q, L_dq, L_qq);
        return;
    }
    double c_dq = m->c_dq, i_0 = m->i_0;
    double mm = i_d + i_0;
    double hq = 0.5 * c_dq * i_q;
    double L = m->L_q - 0.5 * c_dq * i_d * (i_d + 2.0 * i_0);
    *psi_d -= hq * mm * i_q;
    *psi_q = L * i_q;
    *L_dd -= hq * i_q;
    *L_dq = -c_dq * mm * i_q;
    *L_qq = L;
}

/* psi_d and L_dd of the d-axis model in use (x = i_d / i_sat). */
void plant_flux_d(const plant_machine *m, double i_d, double *psi_d, double *L_dd);

/* flux_dq with cross = 1: out = (psi_d, psi_q, L_dd, L_dq, L_qq). */
void plant_flux_dq(const plant_machine *m, double i_d, double i_q, double out[5]);


/* Plant._f: out = (di_d, di_q, dw, tau_e); the angle's cos and sin through the memo t
 * (plant_trig_of; may be NULL), as for plant_machine_f_float. */
void plant_machine_f(const plant_machine *m, int imposed, double i_d, double i_q, double w_m,
                     double th_m, double u_al, double u_be, double tau_L, plant_trig *t,
                     double out[4]);

/* Plant._f_float: phase x floating; out = (di_d, di_q, dw, tau_e, v_x). */
void plant_machine_f_float(const plant_machine *m, int imposed, double i_d, double i_q,
                           double w_m, double th_m, double u_al0, double u_be0, int x,
                           double tau_L, plant_trig *t, double out[5]);

/* Electromagnetic torque 1.5 n_p (psi_d i_q - psi_q i_d) (N m). */
double plant_machine_torque(const plant_machine *m, double i_d, double i_q);

/* Phase currents from the d-q currents at the rotor angle (its cos and sin through
 * the memo t, which may be NULL). */
void plant_currents_abc(const plant_machine *m, const plant_state *s, plant_trig *t,
                        double out[3]);

/* Remove phase x's current by projecting i_dq onto its null line. */
void plant_zero_phase(const plant_machine *m, plant_state *s, int x);

/* The state derivative of one RK4 stage for a voltage fixed in alpha-beta
 * (the hot path, inline): eq. (1) with the voltage rotated into d-q at the
 * stage's own angle (c, sn the cosine and sine of theta_e); with
 * cross-saturation the 2x2 incremental inductance matrix is solved,
 * L_inc d i_dq / dt = u_dq - R i_dq - w_e J psi_dq. d = (di_d, di_q, dw). */
static inline void plant_machine_stage(const plant_machine *m, double i_d, double i_q, double w, double c,
                         double sn, double u_al, double u_be, double tau_L, int free_,
                         double d[3])
{
    double R = m->R, L_q = m->L_q;
    double w_e = m->n_p * w;
    double psi_d, L_dd;
    if (m->sat) {
        plant_flux_d_sat(m, i_d, i_d * m->inv_i_sat, &psi_d, &L_dd);
    } else {
        psi_d = m->psi_f + m->L_d * i_d;
        L_dd = m->L_d;
    }
    switch (m->variant) {
    case PLANT_FLUX_CROSS: {
        double psi_q, L_dq, L_qq;
        plant_flux_cross(m, i_d, i_q, &psi_d, &L_dd, &psi_q, &L_dq, &L_qq);
        double e_d = c * u_al + sn * u_be - R * i_d + w_e * psi_q;
        double e_q = c * u_be - sn * u_al - R * i_q - w_e * psi_d;
        double inv_det = 1.0 / (L_dd * L_qq - L_dq * L_dq);
        d[0] = (L_qq * e_d - L_dq * e_q) * inv_det;
        d[1] = (L_dd * e_q - L_dq * e_d) * inv_det;
        d[2] = free_ ? (m->k_tau * (psi_d * i_q - psi_q * i_d) - tau_L - m->b * w) * m->inv_J
                     : 0.0;
        break;
    }
    default:
        d[0] = (c * u_al + sn * u_be - R * i_d + w_e * L_q * i_q) / L_dd;
        d[1] = (c * u_be - sn * u_al - R * i_q - w_e * psi_d) / L_q;
        d[2] = free_ ? (m->k_tau * (psi_d - L_q * i_d) * i_q - tau_L - m->b * w) * m->inv_J : 0.0;
        break;
    }
}

#endif
