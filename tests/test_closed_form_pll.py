"""PositionObserver (PI-type PLL, Wen Fig. 4) against the closed forms of its loop.

The code's update with the linearised error ``e_k = theta_k - theta_hat_k`` as input::

    w_i[k+1]       = w_i[k] + T k_i e_k
    w_hat[k]       = k_p e_k + w_i[k+1]
    theta_hat[k+1] = theta_hat[k] + T w_hat[k]

gives the open loop ``L(z) = T (k_p (z - 1) + T k_i z) / (z - 1)^2`` and the
characteristic polynomial

    D(z) = z^2 - (2 - T k_p - T^2 k_i) z + (1 - T k_p)

which with the docstring's design ``k_p = 2 w_o``, ``k_i = w_o^2`` and
``a = w_o T`` is ``z^2 - (2 - 2a - a^2) z + (1 - 2a)``: two real poles
``1 - a - a^2/2 +- sqrt(a^3 (4 + a))/2`` next to the designed double pole
``exp(-a)`` (continuous ``s = -w_o``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller import PositionObserver

W_O = 2.0 * math.pi * 20.0  # default observer bandwidth of the rotating estimators (rad/s)
T_WEN = 1e-4  # wen2023 sampling period (s)
T_XUE = 1e-3  # xue2022 sampling period (s)
TH0 = 1.0  # operating angle (rad), away from the 0 / 2 pi wrap


def _error_matrix(w_o: float, T_s: float) -> np.ndarray:
    """Matrix of the map (e_k, w_i[k]) -> (e_{k+1}, w_i[k+1]) at constant theta, probed from the code."""
    cols = []
    for e0, wi0 in ((1e-3, 0.0), (0.0, 1.0)):
        p = PositionObserver(w_o, T_s)
        p.theta_hat = TH0 - e0
        p.w_i = wi0
        p.update(TH0 - p.theta_hat)
        cols.append((TH0 - p.theta_hat, p.w_i))
    # column 0 was probed with e0 = 1e-3: scale it to a unit input
    a = np.array(cols, dtype=float).T
    a[:, 0] /= 1e-3
    return a


@pytest.mark.parametrize("T_s", [T_WEN, T_XUE])
def test_gains_follow_docstring_design(T_s: float) -> None:
    """k_p = 2 w_o, k_i = w_o^2 (catches swapped or squared gains)."""
    p = PositionObserver(W_O, T_s)
    assert p.k_p == pytest.approx(2.0 * W_O, rel=1e-15)
    assert p.k_i == pytest.approx(W_O * W_O, rel=1e-15)


@pytest.mark.parametrize("T_s", [T_WEN, T_XUE])
def test_error_dynamics_eigenvalues(T_s: float) -> None:
    """Eigenvalues of the probed error map equal the roots of D(z) derived above, and lie
    next to the designed double pole exp(-w_o T)."""
    a = W_O * T_s
    A = _error_matrix(W_O, T_s)
    # Trace and determinant of the code's map against D(z). A loop that used the old
    # integrator state in w_hat (w_hat = k_p e + w_i[k]) has trace 2 - 2a and det
    # (1 - a)^2 and fails here; so do swapped gains (trace 2 - 2 w_o^2 T - 2 w_o T^2 ...).
    assert np.trace(A) == pytest.approx(2.0 - 2.0 * a - a * a, abs=1e-9)
    assert np.linalg.det(A) == pytest.approx(1.0 - 2.0 * a, abs=1e-9)
    z = np.sort(np.linalg.eigvals(A).real)
    half = 0.5 * math.sqrt(a**3 * (4.0 + a))
    assert z == pytest.approx(
        [1.0 - a - 0.5 * a * a - half, 1.0 - a - 0.5 * a * a + half], abs=1e-9
    )
    # Designed double pole s = -w_o: the continuous equivalents ln(z)/T of the two poles
    # are -w_o (1 -+ sqrt(a)) + O(a w_o) (split of the Euler-type loop), and their mean
    # ln(det)/(2T) = ln(1 - 2a)/(2T) = -w_o (1 + a + 4a^2/3 + ...). A bandwidth off by
    # 10 % moves the mean by 0.1 w_o and fails at both rates.
    s_each = np.log(z) / T_s
    assert np.all(np.abs(s_each / W_O + 1.0) < math.sqrt(a) + 2.0 * a)
    s_mean = math.log(z[0] * z[1]) / (2.0 * T_s)
    assert s_mean == pytest.approx(-W_O, rel=a + 2.0 * a * a)
    assert abs(s_mean / W_O + 1.0) > 0.9 * a  # the O(a) Euler offset is really there


@pytest.mark.parametrize("T_s", [T_WEN, T_XUE])
def test_constant_speed_zero_steady_error(T_s: float) -> None:
    """Type-2 loop: a constant speed gives zero angle error and w_hat = w_e.

    A type-1 loop (k_i = 0 or an integrator that never updates) would settle at
    ``w / k_p`` = 0.25 rad for 100 rad/s at w_o = 2 pi 20."""
    w_e = 100.0
    p = PositionObserver(W_O, T_s)
    p.reset(TH0)
    n = int(round(15.0 / (W_O * T_s)))  # 15 time constants
    e = 0.0
    for k in range(n):
        theta = (TH0 + w_e * k * T_s) % (2.0 * math.pi)
        e = math.remainder(theta - p.theta_hat, 2.0 * math.pi)
        p.update(e)
    assert abs(e) < 1e-4 * w_e / p.k_p
    assert p.w_hat == pytest.approx(w_e, rel=1e-4)


@pytest.mark.parametrize("T_s", [T_WEN, T_XUE])
def test_speed_ramp_steady_error_alpha_over_k_i(T_s: float) -> None:
    """theta_k = alpha (k T)^2 / 2: final value of (z - 1) E(z) = alpha T^2 / D(1) = alpha / k_i.

    D(1) = T^2 k_i exactly, so the discrete loop keeps the continuous value
    ``alpha / w_o^2`` (0.0633 rad for alpha = 1000 rad/s^2). Catches a wrong k_i and a
    type-3 mistake (zero error) alike."""
    alpha = 1000.0
    p = PositionObserver(W_O, T_s)
    p.reset(0.0)
    n = int(round(20.0 / (W_O * T_s)))
    e = 0.0
    for k in range(n):
        t = k * T_s
        theta = (0.5 * alpha * t * t) % (2.0 * math.pi)
        e = math.remainder(theta - p.theta_hat, 2.0 * math.pi)
        p.update(e)
    assert e == pytest.approx(alpha / (W_O * W_O), rel=1e-5)
    assert p.w_hat == pytest.approx(alpha * (n - 0.5) * T_s, rel=1e-6)


def _step_response_error(T_s: float, dth: float, dw: float) -> float:
    """Max |e_k - e(kT)| / scale over 12 time constants for a step in angle or speed."""
    p = PositionObserver(W_O, T_s)
    p.reset(TH0)
    n = int(round(12.0 / (W_O * T_s)))
    worst = 0.0
    for k in range(n):
        t = k * T_s
        theta = TH0 + dth + dw * t
        e = theta - p.theta_hat
        # Closed forms of E(s) = Theta(s) s^2 / (s + w_o)^2:
        #   angle step dth / s      -> dth (1 - w_o t) e^{-w_o t}
        #   speed step dw / s^2     -> dw t e^{-w_o t}
        ref = (dth * (1.0 - W_O * t) + dw * t) * math.exp(-W_O * t)
        worst = max(worst, abs(e - ref))
        p.update(e)
    return worst


@pytest.mark.parametrize(("dth", "dw"), [(0.3, 0.0), (0.0, 50.0)])
def test_step_response_matches_continuous_closed_form(dth: float, dw: float) -> None:
    """Angle step: e(t) = dth (1 - w_o t) e^{-w_o t}; speed step: e(t) = dw t e^{-w_o t}.

    For the PI loop the error of an angle step is ``s / (s + w_o)^2``, hence
    ``(1 - w_o t)``: ``(1 + w_o t) e^{-w_o t}`` is the free response from
    ``e(0) = dth, de/dt(0) = 0``, not the step response (the proportional path makes
    ``de/dt(0+) = -k_p dth``). The discrete loop is a first-order (Euler) integration
    of the continuous one, so the deviation is O(w_o T) of the scale (dth, or the peak
    dw / (e w_o) of the speed-step error): asserted below ``w_o T`` at 10 kHz and 1 kHz,
    and shrinking ~10x per 10x in T_s (first-order convergence). A bandwidth error of
    5 % or a missing proportional path gives a deviation of order 0.05-1 and fails.
    """
    scale = dth if dth else dw / (math.e * W_O)
    d_xue = _step_response_error(T_XUE, dth, dw) / scale
    d_wen = _step_response_error(T_WEN, dth, dw) / scale
    assert d_xue < W_O * T_XUE
    assert d_wen < W_O * T_WEN
    assert 7.0 < d_xue / d_wen < 13.0
