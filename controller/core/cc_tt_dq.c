/* tt-dq: triangular-transform self-demodulation in the estimated d-q axes,
 * Wen eqs. (31)-(34): i_dh i_qh = I_p I_n sin(2 theta - 2 theta_hat) + HF terms (33),
 * the LPF of eq. (13) leaves the position error (34); with accel_ff the speed loop's
 * designed acceleration is fed into the PLL beside its loop (controller/_rotating.py). */
#include "cc_math.h"
#include "cc_rotating.h"

void cc_tt_dq_step(cc_est_t *e, cc_rot_t *r, long long k, double i_a, double i_b,
                   double accel_ref)
{
    r->k = k;
    double th = cc_rot_theta(r);
    double c = cos(th);
    double s = sin(th);
    double i_d = c * i_a + s * i_b;
    double i_q = c * i_b - s * i_a;
    double i_dh, i_qh;
    if (r->track) {
        double w_0 = r->w_h - (r->mech ? r->luen.w_hat : r->pll.w_i);
        if (w_0 < 0.0)
            w_0 = -w_0;
        if (w_0 < r->w0_min)
            w_0 = r->w0_min;
        double b0;
        cc_bandpass_coefficients(w_0, r->B, r->T_s, &b0, &r->bpf.a1, &r->bpf.a2);
        r->bpf.b0 = b0;
        r->bpf.b2 = -b0;
    }
    cc_bq2_step(&r->bpf, i_d, i_q, &i_dh, &i_qh);
    double f, err;
    if (r->measured) {
        /* quadrature: LPF((i_dh^2 - i_qh^2)/2) = I_p I_n cos(2 dtheta) */
        double g;
        cc_fo2_step(&r->lpf_m, i_dh * i_qh, 0.5 * (i_dh * i_dh - i_qh * i_qh), &f, &g);
        err = cc_rot_err_measured(r, f, f, g);
    } else {
        f = cc_fo_step(&r->lpf, i_dh * i_qh);
        err = f * r->inv_norm;
    }
    double i_df = i_d - i_dh;
    double i_qf = i_q - i_qh;
    if (r->accel_ff)
        r->accel = accel_ref;
    cc_rot_publish(e, r, th, f, err, c * i_df - s * i_qf, s * i_df + c * i_qf);
}
