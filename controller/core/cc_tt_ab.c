/* tt-ab: triangular transform in alpha-beta, Wen eqs. (23)-(28): the LPF of
 * i_ah i_bh and (i_ah^2 - i_bh^2)/2 gives I_p I_n sin/cos 2 theta, the heterodyne
 * with 2 theta_hat the error (28, with the sign the identity needs). */
#include "cc_math.h"
#include "cc_rotating.h"

void cc_tt_ab_step(cc_est_t *e, cc_rot_t *r, long long k, double i_a, double i_b)
{
    r->k = k;
    double th = cc_rot_theta(r);
    double i_ah, i_bh, s_2, c_2;
    cc_bq2_step(&r->bpf, i_a, i_b, &i_ah, &i_bh);
    cc_fo2_step(&r->lpf_ab, i_ah * i_bh, 0.5 * (i_ah * i_ah - i_bh * i_bh), &s_2, &c_2);
    double f = s_2 * cos(2.0 * th) - c_2 * sin(2.0 * th);
    double err = r->measured ? cc_rot_err_measured(r, f, s_2, c_2) : f * r->inv_norm;
    cc_rot_publish(e, r, th, f, err, i_a - i_ah, i_b - i_bh);
}
