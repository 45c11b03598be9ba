/*
 * Sensored field-oriented speed control of a PMSM (see foc.h).
 *
 * Per PWM period k:
 *
 *   i_a, i_b  --Clarke-->  i_alpha, i_beta  --Park(theta_e)-->  i_d, i_q
 *   speed PI (w_m_ref, w_m)  -> torque -> i_q_ref (i_d_ref = 0), limited
 *   current PIs + decoupling -> u_d, u_q, limited to the linear range of SVPWM
 *   inverse Park at theta_e + 1.5 T_s w_e -> SVPWM -> duties for period k + 1
 *
 * Gains from bandwidths (continuous-time design, valid while the bandwidths
 * are far below the sampling rate):
 *
 * Current loop.  In rotor coordinates the machine is
 *     L di/dt = u - R_s i + (cross-coupling, removed by the decoupling terms)
 * per axis (L = L_d or L_q).  With the 2DOF PI
 *     u = k_t i_ref - k_p i + k_i integral(i_ref - i),
 *     k_t = alpha_c L,  k_p = 2 alpha_c L - R_s,  k_i = alpha_c^2 L
 * the closed loop is (s L + R_s + k_p) i = (s k_t + k_i) i_ref + ..., i.e.
 *     (s + alpha_c)^2 L i = alpha_c L (s + alpha_c) i_ref,
 * so i / i_ref = alpha_c / (s + alpha_c): a first-order response of
 * bandwidth alpha_c, and load disturbances decay with the double pole at
 * -alpha_c.  The decoupling feed-forward
 *     u_d += -w_e L_q i_q,   u_q += w_e (L_d i_d + psi_f)
 * cancels the rotational voltages of the machine model.
 *
 * Speed loop.  For a rigid inertia J d(w_m)/dt = tau (the fast current loop
 * seen as a unity gain from tau_ref to tau), the same 2DOF structure with
 *     k_t = alpha_s J,  k_p = 2 alpha_s J,  k_i = alpha_s^2 J
 * gives w_m / w_m_ref = alpha_s / (s + alpha_s); friction and load torque
 * are rejected by the integral.
 *
 * Delay compensation: the duties computed from the sample at k T_s act over
 * [(k+1) T_s, (k+2) T_s], whose mid-point is 1.5 T_s after the sample, so the
 * inverse Park uses theta_e + 1.5 T_s w_e.
 *
 * Anti-windup: each PI's integrator is updated with the output actually
 * applied (after the torque, current or voltage limit).
 */
#include "foc.h"

#include <math.h>

#define TWO_PI 6.28318530717958647692
#define SQRT3 1.73205080756887729353
#define DELAY_PERIODS 1.5

static void pi_init(pi_ctrl_t *pi, double k_p, double k_i, double k_t, double T_s)
{
    pi->k_p = k_p;
    pi->k_i = k_i;
    pi->k_t = k_t;
    pi->T_s = T_s;
    pi->u_i = 0.0;
    pi->e = 0.0;
    pi->u = 0.0;
}

static void pi_reset(pi_ctrl_t *pi)
{
    pi->u_i = 0.0;
    pi->e = 0.0;
    pi->u = 0.0;
}

/* Unlimited output for reference r, measurement y and feed-forward u_ff. */
static double pi_output(pi_ctrl_t *pi, double r, double y, double u_ff)
{
    pi->e = r - y;
    pi->u = pi->k_t * r - pi->k_p * y + pi->u_i + u_ff;
    return pi->u;
}

/* Advance the integrator with the realised (limited) output u_lim. */
static void pi_update(pi_ctrl_t *pi, double u_lim)
{
    pi->u_i += pi->T_s * pi->k_i * (pi->e + (u_lim - pi->u) / pi->k_t);
}

static double clip(double x, double lo, double hi)
{
    return x < lo ? lo : (x > hi ? hi : x);
}

void foc_init(foc_t *f, double T_s, double n_p, double R_s, double L_d, double L_q,
              double psi_f, double J, double i_max, double tau_max, double alpha_c,
              double alpha_s)
{
    f->T_s = T_s;
    f->n_p = n_p;
    f->R_s = R_s;
    f->L_d = L_d;
    f->L_q = L_q;
    f->psi_f = psi_f;
    f->i_max = i_max;
    f->tau_max = tau_max;
    f->k_tau = 1.5 * n_p * psi_f;
    pi_init(&f->pi_d, 2.0 * alpha_c * L_d - R_s, alpha_c * alpha_c * L_d, alpha_c * L_d, T_s);
    pi_init(&f->pi_q, 2.0 * alpha_c * L_q - R_s, alpha_c * alpha_c * L_q, alpha_c * L_q, T_s);
    pi_init(&f->pi_w, 2.0 * alpha_s * J, alpha_s * alpha_s * J, alpha_s * J, T_s);
    f->w_m_ref = 0.0;
    f->enabled = false;
}

