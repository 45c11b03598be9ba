/* Space-vector PWM by min-max zero-sequence injection: duties 0..1 of the three
 * phases for the stationary voltage (u_alpha, u_beta) at DC-link voltage u_dc.
 *
 *   u_abc = inverse Clarke (u_alpha, u_beta)
 *   d_x   = 1/2 - (max u + min u) / (2 u_dc) + u_x / u_dc
 *
 * linear up to |u| = u_dc / sqrt(3); beyond it the duties are clipped to 0..1.
 * (The papers' drives modulate this way; neither writes it as an equation.) */
#ifndef CC_SVPWM_H
#define CC_SVPWM_H

void cc_svpwm(double u_alpha, double u_beta, double u_dc, double d[3]);

/* the vector (x_1, x_2) scaled down to the magnitude x_max if it is longer: the current
 * loop's voltage limit |u_dq| <= u_dc / sqrt(3) - |u_h| (cc_foc.c) */
void cc_limit_magnitude(double *x_1, double *x_2, double x_max);

#endif
