/* Start-up from an unknown rotor angle: the magnet-polarity test by d-axis voltage
 * pulses, one period at a time (controller/_startup.py derives the sequence):
 *
 *   +U for N periods, -U for N, 0 for N;  -U for N, +U for N, 0 for N
 *   U = min(u_frac u_dc / sqrt(3), L_d i_pulse / (2 T_s)),  N = ceil(L_d i_pulse / (U T_s))
 *
 * The peaks dI+ = max(i_d - i_d0) over the first half and dI- = max(i_d1 - i_d) over
 * the second decide: dI+ < dI- means the estimated d axis points south (flip by pi).
 * (Neither paper gives its start-up; the HF estimators of both converge to theta_e or
 * theta_e + pi, Wen eq. (8) and Xue eq. (6) being functions of 2 theta.) */
#ifndef CC_STARTUP_H
#define CC_STARTUP_H

typedef struct {
    double L_d, T_s, i_pulse, u_frac;
    double U;
    long long N, n;
    double i0, i1, d_i_pos, d_i_neg;
    int done, flip;
} cc_polarity_t;

void cc_polarity_init(cc_polarity_t *p, double L_d, double T_s, double i_pulse, double u_frac);
/* begin a test at DC-link voltage u_dc (V) and d current i_d0 (A) */
void cc_polarity_start(cc_polarity_t *p, double u_dc, double i_d0);
/* take the d current of sample k (A); return u_d (V) for period k + 1 */
double cc_polarity_step(cc_polarity_t *p, double i_d);

#endif
