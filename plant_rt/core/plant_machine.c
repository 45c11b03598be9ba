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
    m->x_lim = PLANT_FLUX_RANGE * p->i_max;
    m->x_w = PLANT_FLUX_FADE * m->x_lim;
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

/* The cross map beyond its range: what the emulator does where the map was not identified.
 *
 * Decision. The cross co-energy W'_x = -(c/4) (m_d^2 - i_0^2) i_q^2 is a polynomial fitted
 * to the identified range; continued as it is, its quadratic growth drives the incremental
 * inductance matrix through zero (the xue2022 map at |i_s| of 100-800 A, 5 to 40 i_max),
 * the current equations turn singular and the plant emits NaN. A real machine's iron
 * saturates instead: its incremental inductances fall towards the air-core (leakage)
 * values, which stay positive. So beyond the range the cross co-energy stops growing: it is
 * evaluated at each current limited smoothly to the range,
 *
 *     W'_x(s(i_d), s(i_q)),  s(u) = u                                  for |u| <= a,
 *                            s(u) = sgn(u) a + w tanh((u - sgn(u) a) / w) beyond,
 *
 * a = x_lim = PLANT_FLUX_RANGE i_max (the checked range), w = x_w = PLANT_FLUX_FADE a.
 * s has s(a) = a, s'(a) = 1 and s''(a) = 0, so the flux (the gradient of W'_x) and the
 * incremental inductance matrix (its Hessian) are continuous across the edge, and the
 * map is the same bits as before inside |i_d|, |i_q| <= a. Far beyond the edge s' and s''
 * vanish: the cross terms fade and the matrix tends to diag(L_dd(i_d), L_q), whose least
 * value L_d (1 - sigma) (the d-axis model's fully saturated incremental inductance,
 * SaturationPars) is the floor. Still one co-energy: the matrix stays symmetric and the
 * machine conserves energy. Why w = a / 4: the limited currents end at 1.25 a = 2.5 i_max,
 * short of the 3 i_max and 4 i_max up to which the shipped presets' maps are positive
 * definite (plant_rt/_presets.py), so the continued map only reuses currents where the
 * map is still physical; plant_rt.cross_saturation_check verifies the whole continued
 * map on a grid to 50 i_max when a plant is built. A run that leaves |i_s| <= 2 i_max is
 * outside what the map models: the plant counts those periods (plant_out_of_range_s).
 *
 * With G = W'_x and its derivatives at (s_d, s_q) = (s(i_d), s(i_q)):
 *   psi_d += G_d s_d',   psi_q = L_q i_q + G_q s_q',
 *   L_dd += G_dd s_d'^2 + G_d s_d'',   L_dq = G_dq s_d' s_q',   L_qq = L_q + G_qq s_q'^2 + G_q s_q''. */
static void flux_limit(double u, double a, double w, double *s, double *s1, double *s2)
{
    if (fabs(u) <= a) {
        *s = u;
        *s1 = 1.0;
        *s2 = 0.0;
        return;
    }
    double e = u > 0.0 ? a : -a;
    double t = 1.0 - 2.0 / (exp(2.0 * (u - e) / w) + 1.0); /* tanh((u - e) / w), in libm's exp */
    *s = e + w * t;
    *s1 = 1.0 - t * t;
    *s2 = -2.0 * t * *s1 / w;
}

void plant_flux_cross_ext(const plant_machine *m, double i_d, double i_q, double *psi_d,
                          double *L_dd, double *psi_q, double *L_dq, double *L_qq)
{
    double c_dq = m->c_dq, i_0 = m->i_0;
    double sd, sd1, sd2, sq, sq1, sq2;
    flux_limit(i_d, m->x_lim, m->x_w, &sd, &sd1, &sd2);
    flux_limit(i_q, m->x_lim, m->x_w, &sq, &sq1, &sq2);
    double mm = sd + i_0;
    double p = mm * mm - i_0 * i_0;
    double G_d = -0.5 * c_dq * mm * sq * sq;
    double G_q = -0.5 * c_dq * p * sq;
    *psi_d += G_d * sd1;
    *psi_q = m->L_q * i_q + G_q * sq1;
    *L_dd += -0.5 * c_dq * sq * sq * sd1 * sd1 + G_d * sd2;
    *L_dq = -c_dq * mm * sq * sd1 * sq1;
    *L_qq = m->L_q - 0.5 * c_dq * p * sq1 * sq1 + G_q * sq2;
}

/* CrossSaturationPars: the d-axis model with the co-energy terms (plant_flux_cross). */
void plant_flux_dq(const plant_machine *m, double i_d, double i_q, double out[5])
{
    plant_flux_d(m, i_d, &out[0], &out[2]);
    plant_flux_cross(m, i_d, i_q, &out[0], &out[2], &out[1], &out[3], &out[4]);
}

void plant_machine_f(const plant_machine *m, int imposed, double i_d, double i_q, double w_m,
                     double th_m, double u_al, double u_be, double tau_L, plant_trig *t,
                     double out[4])
{
    double n_p = m->n_p;
    double c, sn;
    plant_trig_of(t, n_p * th_m, &c, &sn);
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
                           double tau_L, plant_trig *t, double out[5])
{
    double n_p = m->n_p;
    double c, sn;
    plant_trig_of(t, n_p * th_m, &c, &sn);
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
void plant_currents_abc(const plant_machine *m, const plant_state *s, plant_trig *t,
                        double out[3])
{
    double c, sn;
    plant_trig_of(t, m->n_p * s->th_m, &c, &sn);
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
