/* A designed controller into the core: the one mapping of each design call onto the
 * core's _init calls.
 *
 * Python designs every gain and filter (controller/_controller.py and the estimators'
 * modules); controller._compiled.build_core hands the values, by position, to the
 * design calls of its core.  Each design call is one function here, with the same name
 * after cc_design_ and the same arguments in the same order.  Two callers use them:
 * the CPython binding (controller/_cctl.c), which converts Python's values, and the
 * header `bench codegen --estimator` writes for a firmware (bench/wire/_ctlgen.py,
 * bench_controller.h), which calls them with the recorded values.  The generator reads
 * the parameter types of the prototypes below, so keep each prototype on its own line(s)
 * in this form: only the types cc_foc_t *, cc_sup_t *, double, long long, int (a flag or
 * an index), const double * (a tuple of doubles, flags as 0.0/1.0; NULL: None) and
 * const long long * (an optional integer; NULL: None).
 *
 * Plain C99: no allocation, no global state.  Functions that return int return 0, or a
 * CC_DESIGN_* error (the argument the core refuses).
 */
#ifndef CC_DESIGN_H
#define CC_DESIGN_H

#include <stddef.h> /* NULL: an argument left out (None) */

#include "cc_foc.h"
#include "cc_supervision.h"

enum {
    CC_DESIGN_OK = 0,
    CC_DESIGN_BAD_KIND = -1,   /* an estimator kind the core has not */
    CC_DESIGN_BAD_CIC = -2,    /* a CIC delay outside 1..CC_CIC_MAX */
    CC_DESIGN_BAD_OFFSET = -3, /* fewer than one offset calibration period */
};

/* c and sup zeroed, and the estimator's kind (CC_EST_*) */
int cc_design_init(cc_foc_t *c, cc_sup_t *sup, int kind);
/* the FOC constants, the start-up (alignment, settling) and the current feedback */
void cc_design_foc(cc_foc_t *c, double n_p, double L_d, double L_q, double psi_f, double i_max,
                   double tau_max, double t_delay, long long n_align, long long n_settle,
                   double theta0, int raw, int align);
/* one PI: which 0 the d axis, 1 the q axis, else the speed loop */
void cc_design_pi(cc_foc_t *c, int which, double k_p, double k_i, double T_s, double k_t);
/* the speed estimate's first-order filter */
void cc_design_speed_filter(cc_foc_t *c, double b0, double b1, double a1);
/* the magnet polarity test */
void cc_design_polarity(cc_foc_t *c, double L_d, double T_s, double i_pulse, double u_frac);
/* the speed loop's reference model */
void cc_design_reference_model(cc_foc_t *c, double alpha_s, double n_p, double a_max,
                               double T_s);
/* a rotating-injection demodulator: pll {k_p, k_i, T_s}, bpf {b0, b1, b2, a1, a2},
 * lpf {b0, b1, a1} (also the two-axis and normalising filters), hpf {b0, b1, a1} or NULL,
 * track {w_h, T_s, B, w0_min} or NULL (the tracking BPF), quad {b0, b1, b2, a1, a2} or
 * NULL (the quadrature twin) */
void cc_design_rotating(cc_foc_t *c, double V_h, double wT, double inv_norm, const double *pll,
                        const double *bpf, const double *lpf, const double *hpf,
                        const double *track, const double *quad);
/* a rotating demodulator's observer = "mechanical", after cc_design_rotating */
void cc_design_mechanical(cc_foc_t *c, double T_s, double g1, double g2, double g3, double gt,
                          double l3);
/* a rotating demodulator's normalise = "measured", after cc_design_rotating */
void cc_design_measured(cc_foc_t *c, double amp_floor);
/* tt-dq's (or the hybrid's tt-dq's) acceleration feed-forward into its PLL */
void cc_design_accel_ff(cc_foc_t *c);
/* the square-wave demodulator (or the hybrid's): obs {T_s, g1, g2, g3, gt} of its
 * Luenberger observer; CC_DESIGN_BAD_CIC when M is outside 1..CC_CIC_MAX */
int cc_design_square_wave(cc_foc_t *c, int cic, long long M, double U_h, double t_comp,
                          double k_err, const double *obs);
/* the hybrid: obs {R_s, L_d, L_q, psi_f, T_s, zeta_f, w_min, k_p, k_i} of its flux
 * observer, band {w_lo, w_mid, w_hi, h}, after its HF estimator */
void cc_design_hybrid(cc_foc_t *c, const double *obs, const double *band, double T_s,
                      double n_p, double J);
/* the countermeasures switched on (NULL: off): dt {T_s, t_dead, v_ce, v_f, i_band, sine,
 * hf_next}, cross {k_dq, sal_own}, n_offset the offset calibration's periods (>= 1, else
 * CC_DESIGN_BAD_OFFSET and nothing set), hf {I_p, I_n} the rotating injection's model HF
 * amplitudes */
int cc_design_compensation(cc_foc_t *c, const double *dt, const double *cross,
                           const long long *n_offset, const double *hf);
/* the supervision (cc_sup_after after each step) */
void cc_design_supervision(cc_sup_t *sup, double T_s, double i_rail, long long n_range,
                           double i_res, double du_stuck, long long n_stuck, double i_min,
                           double rho_open, long long n_open_min, long long n_open_max,
                           double u_uv, double u_ov, double u_hyst, long long n_dc);

#endif /* CC_DESIGN_H */
