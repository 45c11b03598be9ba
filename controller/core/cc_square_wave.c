/* HF square-wave injection estimator, Xue eqs. (3)-(12) (cc_square_wave.h). */
#include "cc_math.h"
#include "cc_square_wave.h"

static void sqw_reset_state(cc_sqw_t *q)
{
    q->n = 0;
    /* the sign keeps alternating across a reset (the inverter keeps injecting) */
    q->c0 = q->c1 = q->c2 = 1.0;
    q->s0 = q->s1 = q->s2 = 0.0;
    q->ha1 = q->hb1 = 0.0;
    q->env_n = 0;
    q->held[0] = 0.0;
    q->held[1] = 0.0;
    q->held[2] = 1.0;
    q->held[3] = 0.0;
    for (int j = 0; j < 4; j++)
        cc_cici_reset(&q->interp[j], 0.0);
}

int cc_sqw_init(cc_est_t *e, cc_sqw_t *q, int cic, long long M, double U_h, double t_comp,
                double k_err)
{
    q->cic = cic;
    q->U_h = U_h;
    q->t_comp = t_comp;
    q->k_err = k_err;
    for (int j = 0; j < 4; j++)
        if (cc_cici_init(&q->interp[j], M) < 0)
            return -1;
    e->theta_hat = e->w_hat = e->err = e->i_alpha_f = e->i_beta_f = 0.0;
    q->e_alpha = q->e_beta = 0.0;
    q->u_next_a = q->u_next_b = 0.0;
    q->sg0 = q->sg1 = q->sg2 = 0.0;
    q->n_tot = 0;
    q->ia1 = q->ib1 = 0.0;
    q->id1 = q->iq1 = q->id2 = q->iq2 = 0.0;
    sqw_reset_state(q);
    return 0;
}

void cc_sqw_reset(cc_est_t *e, cc_sqw_t *q, double theta0)
{
    cc_luen_reset(&q->obs, theta0, 0.0, 0.0);
    e->theta_hat = q->obs.theta_hat;
    e->w_hat = 0.0;
    e->err = 0.0;
    q->n_tot = 0; /* the stored rotor-frame samples refer to the old angle */
    sqw_reset_state(q);
}

void cc_sqw_injection(const cc_sqw_t *q, double *u_a, double *u_b)
{
    *u_a = q->u_next_a;
    *u_b = q->u_next_b;
}

void cc_sqw_step(cc_est_t *e, cc_sqw_t *q, double i_a, double i_b, double torque)
{
    long long n = q->n;
    int fresh = 0;
    double E_a = 0.0, E_b = 0.0, u_c = 0.0, u_s = 0.0;
    if (n >= 1) {
        /* eq. (7): the response to the voltage of period k-1 */
        double h_a = 0.5 * (i_a - q->ia1);
        double h_b = 0.5 * (i_b - q->ib1);
        if (n >= 3 && q->sg1 < 0.0) {
            /* rate conversion: periods k-2 (+U_h) and k-1 (-U_h) give one envelope
             * sample (eq. 6), mid-point k-1; the fundamental's linear drift cancels */
            E_a = 0.5 * (q->ha1 - h_a);
            E_b = 0.5 * (q->hb1 - h_b);
            u_c = 0.5 * (q->c1 + q->c2);
            u_s = 0.5 * (q->s1 + q->s2);
            fresh = 1;
        }
        q->ha1 = h_a;
        q->hb1 = h_b;
    }
    double err = 0.0;
    if (fresh && q->env_n == 0) {
        cc_cici_prime(&q->interp[0], E_a);
        cc_cici_prime(&q->interp[1], E_b);
        cc_cici_prime(&q->interp[2], u_c);
        cc_cici_prime(&q->interp[3], u_s);
    }
    if (fresh)
        q->env_n += 1;
    if (q->env_n) {
        double e_a, e_b, v_c, v_s;
        if (q->cic) { /* eq. (8) */
            e_a = cc_cici_step(&q->interp[0], fresh, E_a);
            e_b = cc_cici_step(&q->interp[1], fresh, E_b);
            v_c = cc_cici_step(&q->interp[2], fresh, u_c);
            v_s = cc_cici_step(&q->interp[3], fresh, u_s);
        } else {
            if (fresh) {
                q->held[0] = E_a;
                q->held[1] = E_b;
                q->held[2] = u_c;
                q->held[3] = u_s;
            }
            e_a = q->held[0];
            e_b = q->held[1];
            v_c = q->held[2];
            v_s = q->held[3];
        }
        q->e_alpha = e_a;
        q->e_beta = e_b;
        double den = sqrt((e_a * e_a + e_b * e_b) * (v_c * v_c + v_s * v_s));
        if (den > 0.0)
            err = (e_b * v_c - e_a * v_s) / den * q->k_err;
    }
    e->err = err;

    cc_luen_step(&q->obs, err, torque); /* eqs. (9)-(12) */
    double th = q->obs.theta_hat;
    double w = q->obs.w_hat;
    e->theta_hat = th;
    e->w_hat = w;

    /* eq. (3): the next period's injection, delay-compensated */
    double sgn = q->sg0 != 0.0 ? -q->sg0 : 1.0;
    double phi = th + q->t_comp * w;
    double c = cos(phi);
    double s = sin(phi);
    double uh = sgn * q->U_h;
    q->u_next_a = uh * c;
    q->u_next_b = uh * s;
    q->sg2 = q->sg1;
    q->c2 = q->c1;
    q->s2 = q->s1;
    q->sg1 = q->sg0;
    q->c1 = q->c0;
    q->s1 = q->s0;
    q->sg0 = sgn;
    q->c0 = c;
    q->s0 = s;

    /* the fundamental current without the HF triangle (rotor frame) */
    double ct = cos(th);
    double st = sin(th);
    double i_d = ct * i_a + st * i_b;
    double i_q = ct * i_b - st * i_a;
    double i_df, i_qf;
    if (q->n_tot >= 2) {
        i_df = 0.25 * (3.0 * i_d + 2.0 * q->id1 - q->id2);
        i_qf = 0.25 * (3.0 * i_q + 2.0 * q->iq1 - q->iq2);
    } else {
        i_df = i_d;
        i_qf = i_q;
    }
    e->i_alpha_f = ct * i_df - st * i_qf;
    e->i_beta_f = st * i_df + ct * i_qf;
    q->id2 = q->id1;
    q->iq2 = q->iq1;
    q->id1 = i_d;
    q->iq1 = i_q;
    q->ia1 = i_a;
    q->ib1 = i_b;
    q->n = n + 1;
    q->n_tot += 1;
}
