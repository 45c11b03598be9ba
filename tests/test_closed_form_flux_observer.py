"""The reduced-order flux observer against its closed forms (controller/_flux_observer.py).

The "ideal model input" is an exact machine at constant speed and current:
``psi(t) = e^{j theta(t)} psi_r``, ``i(t) = e^{j theta(t)} i_r``, and for each
period the constant voltage that takes the flux from sample to sample with
the resistive drop of the trapezoid, ``u = (psi(k+1) - psi(k))/T_s + R_s (i(k)
+ i(k+1))/2``: the discrete observer with an exact model reproduces it with
no error, so every deviation is the closed form's.
"""

from __future__ import annotations

import cmath
import math
from dataclasses import replace

import numpy as np
import pytest

from bench.scenarios._setup import motor_model
from controller import FluxObserver, Measurement, MotorModel, pll_gains
from plant_rt import ConstantLoad, preset
from tests.loop_helpers import RPM, make_loop
from tests.oracle import OracleController

XUE = motor_model(preset("xue2022"))
WEN = motor_model(preset("wen2023"))
ZETA = 0.2


def _wrap(x: float) -> float:
    return (x + math.pi) % (2.0 * math.pi) - math.pi


def run_ideal(
    true: MotorModel,
    model: MotorModel,
    T_s: float,
    w: float,
    i_r: complex,
    n: int,
    dtheta0: float = 0.0,
    dpsi0: complex = 0.0,
    alpha_o: float = 400.0,
    w_min: float = 20.0,
) -> tuple[list[float], list[complex], list[float]]:
    """Observer on an ideal model input; returns the angle error, the flux error in the
    true rotor frame and the true angle, per sample (samples 1..n)."""
    psi_r = true.psi_f + true.L_d * i_r.real + 1j * true.L_q * i_r.imag
    th0 = 0.3

    def at(k: int) -> tuple[float, complex, complex]:
        th = th0 + w * k * T_s
        e = cmath.exp(1j * th)
        return th, e * i_r, e * psi_r

    obs = FluxObserver(model, T_s, alpha_o, ZETA, w_min)
    obs.reset(at(1)[0] - dtheta0, w)  # the estimate for sample 1
    _, i0, p0 = at(0)
    p_hat = p0 - dpsi0  # flux error dpsi0 = true - estimate, at sample 0
    obs.set_state(p_hat.real, p_hat.imag, i0.real, i0.imag)
    errs: list[float] = []
    dpsi: list[complex] = []
    ths: list[float] = []
    for k in range(1, n + 1):
        _, i_p, p_p = at(k - 1)
        th, i_k, p_k = at(k)
        u = (p_k - p_p) / T_s + true.R_s * (i_p + i_k) / 2.0
        obs.update(i_k.real, i_k.imag, u.real, u.imag)
        errs.append(_wrap(th - obs.theta_hat))
        dpsi.append((p_k - complex(obs.psi_alpha, obs.psi_beta)) * cmath.exp(-1j * th))
        ths.append(th)
    return errs, dpsi, ths


def test_pll_gains_place_a_double_pole_at_exp_minus_alpha_T() -> None:
    """``k_p = (1 - p^2)/T``, ``k_i = (1 - p)^2/T^2``: the error recursion's characteristic
    polynomial ``z^2 - (2 - T k_p - T^2 k_i) z + 1 - T k_p`` has the double root ``p``."""
    for alpha, T in ((415.0, 1e-4), (405.0, 1e-3), (2000.0, 1e-3)):
        k_p, k_i = pll_gains(alpha, T)
        roots = np.roots([1.0, -(2.0 - T * k_p - T * T * k_i), 1.0 - T * k_p])
        assert np.allclose(roots, math.exp(-alpha * T), atol=1e-6)
        # the continuous design 2 alpha, alpha^2 is the limit, not the value, at 1 kHz
        if alpha * T > 0.3:
            assert abs(k_p - 2.0 * alpha) > 0.05 * 2.0 * alpha