void foc_set_speed_ref(foc_t *f, double w_m_ref)
{
    f->w_m_ref = w_m_ref;
}

void foc_enable(foc_t *f, bool enable)
{
    if (enable && !f->enabled) {
        pi_reset(&f->pi_d);
        pi_reset(&f->pi_q);
        pi_reset(&f->pi_w);
    }
    f->enabled = enable;
}

void svpwm(double u_alpha, double u_beta, double u_dc, double *d_a, double *d_b, double *d_c)
{
    /* Phase voltages (amplitude-invariant inverse Clarke). */
    double u_a = u_alpha;
    double u_b = -0.5 * u_alpha + 0.5 * SQRT3 * u_beta;
    double u_c = -0.5 * u_alpha - 0.5 * SQRT3 * u_beta;
    double hi = fmax(u_a, fmax(u_b, u_c));
    double lo = fmin(u_a, fmin(u_b, u_c));
    /* Min-max zero sequence centres the phase voltages in [-u_dc/2, u_dc/2]:
     * the same switching times as conventional space-vector modulation.
     * Duty d_x = 1/2 + u_x / u_dc (pole voltage against the negative rail). */
    double off = 0.5 - 0.5 * (hi + lo) / u_dc;
    *d_a = clip(off + u_a / u_dc, 0.0, 1.0);
    *d_b = clip(off + u_b / u_dc, 0.0, 1.0);
    *d_c = clip(off + u_c / u_dc, 0.0, 1.0);
}

void foc_step(foc_t *f, const foc_input_t *in, foc_output_t *out)
{
    /* Measure: Clarke (three-wire, i_c = -i_a - i_b), Park with the rotor angle. */
    double i_alpha = in->i_a;
    double i_beta = (in->i_a + 2.0 * in->i_b) / SQRT3;
    double c = cos(in->theta_e);
    double s = sin(in->theta_e);
    double i_d = c * i_alpha + s * i_beta;
    double i_q = -s * i_alpha + c * i_beta;
    double w_e = f->n_p * in->w_m;

    out->i_d = i_d;
    out->i_q = i_q;
    out->i_q_ref = 0.0;
    if (!f->enabled || !(in->u_dc > 1.0)) {
        /* Disabled (or no DC link): all switches open, loops held at rest. */
        out->d_a = out->d_b = out->d_c = 0.5;
        out->enable = false;
        return;
    }

    /* Speed loop -> torque reference, limited; i_d_ref = 0 (below base speed). */
    double tau = clip(pi_output(&f->pi_w, f->w_m_ref, in->w_m, 0.0), -f->tau_max, f->tau_max);
    double i_d_ref = 0.0;
    double i_q_max = sqrt(fmax(f->i_max * f->i_max - i_d_ref * i_d_ref, 0.0));
    double i_q_ref = clip(tau / f->k_tau, -i_q_max, i_q_max);
    tau = f->k_tau * i_q_ref; /* torque actually asked for */

    /* Current loops with decoupling. */
    double u_d = pi_output(&f->pi_d, i_d_ref, i_d, -w_e * f->L_q * i_q);
    double u_q = pi_output(&f->pi_q, i_q_ref, i_q, w_e * (f->L_d * i_d + f->psi_f));

    /* Voltage limit: the linear range of SVPWM, |u| <= u_dc / sqrt(3). */
    double u_lim = in->u_dc / SQRT3;
    double mag = sqrt(u_d * u_d + u_q * u_q);
    if (mag > u_lim) {
        u_d *= u_lim / mag;
        u_q *= u_lim / mag;
    }

    /* Inverse Park at the mid-point of the period the duties act in. */
    double th_u = in->theta_e + DELAY_PERIODS * f->T_s * w_e;
    double c_u = cos(th_u);
    double s_u = sin(th_u);
    svpwm(c_u * u_d - s_u * u_q, s_u * u_d + c_u * u_q, in->u_dc, &out->d_a, &out->d_b,
          &out->d_c);
    out->enable = true;
    out->i_q_ref = i_q_ref;

    /* Update states with the realised outputs. */
    pi_update(&f->pi_d, u_d);
    pi_update(&f->pi_q, u_q);
    pi_update(&f->pi_w, tau);
}
