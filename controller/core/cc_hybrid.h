/* Full speed range: HF injection at low speed handed over to the flux observer above a
 * band (controller/_hybrid.py derives the band and the trackers).
 *
 *   theta_hat = theta_HF + lam wrap(theta_obs - theta_HF),  w_hat = w_HF + lam (w_obs - w_HF)
 *   injection scaled by g;  (lam, g) from the schedule speed y, the play operator on |w|
 *   (y follows |w| down at once, up with a lag h), ramps w_lo..w_mid and w_mid..w_hi.
 * The injection estimator is tt-dq (its PLL tracker, or with observer = "mechanical"
 * its Luenberger observer, cc_rotating.h) or square-wave (its Luenberger tracker); above
 * the band it is slaved to the observer (sync), below it the observer is slaved to it. */
#ifndef CC_HYBRID_H
#define CC_HYBRID_H

#include "cc_estimator.h"
#include "cc_flux_observer.h"
#include "cc_rotating.h"
#include "cc_square_wave.h"

typedef struct { double w_lo, w_mid, w_hi, h; } cc_band_t;

void cc_band_init(cc_band_t *b, double w_lo, double w_mid, double w_hi, double h);
double cc_band_play(const cc_band_t *b, double y, double w);
void cc_band_weights(const cc_band_t *b, double y, double *lam, double *g);

typedef struct {
    int square;           /* 0: tt-dq and its PLL or mechanical observer; 1: square-wave */
    cc_est_t hf;          /* the injection estimator's published estimate */
    cc_rot_t *rot;        /* the injection estimator (one of the two) */
    cc_sqw_t *sqw;
    cc_flux_t obs;
    cc_band_t band;
    double tr_T_s, tr_k_x; /* the trackers' constants: T_s; -n_p / J (a Luenberger one) */
    double weight, gain, y;
    /* the angle (rad) by which the injection estimator's saliency axis leads the rotor's
     * (cross-saturation, cc_compensation.h), set by the controller before each step and
     * subtracted from the injection estimate alone */
    double saliency_offset;
} cc_hyb_t;

/* hf: the injection estimator (initialised by the caller), obs and band by theirs */
void cc_hyb_init(cc_est_t *e, cc_hyb_t *h, int square, cc_rot_t *rot, cc_sqw_t *sqw,
                 double T_s, double n_p, double J);
void cc_hyb_reset(cc_est_t *e, cc_hyb_t *h, double theta0);
void cc_hyb_step(cc_est_t *e, cc_hyb_t *h, long long k, double i_alpha, double i_beta,
                 double u_alpha, double u_beta, double torque, int running,
                 double accel_ref);
void cc_hyb_injection(const cc_hyb_t *h, double *u_a, double *u_b);
/* the injection estimator's predicted HF current scaled by g (0 for square-wave) */
void cc_hyb_hf_current_next(const cc_hyb_t *h, double *i_a, double *i_b);

#endif