@pytest.mark.parametrize(("T_s", "w"), [(1e-3, 300.0), (1e-4, 600.0), (1e-3, -450.0)])
def test_angle_error_decays_at_the_designed_rate(T_s: float, w: float) -> None:
    """A small initial angle error with the flux estimate exact: the flux error stays
    zero (the correction does not see ``theta~``), and the angle error follows the PLL's
    discrete double pole, ``theta~(k) = theta0 (1 - k (1 - p)/p) p^k``, ``p =
    exp(-alpha_o T_s)``: ``(1 - alpha_o t) exp(-alpha_o t)`` sampled."""
    alpha = 400.0
    th0 = 0.01
    errs, dpsi, _ = run_ideal(XUE, XUE, T_s, w, 8j, 200, dtheta0=th0, alpha_o=alpha)
    p = math.exp(-alpha * T_s)
    for k in range(0, 60):
        want = th0 * (1.0 - k * (1.0 - p) / p) * p**k
        assert errs[k] == pytest.approx(want, abs=2e-3 * th0), k
    assert max(abs(d) for d in dpsi) < 1e-3 * th0 * XUE.psi_f
    # and a wrong rate would be seen: the error at t = 1/alpha is ~0, not e^-1 theta0
    k1 = round(1.0 / (alpha * T_s))
    assert abs(errs[k1]) < 0.1 * th0


def test_flux_error_decays_with_the_discrete_poles() -> None:
    """An initial flux error (along and across ``psi_a``) at the true angle: in the
    estimated rotor frame ``z = psi~/psi_a`` obeys ``z(k+1) = e^{-j w T} (z - 2 k_1 T
    Re z)`` to first order, so ``|z(k)|`` follows the powers of that 2x2 matrix
    (spectral radius ``sqrt(1 - 2 k_1 T)``, rate about ``k_1 = zeta_f |w|``)."""
    T = 1e-3
    w = 400.0
    i_r = 6j
    psi_a = XUE.psi_f + (XUE.L_d - XUE.L_q) * i_r.conjugate()
    z0 = 0.004 * (1.0 + 1.0j)
    # error placed in the rotor frame of sample 0 (angle 0.3)
    dpsi0 = z0 * psi_a * cmath.exp(1j * 0.3)
    _, dpsi, _ = run_ideal(XUE, XUE, T, w, i_r, 150, dpsi0=dpsi0)
    g = ZETA * abs(w) * T
    c, s = math.cos(w * T), math.sin(w * T)
    rot = np.array([[c, s], [-s, c]])  # z -> z e^{-j w T}: the frame turns on
    corr = np.array([[1.0 - 2.0 * g, 0.0], [0.0, 1.0]])  # z -> z - 2 g Re z
    step = corr @ rot
    x = np.array([z0.real, z0.imag])  # after the correction of sample 0
    for k, d in enumerate(dpsi):
        x = step @ x
        z = d / psi_a
        assert abs(z - complex(x[0], x[1])) < 0.03 * abs(z0) + 0.02 * abs(z), k
    assert max(abs(np.linalg.eigvals(step))) == pytest.approx(math.sqrt(1.0 - 2.0 * g))
    assert abs(dpsi[-1] / psi_a) < 0.05 * abs(z0)  # decayed, at the rate k_1


def _steady(
    model: MotorModel, T_s: float, w: float, i_r: complex, true: MotorModel, alpha_o: float
) -> float:
    n = max(3000, round(20.0 / (ZETA * abs(w) * T_s)))  # 20 time constants 1/k_1
    errs, _, _ = run_ideal(true, model, T_s, w, i_r, n, alpha_o=alpha_o)
    tail = errs[-200:]
    assert max(tail) - min(tail) < 1e-5 * abs(tail[-1]) + 1e-12  # settled
    return tail[-1]


