"""The rotating-injection estimators' mechanical observer (``observer = "mechanical"``).

Closed forms: the poles of the observer with a separate load pole, its
transfer function against the state-space of the code, the phase margin its
design achieves with tt-dq's filters in the loop, the speed response the
speed loop is designed with (exactly 1 for tt-dq), and the torque
feed-forward: a commanded acceleration leaves the angle untouched where the
PLL lags by ``alpha / w_o^2``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller._api import EstimatorInput
from controller._design import PM_TARGET_DEG
from controller._luenberger import observer_response
from controller._rotating import LOAD_POLE_RATIO, RotatingInjectionPars, in_loop_response
from plant_rt import preset
from tests.loop_helpers import motor_model
from tests.oracle.blocks import OracleLuenbergerObserver
from tests.oracle.estimators import OracleTTDQEstimator

WEN = preset("wen2023")
T_S = WEN.T_s
MODEL = motor_model(WEN)


def _obs_matrix(a: float, b: float) -> np.ndarray:
    """Closed-loop matrix of the code's update with ``e = theta - theta_hat`` (theta = 0)."""
    cols = []
    for j in range(3):
        x0 = np.zeros(3)
        x0[j] = 1e-3
        o = OracleLuenbergerObserver(J=MODEL.J, n_p=MODEL.n_p, a=a, T_s=T_S, b=b)
        o.reset(1.0 + x0[0], x0[1], x0[2])
        o.step(-x0[0], 0.0)
        cols.append((np.array([o.theta_hat - 1.0, o.w_hat, o.x])) / 1e-3)
    return np.array(cols).T


def test_load_pole_places_double_angle_pole_and_load_pole() -> None:
    """Poles of the discrete loop at ``1 - a T_s`` (double) and ``1 - b T_s``: the Euler
    image of ``(s + a)^2 (s + b)``."""
    a, b = 60.0, 6.0
    eig = np.sort(np.linalg.eigvals(_obs_matrix(a, b)).real)
    want = np.sort([1 - a * T_S, 1 - a * T_S, 1 - b * T_S])
    assert eig == pytest.approx(want, abs=2e-4)  # the double pole splits by sqrt(eps)-ish


def test_triple_pole_default_unchanged() -> None:
    """``b = None`` is Xue's triple pole with Xue's gains, bit for bit."""
    o = OracleLuenbergerObserver(J=0.01, n_p=3, a=50.0, T_s=1e-3)
    assert (o.K_1, o.K_2, o.K_3) == (50.0**3 * 0.01, 3.0 * 50.0**2 * 0.01, 3.0 * 50.0 * 0.01)
    o2 = OracleLuenbergerObserver(J=0.01, n_p=3, a=50.0, T_s=1e-3, b=50.0)
    assert pytest.approx((o.K_1, o.K_2, o.K_3), rel=1e-12) == (o2.K_1, o2.K_2, o2.K_3)


def test_observer_response_is_the_codes_transfer_function() -> None:
    """``observer_response`` with a load pole against the state-space of the code."""
    a, b = 60.0, 6.0
    A = _obs_matrix(a, b)
    # input vector: response to e = 1e-3 from the zero state
    o = OracleLuenbergerObserver(J=MODEL.J, n_p=MODEL.n_p, a=a, T_s=T_S, b=b)
    o.reset(1.0, 0.0, 0.0)
    o.step(1e-3, 0.0)
    B = np.array([o.theta_hat - 1.0, o.w_hat, o.x]) / 1e-3
    # the code's A uses e = -theta_hat; without the feedback part: A0 = A + B [1 0 0]
    A0 = A + np.outer(B, [1.0, 0.0, 0.0])
    w = np.geomspace(1.0, 3000.0, 25)
    z = np.exp(1j * w * T_S)
    th, wo = observer_response(a, T_S, z, b)
    for zz, t_c, w_c in zip(z, th, wo, strict=True):
        x = zz * np.linalg.solve(zz * np.eye(3) - A0, B)  # states after the step of sample k
        assert x[0] == pytest.approx(t_c, rel=1e-6)
        assert x[1] == pytest.approx(w_c, rel=1e-6)


