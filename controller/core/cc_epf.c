/* epf: estimated position feedback current demodulation, Wen's reference [25] (Mai et
 * al. 2022) as controller/_epf.py reconstructs it:
 *   the current rotated by theta_hat, the BPF of eq. (11) in the estimated frame
 *   (eq. 19/22); the demodulation signals exp(-+j psi), psi = w_h t - theta_hat, and
 *   the LPF of eq. (13) on each give P_p = I_p exp(j(phi_p - pi/2)) and
 *   P_n = I_n exp(j(2 dtheta + phi_n + pi/2)); f = Im{P_p P_n} = I_p I_n sin(2 dtheta),
 *   err = f / (2 I_p I_n). The positive sequence's LPF is lpf_ab, the negative's lpf_n. */
#include "cc_math.h"
#include "cc_rotating.h"

void cc_epf_step(cc_est_t *e, cc_rot_t *r, long long k, double i_a, double i_b)
{
    r->k = k;
    double th = cc_rot_theta(r);
    double c = cos(th);
    double s = sin(th);
    double i_d = c * i_a + s * i_b;
    double i_q = c * i_b - s * i_a;
    double i_dh, i_qh;
    cc_bq2_step(&r->bpf, i_d, i_q, &i_dh, &i_qh);
    double psi = cc_mod((double)k * r->wT, CC_TWO_PI) - th;
    double c_p = cos(psi);
    double s_p = sin(psi);
    double dc = i_dh * c_p;
    double qs = i_qh * s_p;
    double qc = i_qh * c_p;
    double ds = i_dh * s_p;
    /* i_dqh exp(-j psi): the positive sequence; i_dqh exp(+j psi): the negative */
    double p_r, p_i, n_r, n_i;
    cc_fo2_step(&r->lpf_ab, dc + qs, qc - ds, &p_r, &p_i);
    cc_fo2_step(&r->lpf_n, dc - qs, qc + ds, &n_r, &n_i);
    /* P_p P_n = I_p I_n exp(j 2 dtheta) */
    double f = p_r * n_i + p_i * n_r;
    double err;
    if (r->measured) {
        /* the amplitude I_p I_n from the product and its quadrature, low-passed once more
         * (controller/_epf.py) */
        double a_f, a_g;
        cc_fo2_step(&r->lpf_m, f, p_r * n_r - p_i * n_i, &a_f, &a_g);
        err = cc_rot_err_measured(r, f, a_f, a_g);
    } else {
        err = f * r->inv_norm;
    }
    double i_df = i_d - i_dh;
    double i_qf = i_q - i_qh;
    cc_rot_publish(e, r, th, f, err, c * i_df - s * i_qf, s * i_df + c * i_qf);
}