def _odd(
    f: float,
    key: str,
    T_s: float,
    w: float,
    i_r: complex,
    true: MotorModel = XUE,
    alpha_o: float = 400.0,
) -> float:
    """First-order part of the steady error for a relative model error ``f`` of ``key``
    (model = ``(1 - f)`` times the truth): half the difference of ``+f`` and ``-f``, in
    which the second-order terms cancel."""
    v = getattr(true, key)
    up = _steady(replace(true, **{key: v * (1.0 - f)}), T_s, w, i_r, true, alpha_o)
    dn = _steady(replace(true, **{key: v * (1.0 + f)}), T_s, w, i_r, true, alpha_o)
    return 0.5 * (up - dn)


@pytest.mark.parametrize(("w", "i_r"), [(400.0, 8j), (150.0, 8j), (-300.0, -5j), (400.0, -2 + 6j)])
def test_steady_angle_error_against_a_pm_flux_error(w: float, i_r: complex) -> None:
    """Model ``psi_f`` wrong by 2 %: ``theta~ = -b_i - b_r k_1 T cot(w T/2)/(1 - k_1 T)``,
    ``b = dpsi_f / psi_a``, ``k_1 = zeta_f |w|``, at 1 kHz (the continuous ``2 k_1 / w``
    differs by several per cent there and would fail)."""
    T = 1e-3
    f = 0.02
    got = _odd(f, "psi_f", T, w, i_r)
    psi_a = XUE.psi_f + (XUE.L_d - XUE.L_q) * i_r.conjugate()
    b = f * XUE.psi_f / psi_a  # true minus model, model = (1 - f) psi_f
    g = ZETA * abs(w) * T
    want = -b.imag - b.real * g / math.tan(w * T / 2.0) / (1.0 - g)
    cont = -b.imag - b.real * 2.0 * ZETA * abs(w) / w
    assert got == pytest.approx(want, rel=0.01)
    if abs(b.real) > abs(b.imag):
        assert abs(got - cont) > 0.03 * abs(cont)


@pytest.mark.parametrize(("w", "i_r"), [(400.0, 8j), (-250.0, 8j)])
def test_steady_angle_error_against_an_lq_error(w: float, i_r: complex) -> None:
    """Model ``L_q`` wrong by 5 %: ``dpsi = j dL_q i_q``; the ``-b_i`` part does not fall
    with speed (the floor a transition band cannot remove)."""
    T = 1e-3
    f = 0.05
    got = _odd(f, "L_q", T, w, i_r)
    psi_a = XUE.psi_f + (XUE.L_d - XUE.L_q) * i_r.conjugate()
    b = 1j * f * XUE.L_q * i_r.imag / psi_a
    g = ZETA * abs(w) * T
    want = -b.imag - b.real * g / math.tan(w * T / 2.0) / (1.0 - g)
    assert got == pytest.approx(want, rel=0.01)
    assert abs(b.imag) > 0.5 * abs(got)  # mostly the part that does not fall with speed


def _voltage_error_closed_form(v: complex, psi_a: complex, w: float, k_1: float, T: float) -> float:
    """Steady angle error for a voltage ``v`` the observer misses (rotor frame).

    The missed flux per period is ``T v`` averaged by the trapezoid over the two
    samples, so in the frame of sample ``k`` it enters as ``T N e^{-j w T}`` with
    ``N = v e^{j w T/2} cos(w T/2) / psi_a``; the steady state of the recursion
    (``C = cot(w T/2)``) is::

        x (1 - k_1 T) = -(T/2) (N_r - C N_i),   theta~ = k_1 T C x - (T/2) (N_i + C N_r)

    whose limit ``T -> 0`` is ``-Re(n)/w + (2 k_1/w^2) Im(n)``, ``n = v/psi_a``.
    """
    N = v * cmath.exp(0.5j * w * T) * math.cos(0.5 * w * T) / psi_a
    C = 1.0 / math.tan(0.5 * w * T)
    x = -0.5 * T * (N.real - C * N.imag) / (1.0 - k_1 * T)
    return k_1 * T * C * x - 0.5 * T * (N.imag + C * N.real)


