"""Xue eq. (6) (square-wave injection current envelope) against the plant itself.

Eq. (6): a voltage ``dU`` injected along the estimated d axis ``theta_hat`` for
the time ``1/w_h`` changes the stator current by

    di_ab = dU / (L_d L_q w_h) [L_avg cos(th_hat) - L_dif cos(2 th_e - th_hat),
                                L_avg sin(th_hat) - L_dif sin(2 th_e - th_hat)]

``L_avg = (L_d + L_q)/2``, ``L_dif = (L_d - L_q)/2`` (printed sign). Here the
voltage is held for one PWM period ``T_s`` (the half-period of Xue's square wave,
eq. (3)), so ``1/w_h`` becomes ``T_s``. Eq. (2) neglects R_s and the back-EMF; the
plant is held at standstill (no EMF) and keeps R_s, so per rotor axis it gives the
exact RL step ``u/R (1 - exp(-R T_s / L))`` = ``(u T_s / L)(1 - R T_s / (2L) + ...)``:
eq. (6) is reached within the relative resistive term ``R T_s / (2 L_d)`` (2.7 % on
xue2022 at 1 kHz), which shrinks with R.
"""

from __future__ import annotations

import cmath
import dataclasses
import math

import pytest

from controller import svpwm
from plant_rt import InverterPars, MotorPars, Plant, preset

PRE = preset("xue2022")
M = PRE.motor
T_S = PRE.T_s  # 1 kHz
U_DC = 540.0
U_H = 40.0  # injection amplitude (V); well inside the SVPWM linear range


def _eq6(U: float, th_e: float, th_hat: float, L_d: float, L_q: float) -> complex:
    """Eq. (6) with 1/w_h -> T_s, as a complex alpha-beta vector."""
    L_avg = 0.5 * (L_d + L_q)
    L_dif = 0.5 * (L_d - L_q)
    k = U * T_S / (L_d * L_q)
    return k * (L_avg * cmath.exp(1j * th_hat) - L_dif * cmath.exp(1j * (2.0 * th_e - th_hat)))


def _one_period(motor: MotorPars, th_e: float, th_hat: float, U: float) -> tuple[complex, Plant]:
    """Plant at rest, speed held at 0, one period of U along th_hat; return di_ab."""
    p = Plant(motor, InverterPars(u_dc=U_DC), T_S, saturation=False, theta_m0=th_e / motor.n_p)
    p.impose_speed(0.0)
    i0 = p.currents_abc()
    u = U * cmath.exp(1j * th_hat)
    p.step(*svpwm(u.real, u.imag, U_DC))
    i1 = p.currents_abc()
    # amplitude-invariant Clarke of the phase currents
    di = [b - a for a, b in zip(i0, i1, strict=True)]
    return complex(di[0], (di[1] - di[2]) / math.sqrt(3.0)), p


DTHETAS = [0.0, 0.2, -0.2, math.pi / 4, -math.pi / 3, math.pi / 2, 2.0, math.pi]


@pytest.mark.parametrize("dtheta", DTHETAS)
@pytest.mark.parametrize("th_e", [0.7, 4.0])
@pytest.mark.parametrize("U", [U_H, -U_H], ids=["+U", "-U"])
def test_plant_current_step_matches_eq6(th_e: float, dtheta: float, U: float) -> None:
    """di_ab of the plant vs eq. (6) for dtheta = th_e - th_hat.

    1. Exact: the RL step per rotor axis, within the RK4 truncation of the plant
       (relative ``x^4/120`` with ``x = R_s T_s / (substeps L_d)``: 4.4e-9 here).
    2. Eq. (6) within ``(R T_s / (2 L_d)) |dU| T_s / L_d`` (bound of the neglected
       resistive term, largest on the d axis), and the deviation is really of that
       order (> 1/4 of it along the d axis when the voltage has a d component).
    Catches: L_d/L_q swapped in the plant (error ~|L_d - L_q| / L_q ~ 50 %), the voltage
    rotated by -theta (wrong Park sign), a factor 3/2 or sqrt(3) in the Clarke/duty
    chain, a half-period voltage (factor 1/2) or a back-EMF at standstill.
    """
    th_hat = th_e - dtheta
    di, p = _one_period(M, th_e, th_hat, U)
    tr = p.truth()
    assert tr.w_m == 0.0 and tr.theta_e == pytest.approx(th_e % (2.0 * math.pi), abs=1e-12)
    # 1. exact RL response of the rotor axes (the plant's own physics)
    u_dq = U * cmath.exp(-1j * dtheta)
    q_d = 1.0 - math.exp(-M.R_s * T_S / M.L_d)
    q_q = 1.0 - math.exp(-M.R_s * T_S / M.L_q)
    di_dq = complex(u_dq.real / M.R_s * q_d, u_dq.imag / M.R_s * q_q)
    x = M.R_s * T_S / (p.substeps * M.L_d)
    rk4 = x**4 / 60.0  # twice the leading RK4 term
    assert tr.i_d == pytest.approx(di_dq.real, rel=rk4, abs=1e-12)
    assert tr.i_q == pytest.approx(di_dq.imag, rel=rk4, abs=1e-12)
    assert abs(di - di_dq * cmath.exp(1j * th_e)) <= rk4 * abs(di_dq) + 1e-12
    # 2. eq. (6)
    want = _eq6(U, th_e, th_hat, M.L_d, M.L_q)
    bound = M.R_s * T_S / (2.0 * M.L_d) * abs(U) * T_S / M.L_d
    dev = abs(di - want)
    assert dev <= bound
    if abs(math.cos(dtheta)) > 0.5:
        assert dev > 0.25 * bound  # R_s is really in the plant


@pytest.mark.parametrize("dtheta", DTHETAS)
def test_eq6_reached_as_resistance_vanishes(dtheta: float) -> None:
    """With R_s scaled by 1e-6 the plant meets eq. (6) to ~1e-8 relative: the only
    difference to the HF model of eq. (2) is the resistive drop."""
    motor = dataclasses.replace(M, R_s=M.R_s * 1e-6)
    th_e = 0.7
    th_hat = th_e - dtheta
    di, _ = _one_period(motor, th_e, th_hat, U_H)
    want = _eq6(U_H, th_e, th_hat, motor.L_d, motor.L_q)
    assert abs(di - want) <= motor.R_s * T_S / motor.L_d * abs(want) + 1e-12


def test_envelope_quadrature_and_error_information() -> None:
    """Eq. (6) carries the angle error: in the estimated frame the q component of di is
    ``-(L_dif / (L_d L_q)) U T_s sin(2 dtheta)`` (zero at dtheta = 0 and pi/2, sign of
    dtheta for |dtheta| < pi/2 since L_dif < 0), and the plant shows exactly that up to
    the resistive term. A saliency sign error in the plant would flip it."""
    th_e = 1.1
    L_dif = 0.5 * (M.L_d - M.L_q)
    for dtheta in (-0.6, -0.1, 0.1, 0.6):
        th_hat = th_e - dtheta
        di, _ = _one_period(M, th_e, th_hat, U_H)
        di_q_hat = (di * cmath.exp(-1j * th_hat)).imag
        want = -L_dif / (M.L_d * M.L_q) * U_H * T_S * math.sin(2.0 * dtheta)
        assert math.copysign(1.0, di_q_hat) == math.copysign(1.0, dtheta)
        assert di_q_hat == pytest.approx(want, rel=M.R_s * T_S / M.L_d)
