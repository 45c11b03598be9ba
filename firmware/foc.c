/*
 * Sensored field-oriented speed control of a PMSM on the controller core
 * (see foc.h; the per-period law is cc_foc_step() in controller/core/cc_foc.c).
 *
 * Gains from bandwidths (continuous-time design, valid while the bandwidths
 * are far below the sampling rate):
 *
 * Current loop.  In rotor coordinates the machine is
 *     L di/dt = u - R_s i + (cross-coupling, removed by the core's decoupling)
 * per axis (L = L_d or L_q).  With the core's 2DOF PI (cc_pi.h)
 *     u = k_t i_ref - k_p i + k_i integral(i_ref - i),
 *     k_t = alpha_c L,  k_p = 2 alpha_c L - R_s,  k_i = alpha_c^2 L
 * the closed loop is (s + alpha_c)^2 L i = alpha_c L (s + alpha_c) i_ref,
 * i.e. i / i_ref = alpha_c / (s + alpha_c), and load disturbances decay with
 * the double pole at -alpha_c.
 *
 * Speed loop.  For a rigid inertia J d(w_m)/dt = tau (the fast current loop
 * seen as a unity gain from tau_ref to tau), the same 2DOF structure with
 *     k_t = alpha_s J,  k_p = 2 alpha_s J,  k_i = alpha_s^2 J
 * gives w_m / w_m_ref = alpha_s / (s + alpha_s).
 *
 * The encoder's speed is used as it is: the core's speed filter is set to a
 * pass-through (b0 = 1, b1 = a1 = 0).  The duties computed from the sample at
 * k T_s act over [(k+1) T_s, (k+2) T_s], whose mid-point is 1.5 T_s after the
 * sample: the core's delay compensation t_delay = 1.5 T_s.
 */
#include "foc.h"

#include <string.h>

#define DELAY_PERIODS 1.5

void foc_init(foc_t *f, double T_s, double n_p, double R_s, double L_d, double L_q,
              double psi_f, double J, double i_max, double tau_max, double alpha_c,
              double alpha_s)
{
    cc_foc_t *c = &f->core;
    memset(f, 0, sizeof *f);
    f->T_s = T_s;
    /* sensored: no alignment or polarity test (align = 0), the d-q PIs see the
     * sampled current (no HF to remove) */
    cc_foc_init(c, n_p, L_d, L_q, psi_f, i_max, tau_max, DELAY_PERIODS * T_s, 0, 0, 0.0, 1, 0);
    cc_pi_init(&c->pi_d, 2.0 * alpha_c * L_d - R_s, alpha_c * alpha_c * L_d, T_s, alpha_c * L_d);
    cc_pi_init(&c->pi_q, 2.0 * alpha_c * L_q - R_s, alpha_c * alpha_c * L_q, T_s, alpha_c * L_q);
    cc_pi_init(&c->pi_w, 2.0 * alpha_s * J, alpha_s * alpha_s * J, T_s, alpha_s * J);
    cc_fo_init(&c->lpf_w, 1.0, 0.0, 0.0);
    cc_estim_init(&c->est, CC_EST_SENSORED);
    f->enabled = false;
}

void foc_set_speed_ref(foc_t *f, double w_m_ref)
{
    cc_foc_set_speed_ref(&f->core, w_m_ref);
}

void foc_enable(foc_t *f, bool enable)
{
    cc_foc_set_enable(&f->core, enable ? 1 : 0);
    f->enabled = enable;
}

void foc_step(foc_t *f, const foc_input_t *in, foc_output_t *out)
{
    out->i_q_ref = 0.0;
    if (!f->enabled || !(in->u_dc > 1.0)) {
        /* Disabled (or no DC link): all switches open, loops held at rest. */
        out->d_a = out->d_b = out->d_c = 0.5;
        out->enable = false;
        out->i_d = out->i_q = 0.0;
        return;
    }
    cc_meas_t m = {0, in->i_a, in->i_b, -in->i_a - in->i_b, in->u_dc,
                   1, in->theta_e, f->core.n_p * in->w_m};
    cc_out_t o;
    cc_foc_step(&f->core, &m, &o); /* CC_OK: u_dc > 1 and the angle is given */
    out->d_a = o.d_a;
    out->d_b = o.d_b;
    out->d_c = o.d_c;
    out->enable = o.enable != 0;
    out->i_d = o.i_d;
    out->i_q = o.i_q;
    out->i_q_ref = f->core.i_q_ref;
}
