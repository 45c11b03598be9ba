/* The speed loop's designed response to its reference and the acceleration it implies
 * (controller/_controller.py, ReferenceModel): the 2DOF speed PI is designed for
 * w_m / w_m,ref = alpha_s / (s + alpha_s); forward Euler on the reference alone,
 *     dw = alpha_s (w_ref - w),  a = n_p dw  (limited to +-a_max = n_p tau_max / J),
 *     w += T_s dw,
 * returning a, the electrical acceleration (rad/s^2) the loop is designed to give
 * (controller.EstimatorInput.accel_ref; tt-dq's accel_ff). */
#ifndef CC_REFERENCE_H
#define CC_REFERENCE_H

typedef struct { double alpha_s, n_p, a_max, T_s, w; } cc_ref_t;

void cc_ref_init(cc_ref_t *r, double alpha_s, double n_p, double a_max, double T_s);
void cc_ref_reset(cc_ref_t *r, double w0);
double cc_ref_step(cc_ref_t *r, double w_ref);

#endif
