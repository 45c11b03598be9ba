/* The IPMSM and its flux map: Wen et al. eq. (1), Xue et al. eq. (1)
 * (plant_machine.h). The operation order of every expression is the
 * reference model's (tests/plant_reference.py), so that the traces agree
 * bit for bit; build with -ffp-contract=off. */
#include "plant_machine.h"

#include <math.h>

#include "plant_const.h"

void plant_machine_init(plant_machine *m, const plant_machine_pars *p)
{
    m->n_p = p->n_p;
    m->R = p->R_s;
    m->L_d = p->L_d;
    m->L_q = p->L_q;
    m->psi_f = p->psi_f;
    m->b = p->b;
    m->inv_J = 1.0 / p->J;
    m->k_tau = 1.5 * p->n_p;
    m->sigma = p->sat_sigma;
    m->i_sat = p->sat_i_sat;
    m->sig = p->sat_sigma;
    m->inv_i_sat = 1.0 / p->sat_i_sat;
    m->sig_isat = p->sat_sigma * p->sat_i_sat;
    m->c_dq = p->c_dq;
    m->i_0 = p->psi_f / p->L_d;
    m->sat = p->saturation != 0;
    m->cross = p->cross != 0;
    m->variant = m->cross ? PLANT_FLUX_CROSS : (m->sat ? PLANT_FLUX_SAT : PLANT_FLUX_LINEAR);
}

void plant_flux_d(const plant_machine *m, double i_d, double *psi_d, double *L_dd)
{
    if (!m->sat) {
        *psi_d = m->psi_f + m->L_d * i_d;
        *L_dd = m->L_d;
        return;
    }
    plant_flux_d_sat(m, i_d, i_d / m->i_sat, psi_d, L_dd);
}

/* CrossSaturationPars: the d-axis model with the co-energy terms (plant_flux_cross). */
void plant_flux_dq(const plant_machine *m, double i_d, double i_q, double out[5])
{
    plant_flux_d(m, i_d, &out[0], &out[2]);
    plant_flux_cross(m, i_d, i_q, &out[0], &out[2], &out[1], &out[3], &out[4]);
}

void plant_machine_f(const plant_machine *m, int imposed, double i_d, double i_q, double w_m,
                     double th_m, double u_al, double u_be, double tau_L, double out[4])
{
    double n_p = m->n_p;
    double th_e = n_p * th_m;
    double c = cos(th_e), sn = sin(th_e);
    double u_d = c * u_al + sn * u_be;
    double u_q = c * u_be - sn * u_al;
    double w_e = n_p * w_m;
    if (m->cross) {
        double fl[5];
        plant_flux_dq(m, i_d, i_q, fl);
        double psi_d = fl[0], psi_q = fl[1], L_dd = fl[2], L_dq = fl[3], L_qq = fl[4];
        double e_d = u_d - m->R * i_d + w_e * psi_q;
        double e_q = u_q - m->R * i_q - w_e * psi_d;
        double det = L_dd * L_qq - L_dq * L_dq;
        double tau_e = m->k_tau * (psi_d * i_q - psi_q * i_d);
        out[0] = (L_qq * e_d - L_dq * e_q) / det;
        out[1] = (L_dd * e_q - L_dq * e_d) / det;
        out[2] = imposed ? 0.0 : (tau_e - tau_L - m->b * w_m) * m->inv_J;
        out[3] = tau_e;
        return;
    }
    double L_q = m->L_q, psi_d, L_dd;
    if (m->sat) {
        plant_flux_d_sat(m, i_d, i_d * m->inv_i_sat, &psi_d, &L_dd);
    } else {
        psi_d = m->psi_f + m->L_d * i_d;
        L_dd = m->L_d;
    }
    double R = m->R;
    double tau_e = m->k_tau * (psi_d - L_q * i_d) * i_q;
    out[0] = (u_d - R * i_d + w_e * L_q * i_q) / L_dd;
    out[1] = (u_q - R * i_q - w_e * psi_d) / L_q;
    out[2] = imposed ? 0.0 : (tau_e - tau_L - m->b * w_m) * m->inv_J;
    out[3] = tau_e;
}

/* Phase x floating with the cross-saturated map: d i / dt = Y (e + (2/3) v_x e_x),
 * Y the inverse of the incremental inductance matrix, v_x from d i_x / dt = 0. */
