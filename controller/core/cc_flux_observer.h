/* Reduced-order flux observer for medium and high speed (Hinkkanen et al. 2018, as
 * in motulator), one PWM period at a time; controller/_flux_observer.py derives it.
 *
 *   psi_m(i) = psi_f + L_d i_d + j L_q i_q          current model
 *   e        = psi_m(i) - psi_hat                   flux error
 *   psi_a    = psi_f + (L_d - L_q) conj(i)          auxiliary flux
 *   psi_hat(k) = psi_hat+(k-1) + T_s u(k-1) - R_s T_s (i(k-1) + i(k)) / 2   (stationary)
 *   psi_hat+   = psi_hat + 2 k_1 T_s psi_a Re(e / psi_a)     (k_2 = k_1 psi_a / conj psi_a)
 *   eps = -Im(e / psi_a);  w_i += T_s k_i eps;  theta += T_s (w_i + k_p eps)
 * with k_1 T_s = min(zeta_f T_s max(|w_hat|, w_min), 1/2).
 * The hybrids run it "slaved" below their band: angle and speed from the injection
 * estimator, the flux still corrected. */
#ifndef CC_FLUX_OBSERVER_H
#define CC_FLUX_OBSERVER_H

typedef struct {
    double L_d, L_q, psi_f, T_s, w_min, k_i, kp, ki_T, zT, rT2, dL;
    double psi_alpha, psi_beta, ia1, ib1, theta_hat, w_hat, eps, accel, th_next;
    int init;
} cc_flux_t;

void cc_flux_init(cc_flux_t *o, double R_s, double L_d, double L_q, double psi_f, double T_s,
                  double zeta_f, double w_min, double k_p, double k_i);
void cc_flux_reset(cc_flux_t *o, double theta0, double w0);
/* the flux estimate (Wb) and the current sample (A) of the last sample, from which the
 * next step integrates (instead of the current model) */
void cc_flux_set_state(cc_flux_t *o, double psi_alpha, double psi_beta, double i_alpha,
                       double i_beta);
void cc_flux_step(cc_flux_t *o, double i_alpha, double i_beta, double u_alpha, double u_beta);
void cc_flux_step_slaved(cc_flux_t *o, double i_alpha, double i_beta, double u_alpha,
                         double u_beta, double theta, double w);

#endif