def _tt_dq(observer: str) -> OracleTTDQEstimator:
    return OracleTTDQEstimator(MODEL, T_S, RotatingInjectionPars(observer=observer))


def test_design_meets_phase_margin_with_tt_dq_filters() -> None:
    """The designed poles give the 45-degree target with the BPF and LPF in the loop,
    checked on an independent evaluation of the loop; more gain would lose margin."""
    est = _tt_dq("mechanical")
    a = est.w_o
    b = LOAD_POLE_RATIO * a
    w = np.geomspace(0.05 * a, 0.999 * math.pi / T_S, 40000)
    z = np.exp(1j * w * T_S)
    L = observer_response(a, T_S, z, b)[0] * in_loop_response(
        "bpf+lpf", T_S, est.w_h, est.filters_z, w
    )
    i = int(np.nonzero(np.abs(L) < 1.0)[0][0])
    ph = np.degrees(np.unwrap(np.angle(L[: i + 1])))
    ph += 360.0 * round((-270.0 - ph[0]) / 360.0)
    assert 180.0 + ph[-1] == pytest.approx(PM_TARGET_DEG, abs=0.3)
    g = est.gains()
    assert g["pm_deg"] == pytest.approx(PM_TARGET_DEG, abs=0.1)
    assert g["a"] == a and g["K_1"] == pytest.approx(a * a * b * MODEL.J)
    # the load pole costs a little of the angle loop: a is within 10 % of the PLL's w_o
    assert 0.9 * _tt_dq("pll").w_o < a < _tt_dq("pll").w_o


def test_speed_response_is_one_for_tt_dq() -> None:
    """With the torque fed forward the speed estimate needs no lag in the speed loop
    (``G_m = G`` for tt-dq); the PLL's is a low-pass at its bandwidth."""
    w = np.geomspace(1.0, 300.0, 30)
    assert np.abs(_tt_dq("mechanical").speed_response(w) - 1.0).max() < 1e-9
    pll = _tt_dq("pll").speed_response(w)
    assert abs(pll[-1]) < 0.9 or abs(np.angle(pll[-1])) > 0.3


def _hf_current(est: OracleTTDQEstimator, k: int, theta: float) -> tuple[float, float]:
    """The HF current of eq. (4)/(7) at sample ``k`` for the rotor angle ``theta``
    (the model amplitudes: what the estimator expects, so ``err`` is exact)."""
    ph = k * est.wT
    ng = 2.0 * theta - ph
    return (
        est.I_p * math.sin(ph) - est.I_n * math.sin(ng),
        -est.I_p * math.cos(ph) + est.I_n * math.cos(ng),
    )


@pytest.mark.parametrize("observer", ["pll", "mechanical"])
def test_commanded_acceleration_is_fed_forward(observer: str) -> None:
    """A constant electromagnetic torque on a frictionless, unloaded rotor: the PLL lags
    by about ``alpha / w_o^2``, the mechanical observer tracks with no steady error."""
    est = _tt_dq(observer)
    tau = 0.02 * MODEL.tau_max
    alpha = MODEL.n_p * tau / MODEL.J  # electrical rad/s^2
    est.reset(0.0)
    theta = 0.0
    w = 0.0
    n = int(0.4 / T_S)
    errs = []
    for k in range(n):
        t = k * T_S
        theta = 0.5 * alpha * t * t
        w = alpha * t
        i_a, i_b = _hf_current(est, k, theta)
        est.update(EstimatorInput(k=k, i_alpha=i_a, i_beta=i_b, torque=tau))
        d = (theta - est.theta_hat + math.pi) % (2 * math.pi) - math.pi
        errs.append(d)
    late = np.array(errs[-int(0.05 / T_S) :])
    if observer == "pll":
        assert late.mean() == pytest.approx(alpha / est.w_o**2, rel=0.15)
    else:
        assert abs(late).max() < 0.05 * alpha / _tt_dq("pll").w_o ** 2
    assert w > 0.0