static void f_float_cross(const plant_machine *m, int imposed, double i_d, double i_q,
                          double w_m, double c, double sn, double u_d, double u_q, int x,
                          double tau_L, double out[5])
{
    double w_e = m->n_p * w_m;
    double fl[5];
    plant_flux_dq(m, i_d, i_q, fl);
    double psi_d = fl[0], psi_q = fl[1], L_dd = fl[2], L_dq = fl[3], L_qq = fl[4];
    double R = m->R;
    double e_d = u_d - R * i_d + w_e * psi_q;
    double e_q = u_q - R * i_q - w_e * psi_d;
    double det = L_dd * L_qq - L_dq * L_dq;
    double f_d = (L_qq * e_d - L_dq * e_q) / det;
    double f_q = (L_dd * e_q - L_dq * e_d) / det;
    double c_x = c * PLANT_COS_PHI[x] + sn * PLANT_SIN_PHI[x];
    double s_x = sn * PLANT_COS_PHI[x] - c * PLANT_SIN_PHI[x];
    double y_d = (L_qq * c_x + L_dq * s_x) / det;
    double y_q = (-L_dq * c_x - L_dd * s_x) / det;
    double a = c_x * f_d - s_x * f_q - w_e * (i_d * s_x + i_q * c_x);
    double g = (2.0 / 3.0) * (c_x * y_d - s_x * y_q);
    double v_x = -a / g;
    double tau_e = m->k_tau * (psi_d * i_q - psi_q * i_d);
    out[0] = f_d + (2.0 / 3.0) * v_x * y_d;
    out[1] = f_q + (2.0 / 3.0) * v_x * y_q;
    out[2] = imposed ? 0.0 : (tau_e - tau_L - m->b * w_m) * m->inv_J;
    out[3] = tau_e;
    out[4] = v_x;
}

/* Phase x floating (current held at zero): leg x adds (2/3) v_x e^{j phi_x};
 * v_x solved from d i_x / dt = 0, i_x = i_d cos(theta_e - phi_x) - i_q sin(theta_e - phi_x). */
void plant_machine_f_float(const plant_machine *m, int imposed, double i_d, double i_q,
                           double w_m, double th_m, double u_al0, double u_be0, int x,
                           double tau_L, double out[5])
{
    double n_p = m->n_p;
    double th_e = n_p * th_m;
    double c = cos(th_e), sn = sin(th_e);
    double u_d = c * u_al0 + sn * u_be0;
    double u_q = c * u_be0 - sn * u_al0;
    double w_e = n_p * w_m;
    if (m->cross) {
        f_float_cross(m, imposed, i_d, i_q, w_m, c, sn, u_d, u_q, x, tau_L, out);
        return;
    }
    double L_q = m->L_q, psi_d, L_dd;
    plant_flux_d(m, i_d, &psi_d, &L_dd);
    double R = m->R;
    double f_d = (u_d - R * i_d + w_e * L_q * i_q) / L_dd;
    double f_q = (u_q - R * i_q - w_e * psi_d) / L_q;
    double c_x = c * PLANT_COS_PHI[x] + sn * PLANT_SIN_PHI[x];
    double s_x = sn * PLANT_COS_PHI[x] - c * PLANT_SIN_PHI[x];
    double a = c_x * f_d - s_x * f_q - w_e * (i_d * s_x + i_q * c_x);
    double g = (2.0 / 3.0) * (c_x * c_x / L_dd + s_x * s_x / L_q);
    double v_x = -a / g;
    double tau_e = m->k_tau * (psi_d - L_q * i_d) * i_q;
    out[0] = f_d + (2.0 / 3.0) * v_x * c_x / L_dd;
    out[1] = f_q - (2.0 / 3.0) * v_x * s_x / L_q;
    out[2] = imposed ? 0.0 : (tau_e - tau_L - m->b * w_m) * m->inv_J;
    out[3] = tau_e;
    out[4] = v_x;
}

double plant_machine_torque(const plant_machine *m, double i_d, double i_q)
{
    if (m->cross) {
        double fl[5];
        plant_flux_dq(m, i_d, i_q, fl);
        return m->k_tau * (fl[0] * i_q - fl[1] * i_d);
    }
    double psi_d, L_dd;
    plant_flux_d(m, i_d, &psi_d, &L_dd);
    return m->k_tau * (psi_d - m->L_q * i_d) * i_q;
}

/* Inverse Park and Clarke (amplitude invariant). */
void plant_currents_abc(const plant_machine *m, const plant_state *s, double out[3])
{
    double th_e = m->n_p * s->th_m;
    double c = cos(th_e), sn = sin(th_e);
    double i_al = c * s->i_d - sn * s->i_q;
    double i_be = sn * s->i_d + c * s->i_q;
    out[0] = i_al;
    out[1] = -0.5 * i_al + 0.5 * PLANT_SQRT3 * i_be;
    out[2] = -0.5 * i_al - 0.5 * PLANT_SQRT3 * i_be;
}

void plant_zero_phase(const plant_machine *m, plant_state *s, int x)
{
    double th_e = m->n_p * s->th_m;
    double c = cos(th_e), sn = sin(th_e);
    double c_x = c * PLANT_COS_PHI[x] + sn * PLANT_SIN_PHI[x];
    double s_x = sn * PLANT_COS_PHI[x] - c * PLANT_SIN_PHI[x];
    double i_x = s->i_d * c_x - s->i_q * s_x;
    s->i_d -= i_x * c_x;
    s->i_q += i_x * s_x;
}

double plant_py_mod(double x, double m)
{
    double mod = fmod(x, m);
    if (mod != 0.0) {
        if ((m < 0.0) != (mod < 0.0))
            mod += m;
    } else {
        mod = copysign(0.0, m);
    }
    return mod;
}
