"""Unit tests of Xue's square-wave estimator blocks against closed forms.

- CIC interpolation, Xue eq. (8);
- Luenberger observer, Xue eqs. (9)-(12);
- position quadrature signal and error from the HF model, Xue eqs. (2)-(6).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from controller._api import EstimatorInput
from controller._params import MotorModel
from controller._square_wave import SquareWaveEstimator, create, observer_pole
from tests.oracle.blocks import OracleCicFilter, OracleCicInterpolator, OracleLuenbergerObserver
from tests.oracle.estimators import OracleSquareWaveEstimator, make_oracle_estimator

T_S = 1e-3
# Xue Table 1; psi_f and J as in the xue2022 preset (not used by the HF model)
MOTOR = MotorModel(
    n_p=4, R_s=0.19, L_d=3.53e-3, L_q=7.48e-3, psi_f=0.40, J=0.01, b=0.0, i_max=20.0, tau_max=24.0
)


def wrap_pi(x: float) -> float:
    return (x + math.pi) % (2.0 * math.pi) - math.pi


# --------------------------------------------------------------------------- CIC, eq. (8)


@pytest.mark.parametrize("M", [1, 2, 3, 5])
def test_cic_filter_impulse_response_is_eq8(M: int) -> None:
    """(1 - z^-M)/(1 - z^-1) has the impulse response 1 for n < M, 0 after (scaled 1/M)."""
    f = OracleCicFilter(M)
    y = [f.step(1.0 if n == 0 else 0.0) for n in range(3 * M + 4)]
    expected = [1.0 / M if n < M else 0.0 for n in range(3 * M + 4)]
    assert y == expected  # exact: sums of 1 and 0
    # any input: the same as filtering by the rational function of eq. (8)
    rng = np.random.default_rng(1)
    x = rng.standard_normal(500)
    f = OracleCicFilter(M)
    y2 = np.array([f.step(float(v)) for v in x])
    b = np.zeros(M + 1)
    b[0], b[M] = 1.0, -1.0
    ref = signal.lfilter(b, [1.0, -1.0], x) / M
    np.testing.assert_allclose(y2, ref, rtol=0, atol=1e-12)


@pytest.mark.parametrize(("M", "R"), [(2, 2), (3, 3), (2, 4), (4, 2)])
def test_cic_interpolator_impulse_response(M: int, R: int) -> None:
    """Hold by R then eq. (8): box(R) * box(M) / M; for M = R a triangle (linear interpolation)."""
    ip = OracleCicInterpolator(M, R)
    n_slow = 6
    y: list[float] = []
    for m in range(n_slow):
        for j in range(R):
            y.append(ip.step((1.0 if m == 0 else 0.0) if j == 0 else None))
    expected = np.convolve(np.ones(R), np.ones(M)) / M
    expected = np.concatenate([expected, np.zeros(len(y) - len(expected))])
    np.testing.assert_array_equal(np.array(y), expected)
    assert ip.group_delay == pytest.approx(0.5 * (R - 1) + 0.5 * (M - 1))


def test_cic_m_equals_r_interpolates_linearly() -> None:
    """A slow ramp comes out as a fast ramp (delayed by the group delay), not as a staircase."""
    R = 2
    ip = OracleCicInterpolator(2, R)
    ip.prime(0.0)
    y = []
    for m in range(1, 20):
        for j in range(R):
            y.append(ip.step(float(m) if j == 0 else None))
    d = np.diff(y[4:])
    np.testing.assert_allclose(d, 1.0 / R, atol=1e-12)  # a hold alone alternates 1 and 0
    # fast step n (from 0) carries slow sample 1 + n//R; linear interp. delayed by 1 fast step
    n = 10
    assert y[n] == pytest.approx(1.0 + (n - ip.group_delay) / R)


# ------------------------------------------------------------------ observer, eqs. (9)-(12)

A_OBS = 30.0


def _closed_loop_matrix(obs: OracleLuenbergerObserver) -> np.ndarray:
    """Linearised closed loop of the discrete observer with e = theta - theta_hat, theta = 0."""
    eps = 1e-4
    cols = []
    for i in range(3):
        x0 = [0.0, 0.0, 0.0]
        x0[i] = eps
        obs.reset(0.0)
        obs.theta_hat, obs.w_hat, obs.x = x0[0], x0[1], x0[2]
        obs.step(-x0[0], 0.0)
        cols.append([wrap_pi(obs.theta_hat) / eps, obs.w_hat / eps, obs.x / eps])
    return np.array(cols).T


def test_luenberger_gains_and_triple_pole() -> None:
    obs = OracleLuenbergerObserver(J=MOTOR.J, n_p=MOTOR.n_p, a=A_OBS, T_s=T_S)
    assert math.isclose(obs.K_1, A_OBS**3 * MOTOR.J)
    assert math.isclose(obs.K_2, 3 * A_OBS**2 * MOTOR.J)
    assert math.isclose(obs.K_3, 3 * A_OBS * MOTOR.J)
    A = _closed_loop_matrix(obs)
    z0 = 1.0 - A_OBS * T_S  # Euler image of s = -a
    np.testing.assert_allclose(np.poly(A), np.poly([z0, z0, z0]), rtol=0, atol=1e-6)
    s_poles = np.log(np.linalg.eigvals(A).astype(complex)) / T_S
    np.testing.assert_allclose(s_poles.real, -A_OBS, rtol=0.03)
    assert np.max(np.abs(s_poles.imag)) < 0.1 * A_OBS


def _run_observer(alpha_true: float, tau_ff: float, n: int, w0: float = 0.0) -> list[float]:
    """theta(t) = w0 t + alpha t^2/2 (electrical); observer from zero state; returns e[k]."""
    obs = OracleLuenbergerObserver(J=MOTOR.J, n_p=MOTOR.n_p, a=A_OBS, T_s=T_S)
    obs.reset(0.0)
    errs = []
    for k in range(n):
        t = k * T_S
        th = (w0 * t + 0.5 * alpha_true * t * t) % (2 * math.pi)
        e = wrap_pi(th - obs.theta_hat)
        errs.append(e)
        obs.step(e, tau_ff)
    return errs


def test_luenberger_speed_ramp_zero_steady_state_error() -> None:
    """Type-3 loop: a speed ramp (parabolic angle) is tracked with zero error, eq. (12)."""
    alpha = MOTOR.n_p * 2.0 / MOTOR.J  # 2 N m on the inertia: 800 rad/s^2 electrical
    # with the torque feed-forward and without it
    e_ff = _run_observer(alpha, 2.0, 1500, w0=20.0)
    e_no = _run_observer(alpha, 0.0, 1500, w0=20.0)
    assert max(abs(v) for v in e_no[:300]) > 0.05  # it did have to converge
    assert max(abs(v) for v in e_ff[-200:]) < 1e-5
    assert max(abs(v) for v in e_no[-200:]) < 1e-5


def test_luenberger_load_step_matches_eq12() -> None:
    """Torque fed forward, load step tau_L: e(t) = -(n_p tau_L/J) t^2/2 exp(-a t)."""
    tau_e, tau_L = 3.0, 3.0  # the estimated torque is all taken by the load: speed constant
    w0 = 50.0
    alpha_true = MOTOR.n_p * (tau_e - tau_L) / MOTOR.J
    obs = OracleLuenbergerObserver(J=MOTOR.J, n_p=MOTOR.n_p, a=A_OBS, T_s=T_S)
    obs.reset(0.0, w0)
    errs = []
    for k in range(1000):
        t_k = k * T_S
        e_k = wrap_pi(w0 * t_k + 0.5 * alpha_true * t_k * t_k - obs.theta_hat)
        errs.append(e_k)
        obs.step(e_k, tau_e)
    t = np.arange(1000) * T_S
    ref = -(MOTOR.n_p * tau_L / MOTOR.J) * t**2 / 2 * np.exp(-A_OBS * t)
    e = np.array(errs)
    i_pk = int(np.argmin(e))
    peak = -2 * math.exp(-2) * MOTOR.n_p * tau_L / (MOTOR.J * A_OBS**2)
    assert ref.min() == pytest.approx(peak, rel=1e-4)
    # discrete Euler loop vs continuous closed form: within a few per cent (a T_s = 0.03)
    assert e[i_pk] == pytest.approx(ref.min(), rel=0.06)
    assert t[i_pk] == pytest.approx(2.0 / A_OBS, rel=0.06)
    assert np.max(np.abs(e - ref)) < 0.06 * abs(ref.min())
    assert abs(e[-1]) < 1e-3 * abs(ref.min())  # decays to zero (final value of eq. 12)
    assert obs.tau_L_hat == pytest.approx(tau_L, rel=1e-3)


# --------------------------------------------------------------------------- HF model, eqs. (2)-(6)


def _inv_L_ab(theta: float) -> tuple[float, float, float]:
    """Inverse inductance matrix in alpha-beta at rotor angle theta: (g_aa, g_ab, g_bb)."""
    c, s = math.cos(theta), math.sin(theta)
    gd, gq = 1.0 / MOTOR.L_d, 1.0 / MOTOR.L_q
    return gd * c * c + gq * s * s, (gd - gq) * c * s, gd * s * s + gq * c * c


def test_eq6_envelope_matches_inductance_model() -> None:
    """Eq. (6) as printed (L_dif = (L_d - L_q)/2 with the minus sign) equals L_ab^-1 u T."""
    L_avg = 0.5 * (MOTOR.L_d + MOTOR.L_q)
    L_dif = 0.5 * (MOTOR.L_d - MOTOR.L_q)
    U, T = 20.0, T_S
    for th in np.linspace(0, 2 * math.pi, 13):
        for th_hat in np.linspace(0, 2 * math.pi, 11):
            g = _inv_L_ab(th)
            u_a, u_b = U * math.cos(th_hat), U * math.sin(th_hat)
            di_a = T * (g[0] * u_a + g[1] * u_b)
            di_b = T * (g[1] * u_a + g[2] * u_b)
            k6 = U * T / (MOTOR.L_d * MOTOR.L_q)
            e6_a = k6 * (L_avg * math.cos(th_hat) - L_dif * math.cos(2 * th - th_hat))
            e6_b = k6 * (L_avg * math.sin(th_hat) - L_dif * math.sin(2 * th - th_hat))
            assert di_a == pytest.approx(e6_a, abs=1e-9)
            assert di_b == pytest.approx(e6_b, abs=1e-9)


class HFPlant:
    """Standstill HF model, eq. (2): i(k+1) = i(k) + T L_ab(theta)^-1 u(k) (R and EMF neglected)."""

    def __init__(self, theta: float) -> None:
        self.theta = theta
        self.i_a = self.i_b = 0.0
        self.u = (0.0, 0.0)  # voltage of the present period

    def step(self, u_next: tuple[float, float]) -> None:
        g = _inv_L_ab(self.theta)
        u_a, u_b = self.u
        self.i_a += T_S * (g[0] * u_a + g[1] * u_b)
        self.i_b += T_S * (g[1] * u_a + g[2] * u_b)
        self.u = u_next


def _run_synthetic(
    dtheta0: float, a: float | None, n: int, cic: bool = True
) -> OracleSquareWaveEstimator:
    theta = 0.7
    est = OracleSquareWaveEstimator(MOTOR, T_S, cic=cic, a=a)
    est.reset(theta - dtheta0)
    plant = HFPlant(theta)
    for k in range(n):
        est.update(EstimatorInput(k, plant.i_a, plant.i_b, 0.0))
        plant.step(est.injection())
    return est


@pytest.mark.parametrize("cic", [True, False])
def test_error_signal_sign_and_scale(cic: bool) -> None:
    """err has the sign of theta - theta_hat on (-pi/2, pi/2), ~dtheta for small errors."""
    L_avg = 0.5 * (MOTOR.L_d + MOTOR.L_q)
    L_dif = 0.5 * (MOTOR.L_d - MOTOR.L_q)
    for d in [-1.4, -0.7, -0.2, -0.03, 0.03, 0.2, 0.7, 1.4]:
        est = _run_synthetic(d, a=1e-6, n=12, cic=cic)  # observer frozen
        # closed form of the normalised quadrature error from eq. (6)
        zq = -L_dif * math.sin(2 * d)
        zd = L_avg - L_dif * math.cos(2 * d)
        ref = zq / math.hypot(zd, zq) * MOTOR.L_q / (MOTOR.L_q - MOTOR.L_d)
        assert est.err == pytest.approx(ref, rel=1e-3)
        assert math.copysign(1.0, est.err) == math.copysign(1.0, d)
        if abs(d) < 0.05:
            assert est.err == pytest.approx(d, rel=0.02)


@pytest.mark.parametrize("d0", [math.pi / 2 - 0.05, -(math.pi / 2 - 0.05), math.radians(30)])
def test_locks_at_zero_not_at_half_pi(d0: float) -> None:
    """Starting next to the pi/2 equilibrium the estimate leaves it and locks at zero."""
    est = _run_synthetic(d0, a=None, n=1500)
    d_end = wrap_pi(0.7 - est.theta_hat)
    assert abs(d_end) < 1e-4
    assert abs(est.err) < 1e-4


def test_registry_and_options() -> None:
    est = make_oracle_estimator("square-wave", MOTOR, T_S)
    assert isinstance(est, SquareWaveEstimator) and est.cic
    est2 = make_oracle_estimator("square-wave-nocic", MOTOR, T_S, U_h=15.0)
    assert isinstance(est2, SquareWaveEstimator) and not est2.cic and est2.U_h == 15.0
    with pytest.raises(TypeError):
        create(MOTOR, T_S, no_such_option=1)
    # default observer pole: the design for a 45 degree phase margin (test_gain_design.py)
    assert est.observer.a == pytest.approx(observer_pole(T_S, True, 2, 1.5, 45.0), rel=1e-12)
    assert est2.observer.a == pytest.approx(observer_pole(T_S, False, 2, 1.5, 45.0), rel=1e-12)
    assert OracleSquareWaveEstimator(MOTOR, T_S, a=33.0).observer.a == 33.0


def test_injection_is_square_wave_along_predicted_axis() -> None:
    """Eq. (3): +/-U_h alternating every PWM period, along theta_hat + 1.5 T_s w_hat."""
    est = OracleSquareWaveEstimator(MOTOR, T_S, U_h=20.0)
    est.reset(1.0)
    est.observer.w_hat = 100.0
    signs = []
    for k in range(6):
        est.update(EstimatorInput(k, 0.0, 0.0, 0.0))
        u_a, u_b = est.injection()
        assert math.hypot(u_a, u_b) == pytest.approx(20.0)
        phi = est.theta_hat + 1.5 * T_S * est.w_hat
        proj = u_a * math.cos(phi) + u_b * math.sin(phi)
        assert abs(proj) == pytest.approx(20.0)
        signs.append(math.copysign(1.0, proj))
    assert signs == [1.0, -1.0, 1.0, -1.0, 1.0, -1.0]


def test_fundamental_current_removes_square_wave_response() -> None:
    """i_f = DC current + centre of the HF triangle, constant although the samples swing."""
    theta = 0.3
    est = OracleSquareWaveEstimator(MOTOR, T_S)
    est.reset(theta)
    plant = HFPlant(theta)
    i0 = (4.0, -2.0)
    raw_a, f_a, f_b = [], [], []
    prev = (0.0, 0.0)
    for k in range(60):
        h = (plant.i_a, plant.i_b)
        est.update(EstimatorInput(k, h[0] + i0[0], h[1] + i0[1], 0.0))
        plant.step(est.injection())
        if k >= 10:
            raw_a.append(h[0])
            f_a.append(est.i_alpha_f)
            f_b.append(est.i_beta_f)
            # centre of the triangle: mean of its two levels
            assert est.i_alpha_f == pytest.approx(i0[0] + 0.5 * (h[0] + prev[0]), abs=1e-9)
            assert est.i_beta_f == pytest.approx(i0[1] + 0.5 * (h[1] + prev[1]), abs=1e-9)
        prev = h
    assert max(raw_a) - min(raw_a) > 2.0  # the samples swing by amperes
    assert max(f_a) - min(f_a) < 1e-9
    assert max(f_b) - min(f_b) < 1e-9
