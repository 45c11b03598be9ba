/* sfhf: the conventional synchronous-frame heterodyne demodulation, Wen eqs. (7)-(13):
 * BPF (11) extracts the HF current (7); in the frame of the injection the HPF (12)
 * removes the positive sequence; the heterodyne (9, with the derived sign) and the
 * LPF (13) leave the position error. */
#include "cc_math.h"
#include "cc_rotating.h"

void cc_sfhf_step(cc_est_t *e, cc_rot_t *r, long long k, double i_a, double i_b)
{
    r->k = k;
    double th = cc_rot_theta(r);
    double ph = cc_mod((double)k * r->wT, 2.0 * M_PI);
    double c_h = cos(ph);
    double s_h = sin(ph);
    double i_ah, i_bh, x_p, y_p;
    cc_bq2_step(&r->bpf, i_a, i_b, &i_ah, &i_bh);
    cc_fo2_step(&r->hpf, c_h * i_ah + s_h * i_bh, c_h * i_bh - s_h * i_ah, &x_p, &y_p);
    double i_an = c_h * x_p - s_h * y_p;
    double i_bn = s_h * x_p + c_h * y_p;
    double ref = 2.0 * th - ph;
    double c_r = cos(ref);
    double s_r = sin(ref);
    double f, err;
    if (r->measured) {
        /* quadrature: i_bn cos(ref) - i_an sin(ref) = I_n cos(2 dtheta) */
        double g;
        cc_fo2_step(&r->lpf_m, -(i_an * c_r + i_bn * s_r), i_bn * c_r - i_an * s_r, &f, &g);
        err = cc_rot_err_measured(r, f, f, g);
    } else {
        f = cc_fo_step(&r->lpf, -(i_an * c_r + i_bn * s_r));
        err = f * r->inv_norm;
    }
    cc_rot_publish(e, r, th, f, err, i_a - i_ah, i_b - i_bh);
}