@pytest.mark.parametrize(("T", "w"), [(1e-4, 200.0), (1e-4, -400.0), (1e-4, 1000.0), (1e-3, 500.0)])
def test_steady_angle_error_against_a_resistance_error(T: float, w: float) -> None:
    """Model ``R_s`` 20 % low on the Wen motor: the missed voltage ``v = -dR_s i`` gives
    the discrete closed form above (the continuous ``-Re(n)/w + (2 k_1/w^2) Im(n)`` is
    10 % off at ``w T = 0.1``); it falls as ``1/w`` and stays within the bound
    ``|v| sqrt(1 + 4 zeta_f^2) / (|w| |psi_a|)`` the transition band is built on."""
    i_r = 4j
    got = _odd(0.2, "R_s", T, w, i_r, WEN, 415.0)
    psi_a = WEN.psi_f + (WEN.L_d - WEN.L_q) * i_r.conjugate()
    v = -0.2 * WEN.R_s * i_r
    want = _voltage_error_closed_form(v, psi_a, w, ZETA * abs(w), T)
    assert got == pytest.approx(want, rel=0.01)
    n = v / psi_a
    cont = -n.real / w + 2.0 * ZETA * abs(w) / (w * w) * n.imag
    if abs(w) * T <= 0.04:  # the continuous form is the limit, not the value at 1 kHz
        assert want == pytest.approx(cont, rel=0.05)
    bound = abs(v) * math.sqrt(1.0 + 4.0 * ZETA * ZETA) / (abs(w) * abs(psi_a))
    assert abs(got) <= 1.05 * bound


def test_observer_on_the_plant_beside_the_sensored_drive() -> None:
    """The observer open loop on ``plant_rt`` (RK4, saturating d axis), fed the samples
    and the controller's bookkept voltages while the sensored drive holds 1200 rpm at
    rated load on xue2022 at 1 kHz (0.5 rad per period): the angle error stays below
    0.3 degrees (what is left: the plant's saturation and the trapezoid on ``R_s i``)."""
    P = preset("xue2022")
    plant, ctrl = make_loop(P, "sensored", theta_e0=0.3)
    # the oracle (tests/oracle): its bookkept voltages (``_u_a2``, ``_u_b2``) are attributes
    # the test reads each period; the core keeps them in C (same trace)
    ctrl = OracleController(ctrl.pars)
    ctrl.set_enable(True)
    # the hybrid's gains for this motor (controller/_hybrid.py): alpha_o, zeta_f, w_lo
    obs = FluxObserver(XUE, P.T_s, 405.0, ZETA, 23.4)
    obs.reset(0.3)
    d_a = d_b = d_c = 0.5
    en = False
    worst = 0.0
    for _ in range(int(3.0 / P.T_s)):
        s = plant.sample()
        tr = plant.truth()
        ctrl.set_speed_ref(min(tr.t / 1.5, 1.0) * 1200.0 * RPM)
        if tr.t > 2.0:
            plant.set_load(ConstantLoad(P.motor.tau_rated * min((tr.t - 2.0) / 0.5, 1.0)))
        u_a, u_b = ctrl._u_a2, ctrl._u_b2  # the voltage the estimator input carries
        out = ctrl.step(Measurement(s.k, s.i_a, s.i_b, s.i_c, s.u_dc, tr.theta_e, tr.w_e))
        i_al = (2.0 * s.i_a - s.i_b - s.i_c) / 3.0
        i_be = (s.i_b - s.i_c) / math.sqrt(3.0)
        obs.update(i_al, i_be, u_a, u_b)
        plant.step(d_a, d_b, d_c, en)
        d_a, d_b, d_c, en = out.d_a, out.d_b, out.d_c, out.enable
        if tr.t > 1.6:
            worst = max(worst, abs(_wrap(tr.theta_e - obs.theta_hat)))
    assert abs(plant.truth().w_m / RPM - 1200.0) < 5.0
    assert worst < math.radians(0.3)
