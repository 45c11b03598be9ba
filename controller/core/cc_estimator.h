/* The estimator interface of the core: what every rotor-position estimator publishes each
 * period (the attributes of the Python protocol controller.Estimator, docs/ESTIMATORS.md),
 * what the controller hands it (controller.EstimatorInput), and an estimator outside the
 * core, called through function pointers (cc_est_if_t: a user's estimator). */
#ifndef CC_ESTIMATOR_H
#define CC_ESTIMATOR_H

typedef struct {
    double theta_hat; /* estimated electrical angle (rad) */
    double w_hat;     /* estimated electrical speed (rad/s) */
    double err;       /* position error signal (rad, ~ theta - theta_hat) */
    double i_alpha_f; /* stationary current with the HF response removed (A) */
    double i_beta_f;
} cc_est_t;

/* sample k as the estimator sees it (controller.EstimatorInput; no truth: the sensored
 * baseline is the core's own) */
typedef struct {
    long long k;
    double i_alpha, i_beta; /* measured stator current, HF included (A) */
    double torque;          /* the torque the controller believes it makes (N m) */
    double u_alpha, u_beta; /* the voltage commanded for [(k-1) T_s, k T_s] (V) */
    int running;            /* the speed loop is released */
    double accel_ref;       /* the speed loop's designed electrical acceleration (rad/s^2) */
} cc_est_in_t;

/* An estimator outside the core (CC_EST_EXTERNAL, cc_foc.h): the members of the protocol
 * as functions of its own context.  Each returns 0, or nonzero when it failed; the
 * controller's step then stops there and returns CC_ERR_ESTIMATOR (the caller knows why:
 * the context is its own).  update and reset write what the estimator publishes into
 * *out.  hf_current_next and set_saliency_offset may be NULL (the estimator has none). */
typedef struct {
    void *ctx;
    int (*update)(void *ctx, const cc_est_in_t *x, cc_est_t *out);
    int (*injection)(void *ctx, double *u_alpha, double *u_beta);
    int (*reset)(void *ctx, double theta0, cc_est_t *out);
    /* the HF current (alpha, beta) (A) it predicts at the mid-point of period k + 1 */
    int (*hf_current_next)(void *ctx, double *i_alpha, double *i_beta);
    /* the cross-saturation offset (rad) it removes from its own saliency-based estimate */
    int (*set_saliency_offset)(void *ctx, double offset);
} cc_est_if_t;

/* A user's estimator written in C against this header, built as a shared library
 * (docs/ESTIMATORS.md, "An estimator in C"). The library exports
 *
 *   size_t cc_estimator_size(void);   the bytes of its state (the caller provides them)
 *   int cc_estimator_init(void *state, cc_est_if_t *iface, const cc_est_design_t *d);
 *
 * init designs the estimator from d (d and its options are valid during the call only:
 * keep what it needs in state), fills *iface (ctx = state) and returns 0, or nonzero when
 * it cannot (controller._cplugin reports it). The state needs no other memory: the
 * functions run in the controller's period. */
typedef struct {
    double n_p, R_s, L_d, L_q, psi_f, J; /* the controller's motor model (SI) */
    double T_s;                          /* control period (s) */
    const double *options;               /* the plug-in's options, in their declared order */
    int n_options;
} cc_est_design_t;

#endif
