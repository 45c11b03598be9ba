/* Classic fourth-order Runge-Kutta step of the machine's states.
 *
 * The classic fourth-order method of Kutta (1901), as tabulated in Butcher,
 * Numerical Methods for Ordinary Differential Equations (Wiley, 2016): stage
 * offsets 0, h/2, h/2, h and weights 1, 2, 2, 1 over 6. The states are (i_d, i_q, w_m, theta_m); the
 * stator voltage is constant in alpha-beta over the step, so each stage
 * rotates it into d-q at its own rotor angle. One kernel for every flux map
 * and every stage kind: the stage derivative is chosen by a switch.
 *
 * Subdivision at high speed. In the rotor frame the stator voltage, constant
 * in alpha-beta, and the currents turn at the electrical speed: linearised
 * about a state, the current equations L di/dt = u - R i - w_e J psi have the
 * pole pair -R/L +- j w_e (for L_d != L_q the imaginary part is
 * sqrt(w_e^2 - R^2 (1/L_d - 1/L_q)^2 / 4) <= |w_e|). RK4's amplification on the
 * imaginary axis, z = j y, is |R(jy)|^2 = 1 - y^6/72 + y^8/576 with
 * R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24: it exceeds 1, and the step diverges,
 * once y > 2 sqrt(2) = 2.83. A step is one PWM sub-interval, up to 1 ms at
 * 1 kHz, so w_e h passes that limit at |w_e| > 2830 rad/s (a lost rotor's
 * runaway reaches it). Each step is therefore cut into
 * n = ceil(|w_e| h / PLANT_RK4_WH_MAX) equal RK4 steps, w_e taken at the start
 * of the step. PLANT_RK4_WH_MAX = 1 keeps y within 1/2.83 of the limit, which
 * leaves room for w_e to grow inside the step and for the real part -R/L;
 * at y = 1 the per-step amplitude error is 1 - |R(j)| = 0.61 % (damped, not
 * amplified) and the phase error 0.5 %, so the rotation stays accurate as
 * well as bounded. Below |w_e| h = 1 (every paper run: |w_e| <= 1000 rad/s at
 * h <= 1 ms) n = 1 and the step is the classic one, bit for bit.
 *
 * Beyond the flux map's range (|i_s| > PLANT_FLUX_RANGE i_max, plant_machine.h) a
 * second fast mode matters: the speed and the currents exchange energy through
 * the back-EMF (d i/dt gets -L_inc^-1 n_p J psi dw) and the torque (dw/dt gets
 * (k_tau / J) grad(psi_d i_q - psi_q i_d) . di, the gradient at most
 * |psi| + L_hi |i_s|). Linearised, this pair [[0, u], [v^T, 0]] has the
 * eigenvalues +-sqrt(v . u), so its rate is at most
 *     w_em = sqrt(n_p k_tau |psi| (|psi| + L_hi |i_s|) / (J L_lo)),
 * L_lo, L_hi the least and largest eigenvalues of the incremental inductance
 * matrix. It grows with the current (xue2022: 7 to 15 rad/s per A; a runaway of
 * the xue-fig13 square-wave loop without protection reached 2000-4000 A and, at
 * h = 0.5 ms, left RK4's region and went NaN). There the
 * step count takes n = ceil((|w_e| + w_em) h / PLANT_RK4_WH_MAX), the sum bounding
 * both modes' rates. Inside the range w_em h is small (xue2022 at 40 A, h = 0.5 ms:
 * at most 0.29; wen2023 at 16 A, h = 50 us: at most 0.04) and is not added, so every
 * run that stays
 * in the range keeps its steps, bit for bit; with the speed imposed there is no
 * mechanical mode.
 */
#ifndef PLANT_RK4_H
#define PLANT_RK4_H

#include "plant_machine.h"

/* Energy integrals (J) and the charge of each phase in the last period
 * (A s), integrated with the states (plant_rt.EnergyMeter). */
typedef struct {
    double e_in, e_cu, e_em, e_fric, e_load;
    double q_a, q_b, q_c;
} plant_meter;

/* Stage kinds: the hot stage (plant_machine_stage), the general stage
 * (plant_machine_f) and the stage with one phase floating
 * (plant_machine_f_float). */
enum { PLANT_STAGE_HOT = 0, PLANT_STAGE_GENERAL = 1, PLANT_STAGE_FLOAT = 2 };

/* |w_e| h of one RK4 step at most (see the header comment). */
#define PLANT_RK4_WH_MAX 1.0
/* Most RK4 steps in one call: only keeps the int conversion defined; it is
 * reached at |w_e| h = 1e6 (w_e = 1e9 rad/s at 1 ms), no machine's speed. */
#define PLANT_RK4_MAX_SPLIT 1000000

/* The number of equal RK4 steps that plant_rk4 takes over h from state s:
 * ceil(|n_p w_m| h / PLANT_RK4_WH_MAX), at least 1, with w_em h added beyond the
 * flux map's range when the speed is free (see the header comment). */
int plant_rk4_substeps(const plant_machine *m, const plant_state *s, int imposed, double h);

/* One interval of length h, in plant_rk4_substeps equal RK4 steps. kind PLANT_STAGE_FLOAT needs the floating phase fx
 * (0..2) and the voltage (u_al, u_be) of the other legs; *ua, *ub (may be
 * NULL for the hot stage) receive the RK4-weighted mean stator voltage.
 * With a meter (general and floating stages only) the energy flows are
 * integrated with the stages' weights from the pole voltages v (v[fx]
 * replaced by the floating leg's voltage at each stage). In several steps
 * the mean stator voltage is the mean of the steps' means. Every stage, and the meter
 * at its angle, takes the cosine and sine through the memo t (plant_trig_of; may be NULL). */
void plant_rk4(const plant_machine *m, plant_state *s, int imposed, int kind, int fx, double h,
               double u_al, double u_be, double tau_L, double *ua, double *ub, plant_meter *meter,
               const double v[3], plant_trig *t);

#endif
