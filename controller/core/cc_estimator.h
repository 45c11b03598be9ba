/* What every rotor-position estimator of the core publishes each period (the
 * attributes of the Python protocol controller.Estimator, docs/ESTIMATORS.md). */
#ifndef CC_ESTIMATOR_H
#define CC_ESTIMATOR_H

typedef struct {
    double theta_hat; /* estimated electrical angle (rad) */
    double w_hat;     /* estimated electrical speed (rad/s) */
    double err;       /* position error signal (rad, ~ theta - theta_hat) */
    double i_alpha_f; /* stationary current with the HF response removed (A) */
    double i_beta_f;
} cc_est_t;

#endif
