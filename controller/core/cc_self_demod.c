/* self-demod: HF response current self-demodulation, Wen's reference [27] (Li et al.
 * 2021) as controller/_self_demod.py reconstructs it:
 *   the BPF of eq. (11) gives the HF current d in alpha-beta, its quadrature twin
 *   q = (s / w_h) d; 2 i_p = d - j q, 2 i_n = d + j q separate the sequences (eq. 18);
 *   i_p i_n = I_p I_n exp(j(2 theta_e + phi_p + phi_n)) (four multiplications); the
 *   heterodyne with 2 theta_hat and the LPF of eq. (13) leave the position error,
 *   err = LPF(Im{i_p i_n exp(-j 2 theta_hat)}) / (2 I_p I_n). */
#include "cc_math.h"
#include "cc_rotating.h"

void cc_self_demod_step(cc_est_t *e, cc_rot_t *r, long long k, double i_a, double i_b)
{
    r->k = k;
    double th = cc_rot_theta(r);
    double d_a, d_b, q_a, q_b;
    cc_bq2_step(&r->bpf, i_a, i_b, &d_a, &d_b);
    cc_bq2_step(&r->quad, i_a, i_b, &q_a, &q_b);
    /* 2 i_p = d - j q = (d_a + q_b) + j (d_b - q_a), 2 i_n = d + j q */
    double p_r = d_a + q_b;
    double p_i = d_b - q_a;
    double n_r = d_a - q_b;
    double n_i = d_b + q_a;
    double m_r = 0.25 * (p_r * n_r - p_i * n_i);
    double m_i = 0.25 * (p_r * n_i + p_i * n_r);
    double c_2 = cos(2.0 * th);
    double s_2 = sin(2.0 * th);
    double f, err;
    if (r->measured) {
        /* quadrature: Re{i_p i_n exp(-j 2 theta_hat)} = I_p I_n cos(2 dtheta + ...) */
        double g;
        cc_fo2_step(&r->lpf_m, m_i * c_2 - m_r * s_2, m_r * c_2 + m_i * s_2, &f, &g);
        err = cc_rot_err_measured(r, f, f, g);
    } else {
        f = cc_fo_step(&r->lpf, m_i * c_2 - m_r * s_2);
        err = f * r->inv_norm;
    }
    cc_rot_publish(e, r, th, f, err, i_a - d_a, i_b - d_b);
}
