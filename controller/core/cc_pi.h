/* Two-degree-of-freedom PI controller with anti-windup by the realised output.
 *
 *     u   = k_t r - k_p y + u_i + u_ff                 (output, before limiting)
 *     u_i = u_i + T_s k_i [ (r - y) + (u_lim - u) / k_t ]
 *
 * The current loops' PI of Wen Sec. 3.3, eq. (14) (the regulator the HF
 * current passes through); gains from bandwidths in controller/_controller.py
 * (k_t = alpha L, k_p = 2 alpha L - R_s, k_i = alpha^2 L).
 */
#ifndef CC_PI_H
#define CC_PI_H

typedef struct {
    double k_p; /* proportional gain on the measurement */
    double k_i; /* integral gain */
    double k_t; /* reference gain */
    double T_s; /* sampling period (s) */
    double u_i; /* integral state */
    double e;   /* last error r - y */
    double u;   /* last unlimited output */
} cc_pi_t;

void cc_pi_init(cc_pi_t *p, double k_p, double k_i, double T_s, double k_t);
void cc_pi_reset(cc_pi_t *p);
/* output for reference r, measurement y and feed-forward u_ff */
double cc_pi_output(cc_pi_t *p, double r, double y, double u_ff);
/* integrate with the output u_lim actually applied */
void cc_pi_update(cc_pi_t *p, double u_lim);

#endif
