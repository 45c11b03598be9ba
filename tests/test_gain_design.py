"""Gains by design: the phase margins the observer and PLL gains achieve, computed here
independently of :mod:`controller._design`, and the loop models checked against the code.

Independent means: the observers' transfer functions are probed from the
code's own update (state-space matrices from unit inputs), the filters'
responses come from :func:`scipy.signal.freqz` on the coefficients the
estimators use, and the margin is read off a dense grid. The loop models
themselves are checked in the time domain: the estimators run on synthetic
HF currents with their angle prescribed, and the error they produce is
compared with the chain the design assumes, so a delay counted once too
often or once too few fails here.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from scipy import signal

from controller import (
    ESTIMATOR_NAMES,
    PM_TARGET_DEG,
    CompensationPars,
    Controller,
    ControllerPars,
    EstimatorInput,
)
from controller._pll import PositionObserver
from controller._registry import injection_family
from controller._rotating import in_loop_response
from plant_rt import preset
from tests.loop_helpers import motor_model
from tests.oracle.blocks import OracleLuenbergerObserver
from tests.oracle.estimators import OracleSquareWaveEstimator, make_oracle_estimator
from tests.test_controller_square_wave import MOTOR as XUE_MODEL
from tests.test_controller_square_wave import HFPlant

WEN = preset("wen2023")
T_WEN = WEN.T_s
T_XUE = 1e-3
WEN_MODEL = motor_model(WEN)
W_H = 2.0 * math.pi * 500.0

# --------------------------------------------------------------------------- helpers


def _margin(L: np.ndarray, w: np.ndarray, n_int: int) -> tuple[float, float]:
    """(phase margin deg, crossover rad/s) at the first |L| = 1 on an ascending grid."""
    mag = np.abs(L)
    i = int(np.nonzero(mag < 1.0)[0][0])
    ph = np.degrees(np.unwrap(np.angle(L)))
    ph += 360.0 * round((-90.0 * n_int - ph[0]) / 360.0)
    # log-linear interpolation between grid points i-1 and i
    x = (0.0 - math.log(mag[i - 1])) / (math.log(mag[i]) - math.log(mag[i - 1]))
    w_c = math.exp(math.log(w[i - 1]) + x * (math.log(w[i]) - math.log(w[i - 1])))
    return 180.0 + float(ph[i - 1] + x * (ph[i] - ph[i - 1])), w_c


def _freqz(z: tuple[tuple[float, ...], tuple[float, ...]], w: np.ndarray, T_s: float) -> np.ndarray:
    """Discrete response at signed angular frequencies ``w`` (rad/s)."""
    _, h = signal.freqz(z[0], z[1], worN=np.asarray(w) * T_s)
    return np.asarray(h)


def _state_space(
    step: Callable[[np.ndarray, float], np.ndarray], n: int
) -> tuple[np.ndarray, np.ndarray]:
    """``(A, B)`` of ``x_next = A x + B e`` probed from ``step(x, e)`` with unit inputs."""
    zero = np.zeros(n)
    B = step(zero, 1.0)
    A = np.column_stack([step(np.eye(n)[j], 0.0) for j in range(n)])
    return A, B


def _response(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: float, z: np.ndarray) -> np.ndarray:
    """``C (z I - A)^-1 B + D`` at each ``z``."""
    n = A.shape[0]
    return np.array([C @ np.linalg.solve(zz * np.eye(n) - A, B) + D for zz in z])


# -------------------------------------------------------------- square-wave observer (Xue)


def _luenberger_ss(a: float, T_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(A, B) of the code's observer around theta = 1 rad (away from the wrap):
    states (theta_hat, w_hat, x) after the step of sample k from the step of k-1."""
    th0 = 1.0

    def step(x: np.ndarray, e: float) -> np.ndarray:
        obs = OracleLuenbergerObserver(J=XUE_MODEL.J, n_p=XUE_MODEL.n_p, a=a, T_s=T_s)
        obs.reset(th0 + x[0], x[1], x[2])
        obs.step(e, 0.0)
        return np.array([obs.theta_hat - th0, obs.w_hat, obs.x])

    return _state_space(step, 3)


def _square_wave_loop(a: float, T_s: float, w: np.ndarray, cic: bool, c: float) -> np.ndarray:
    """Slow-rate loop gain from the probed observer and the FIR chain (hold, CIC, delay, pair)."""
    A, B = _luenberger_ss(a, T_s)
    # the states after step k respond to e(k) directly: X = (I - A z^-1)^-1 B E = z (zI - A)^-1 B E
    C = np.array([1.0, c * T_s, 0.0])  # phi = theta_hat + c T_s w_hat

    def f(z: np.ndarray) -> np.ndarray:
        obs = z * _response(A, B, C, 0.0, z)
        zi = 1.0 / z
        fir = (1.0 + zi) * ((1.0 + zi) / 2.0 if cic else 1.0) * zi * 0.5 * (zi + zi * zi)
        return np.asarray(fir * obs)

    z = np.exp(1j * w * T_s)
    return 0.5 * (f(z) + f(-z))


@pytest.mark.parametrize("cic", [True, False])
def test_square_wave_observer_pole_meets_phase_margin(cic: bool) -> None:
    """The default pole gives the target margin (45 deg) at 1 kHz, the loop stays stable
    with 3x more or 4x less gain, and the old 0.1 / (3.5 T_s) had 57 degrees."""
    est = OracleSquareWaveEstimator(XUE_MODEL, T_XUE, cic=cic)
    a = est.observer.a
    w = np.geomspace(0.05 * a, 0.999 * math.pi / (2 * T_XUE), 60000)
    L = _square_wave_loop(a, T_XUE, w, cic, 1.5)
    pm, w_c = _margin(L, w, 3)
    assert pm == pytest.approx(PM_TARGET_DEG, abs=0.2)
    assert est.gains()["pm_deg"] == pytest.approx(pm, abs=0.2)
    assert est.gains()["w_c"] == pytest.approx(w_c, rel=2e-3)
    # gain margins on both sides (type 3: too little gain is unstable too)
    for k in (3.0, 0.25):
        poles_stable = np.all(np.abs(L * k + 1.0) > 0.0)
        assert poles_stable
        # Nyquist: the -1 point is not encircled iff the phase at |kL| = 1 keeps > 0 margin
        assert _margin(k * L, w, 3)[0] > 0.0
    # the numbers of the docstring
    assert a == pytest.approx(50.8 if cic else 60.9, abs=0.1)
    if cic:
        old = 0.1 / (3.5 * T_XUE)
        assert _margin(_square_wave_loop(old, T_XUE, w, True, 1.5), w, 3)[0] == pytest.approx(
            56.7, abs=0.3
        )


def test_square_wave_pm_target_and_pole_are_overridable() -> None:
    est50 = OracleSquareWaveEstimator(XUE_MODEL, T_XUE, pm_deg=50.0)
    assert est50.gains()["pm_deg"] == pytest.approx(50.0, abs=0.05)
    assert est50.observer.a < OracleSquareWaveEstimator(XUE_MODEL, T_XUE).observer.a
    assert OracleSquareWaveEstimator(XUE_MODEL, T_XUE, a=40.0).observer.a == 40.0


class _Prescribed:
    """Stands in for the observer: the angle follows a prescribed sequence, speed 0."""

    def __init__(self, theta: np.ndarray) -> None:
        self.seq = theta
        self.k = 0
        self.theta_hat = float(theta[0])
        self.w_hat = 0.0

    def step(self, e: float, tau_e: float) -> None:
        """After the step of sample k the angle is ``seq[k]``."""
        self.theta_hat = float(self.seq[self.k])
        self.k += 1

    def reset(self, theta0: float, w0: float, x0: float) -> None:
        self.theta_hat = theta0


@pytest.mark.parametrize("cic", [True, False])
def test_square_wave_chain_timing_matches_the_design_model(cic: bool) -> None:
    """Estimator on the standstill HF plant with its angle prescribed: its error equals the
    chain of the design (phi(k+1) = theta_hat(k); envelope of periods k-2, k-1 at the odd
    steps; hold; CIC) on ``theta_e - phi`` to first order in a 0.02 rad wobble."""
    theta = 0.7
    n = 400
    k = np.arange(n + 1)
    th_hat = theta - 0.05 + 0.02 * np.sin(2 * math.pi * k / 37.0) + 0.01 * np.sin(k / 5.0)
    est = OracleSquareWaveEstimator(XUE_MODEL, T_XUE, cic=cic, delay_comp=0.0)
    est.reset(float(th_hat[0]))
    est.observer = _Prescribed(th_hat)  # type: ignore[assignment]
    plant = HFPlant(theta)
    errs = []
    for j in range(n):
        est.update(EstimatorInput(j, plant.i_a, plant.i_b, 0.0))
        errs.append(est.err)
        plant.step(est.injection())
    # the design's chain, linear: phi of period p is theta_hat(p - 1) (the sample before)
    phi = np.concatenate(([np.nan], th_hat[:-1]))
    m = theta - phi  # error of each period
    held = np.full(n, np.nan)
    for j in range(3, n):
        if j % 2 == 1:  # period j - 1 had -U_h: the pair (j - 2, j - 1) closes at j
            held[j] = 0.5 * (m[j - 1] + m[j - 2])
        else:
            held[j] = held[j - 1]
    want = 0.5 * (held + np.roll(held, 1)) if cic else held
    e = np.array(errs)
    sl = slice(10, n)
    # sin(2 x)/2 against x: third-order error (2/3) x^3 = 1e-4 rad at 0.08 rad
    np.testing.assert_allclose(e[sl], want[sl], atol=3e-4)
    # a chain one period shorter would differ by far more than the tolerance
    assert np.abs(e[sl] - np.roll(want, 1)[sl]).max() > 10 * 3e-4


# ------------------------------------------------------------------ rotating-injection PLLs


def _pll_ss(w_o: float, T_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(A, B) of the code's PLL, states (theta_hat, w_i), theta around 1 rad."""
    th0 = 1.0

    def step(x: np.ndarray, e: float) -> np.ndarray:
        p = PositionObserver(w_o, T_s)
        p.theta_hat = th0 + x[0]
        p.w_i = x[1]
        p.update(e)
        return np.array([p.theta_hat - th0, p.w_i])

    return _state_space(step, 2)


def _pll_loop(est: object, w: np.ndarray, w_o: float | None = None) -> np.ndarray:
    """O(z) from the probed PLL times the demodulator's in-loop chain from scipy's freqz."""
    T_s = T_WEN
    w_o = est.w_o if w_o is None else w_o  # type: ignore[attr-defined]
    A, B = _pll_ss(w_o, T_s)
    z = np.exp(1j * w * T_s)
    O = _response(A, B, np.array([1.0, 0.0]), 0.0, z)  # theta_hat(k+1) from e(k): no z factor
    loop = est.IN_LOOP  # type: ignore[attr-defined]
    bz = est.bpf_z  # type: ignore[attr-defined]
    h_p = _freqz(bz, np.array([W_H]), T_s)[0]
    h_n = _freqz(bz, np.array([-W_H]), T_s)[0]
    if loop == "none":  # the error's amplitude through the BPF, I_p I_n |H_B(w_h)|^2
        return O * abs(h_p * h_n)
    G = _freqz(est.lpf_z, w, T_s)  # type: ignore[attr-defined]
    if loop == "lpf":  # the negative sequence through BPF and HPF (Table 3, conventional)
        G = G * abs(h_n * _freqz(est.hpf_z, np.array([-2 * W_H]), T_s)[0])  # type: ignore[attr-defined]
    else:
        G = (
            G
            * abs(h_p * h_n)
            * 0.5
            * (_freqz(bz, W_H + w, T_s) / h_p + _freqz(bz, w - W_H, T_s) / h_n)
        )
    return O * G


@pytest.mark.parametrize("name", ["tt-dq", "sfhf", "tt-ab"])
def test_pll_bandwidth_meets_phase_margin(name: str) -> None:
    """Each demodulator's PLL reaches the target margin with its in-loop filters, unless
    its crossover reached the LPF's -3 dB corner first (tt-ab: nothing in its loop)."""
    est = make_oracle_estimator(name, WEN_MODEL, T_WEN)
    w = np.geomspace(1e-2 * est.w_o, 0.999 * math.pi / T_WEN, 80000)  # type: ignore[attr-defined]
    pm, w_c = _margin(_pll_loop(est, w), w, 2)
    g = est.gains()
    assert g["pm_deg"] == pytest.approx(pm, abs=0.1)
    assert g["w_c"] == pytest.approx(w_c, rel=2e-3)
    _, h = signal.freqz(*est.lpf_z, worN=[628.0 * T_WEN])  # type: ignore[attr-defined]
    assert abs(h[0]) == pytest.approx(math.sqrt(0.5), rel=1e-6)  # the corner of eq. (13)
    if name == "tt-ab":
        assert w_c == pytest.approx(628.0, rel=2e-3)
        assert pm > PM_TARGET_DEG
    else:
        assert pm == pytest.approx(PM_TARGET_DEG, abs=0.2)
        assert w_c < 628.0
    want = {"tt-dq": 58.5, "sfhf": 190.1, "tt-ab": 303.0}[name]  # docstring of _rotating
    assert est.w_o == pytest.approx(want, abs=0.1)  # type: ignore[attr-defined]


def test_old_tt_dq_bandwidth_had_21_degrees() -> None:
    """The issue's figure: w_o = 2 pi 20 through tt-dq's BPF and LPF leaves about 21 degrees
    (the model reproduces it), and the complementary sensitivity peaks near 2.9."""
    est = make_oracle_estimator("tt-dq", WEN_MODEL, T_WEN)
    w = np.geomspace(1.0, 0.999 * math.pi / T_WEN, 80000)
    L = _pll_loop(est, w, w_o=2 * math.pi * 20)
    pm, _ = _margin(L, w, 2)
    assert 19.0 < pm < 23.0
    assert np.abs(L / (1 + L)).max() > 2.5
    L_new = _pll_loop(est, w)
    assert np.abs(L_new / (1 + L_new)).max() < 1.45


@pytest.mark.parametrize("name", ["tt-dq", "sfhf", "tt-ab"])
@pytest.mark.parametrize("f_mod", [8.0, 40.0])
def test_pll_in_loop_chain_matches_the_code(name: str, f_mod: float) -> None:
    """Demodulator on the standstill currents of eq. (7), PLL frozen and its angle wobbled
    by 0.01 rad at ``f_mod`` around its lock point: the error's component at ``f_mod`` is
    ``-G`` times the wobble, with ``G`` the in-loop chain of the design (amplitude within
    0.5 %, phase within 0.2 deg). sfhf locks off the rotor by half the phase of its
    negative sequence through BPF and HPF (Table 3, conventional); there, and only there,
    its error has the slope ``|H_B H_H|`` of the design."""
    est = make_oracle_estimator(name, WEN_MODEL, T_WEN, w_o=0.0)
    theta = 1.1
    centre = theta
    if name == "sfhf":
        h_n = _freqz(est.bpf_z, np.array([-W_H]), T_WEN)[0]  # type: ignore[attr-defined]
        h_n = h_n * _freqz(est.hpf_z, np.array([-2 * W_H]), T_WEN)[0]  # type: ignore[attr-defined]
        centre = theta + float(np.angle(h_n)) / 2
    I_p, I_n = est.I_p, est.I_n  # type: ignore[attr-defined]
    W = 2 * math.pi * f_mod
    n = int(round(12 / f_mod / T_WEN))  # 12 periods of the wobble
    t = np.arange(n) * T_WEN
    wob = 0.01 * np.sin(W * t)
    errs = np.empty(n)
    for k in range(n):
        est.pll.theta_hat = centre + wob[k]  # type: ignore[attr-defined]
        tk = k * T_WEN
        z = I_p * np.exp(1j * (W_H * tk - math.pi / 2)) + I_n * np.exp(
            1j * (-W_H * tk + 2 * theta + math.pi / 2)
        )
        est.update(EstimatorInput(k, z.real, z.imag, 0.0))
        errs[k] = est.err
    sl = slice(n // 3, n)  # after the filters' transients
    X = np.column_stack([np.sin(W * t[sl]), np.cos(W * t[sl]), np.ones(n - n // 3)])
    c = np.linalg.lstsq(X, errs[sl], rcond=None)[0]
    measured = complex(c[0], c[1]) / 0.01  # err = Im(... e^{jWt}) read as sin + j cos
    G = in_loop_response(
        est.IN_LOOP,  # type: ignore[attr-defined]
        T_WEN,
        W_H,
        est.filters_z,  # type: ignore[attr-defined]
        np.array([W]),
    )[0]
    assert abs(measured) == pytest.approx(abs(G), rel=0.005)
    assert math.degrees(abs(np.angle(-measured / G))) < 0.2
    assert abs(c[2]) < 1e-4  # at the lock point: no steady error


def test_pll_options_override_the_design() -> None:
    est = make_oracle_estimator("tt-dq", WEN_MODEL, T_WEN, w_o=100.0)
    assert est.w_o == 100.0 and est.pll.k_p == 200.0  # type: ignore[attr-defined]
    est50 = make_oracle_estimator("tt-dq", WEN_MODEL, T_WEN, pm_deg=50.0)
    assert est50.gains()["pm_deg"] == pytest.approx(50.0, abs=0.05)
    assert est50.w_o < make_oracle_estimator("tt-dq", WEN_MODEL, T_WEN).w_o  # type: ignore[attr-defined]
    with pytest.raises(ValueError):
        make_oracle_estimator("tt-dq", WEN_MODEL, T_WEN, w_o=-1.0)


# ------------------------------------------------------------------------ gains() complete

CONTROLLER_KEYS = {
    "T_s",
    "alpha_c",
    "k_p_d",
    "k_i_d",
    "k_t_d",
    "k_p_q",
    "k_i_q",
    "k_t_q",
    "alpha_s",
    "k_p_w",
    "k_i_w",
    "k_t_w",
    "w_f",
    "speed_pm_deg",
    "delay_periods",
    "i_max",
    "tau_max",
    "raw_current_feedback",
    "comp.dead_time",
    "comp.t_dead",
    "comp.i_band",
    "comp.cross_saturation",
    "comp.offset_calibration",
    "comp.offset_periods",
}
ROTATING_KEYS = {"w_o", "k_p", "k_i", "pm_deg", "pm_target_deg", "w_c", "lpf_corner", "w_h", "V_h"}
SQUARE_KEYS = {"a", "K_1", "K_2", "K_3", "pm_deg", "pm_target_deg", "w_c", "delay_comp_periods"}


@pytest.mark.parametrize("name", ESTIMATOR_NAMES)
def test_controller_gains_are_complete(name: str) -> None:
    """Every estimator reports its gains; the controller's list has every loop, and the
    numbers are the ones in use (not recomputed copies that could drift)."""
    p = WEN if injection_family(name) != "square" else preset("xue2022")
    ctrl = Controller(ControllerPars(motor=motor_model(p), T_s=p.T_s, estimator=name))
    g = ctrl.gains()
    assert set(g) >= CONTROLLER_KEYS
    assert all(isinstance(v, float) and math.isfinite(v) for v in g.values())
    assert g["k_p_d"] == ctrl.pi_d.k_p and g["k_i_q"] == ctrl.pi_q.k_i
    assert g["alpha_c"] == ctrl.pars.alpha_c and g["w_f"] == ctrl.w_f
    assert g["alpha_s"] == ctrl.alpha_s and g["k_p_w"] == ctrl.pi_w.k_p
    est_keys = {k.removeprefix("estimator.") for k in g if k.startswith("estimator.")}
    fam = injection_family(name)
    # a hybrid reports its injection estimator's gains, the band and the flux observer's
    inj: Any = ctrl.estimator
    if name.startswith("hybrid-"):
        inj = inj.hf
        assert {"band.w_lo", "band.w_hi", "observer.alpha_o", "observer.k_p"} <= est_keys
        assert g["estimator.observer.k_p"] == ctrl.estimator.observer.k_p  # type: ignore[attr-defined]
    if fam == "rotating":
        assert est_keys >= ROTATING_KEYS
        assert g["estimator.k_p"] == inj.pll.k_p
    elif fam == "square":
        assert est_keys >= SQUARE_KEYS
        assert g["estimator.a"] == inj.observer.a
    else:
        assert est_keys == set()
    # countermeasures reported when switched on
    cp = CompensationPars(dead_time=True, t_dead=2e-6, offset_calibration=True, adc_lsb=5e-3)
    ctrl2 = Controller(
        ControllerPars(motor=motor_model(p), T_s=p.T_s, estimator=name, compensation=cp)
    )
    g2 = ctrl2.gains()
    assert g2["comp.dead_time"] == 1.0 and g2["comp.t_dead"] == 2e-6
    assert g2["comp.offset_periods"] >= 1.0


# ------------------------------------------------------------------------------ speed loop


@pytest.mark.parametrize("name", ["tt-dq", "tt-ab", "self-demod", "epf"])
@pytest.mark.parametrize("w_mod", [20.0, 60.0])
def test_speed_response_matches_the_code(name: str, w_mod: float) -> None:
    """The PLL's speed estimate on eq. (7) currents whose angle carries a speed wobble of
    0.5 rad/s at ``w_mod``: amplitude within 2 %, phase within 1.5 degrees of
    ``speed_response`` (the design model of the speed loop)."""
    est = make_oracle_estimator(name, WEN_MODEL, T_WEN)
    th0 = 1.1
    est.reset(th0)
    I_p, I_n = est.I_p, est.I_n  # type: ignore[attr-defined]
    amp = 0.5
    n = int(round(14 * 2 * math.pi / w_mod / T_WEN))
    t = np.arange(n) * T_WEN
    theta = th0 + amp * np.sin(w_mod * t) / w_mod
    wh = np.empty(n)
    for k in range(n):
        z = I_p * np.exp(1j * (W_H * t[k] - math.pi / 2)) + I_n * np.exp(
            1j * (-W_H * t[k] + 2 * theta[k] + math.pi / 2)
        )
        est.update(EstimatorInput(k, z.real, z.imag, 0.0))
        wh[k] = est.w_hat
    sl = slice(n // 2, n)
    X = np.column_stack([np.cos(w_mod * t[sl]), -np.sin(w_mod * t[sl]), np.ones(n - n // 2)])
    c = np.linalg.lstsq(X, wh[sl], rcond=None)[0]
    measured = complex(c[0], c[1]) / amp
    E = est.speed_response(np.array([w_mod]))[0]  # type: ignore[attr-defined]
    assert abs(measured) == pytest.approx(abs(E), rel=0.02)
    assert math.degrees(abs(np.angle(measured / E))) < 1.5


def test_speed_loop_keeps_its_margin_with_the_estimator() -> None:
    """Speed loop (module docstring of controller._controller): with an exact speed the
    target 2 pi 5 and w_f = 4 alpha_s give 44 degrees (Wen, 10 kHz); tt-dq's PLL would take
    that to 3 degrees, so its bandwidth is lowered until 30 degrees are left (3.0 Hz);
    sfhf and tt-ab lose less; the sensored and the square-wave drives keep exactly the
    old gains (their traces do not change)."""
    from controller._controller import SPEED_PM_MIN_DEG, speed_loop_margin

    a_t = 2 * math.pi * 5
    a_c = 2 * math.pi * 100
    assert speed_loop_margin(a_t, a_c, 4 * a_t, T_WEN, None)[0] == pytest.approx(44.1, abs=0.1)
    want = {"tt-dq": 18.76, "sfhf": 30.74, "tt-ab": 27.52}
    for name, a_s in want.items():
        c = Controller(ControllerPars(motor=WEN_MODEL, T_s=T_WEN, estimator=name))
        resp = c.estimator.speed_response  # type: ignore[attr-defined]
        assert speed_loop_margin(a_t, a_c, 4 * a_t, T_WEN, resp)[0] < SPEED_PM_MIN_DEG
        assert c.gains()["speed_pm_deg"] == pytest.approx(SPEED_PM_MIN_DEG, abs=0.05)
        assert c.alpha_s == pytest.approx(a_s, abs=0.01) and c.w_f == 4 * c.alpha_s
    tt = Controller(ControllerPars(motor=WEN_MODEL, T_s=T_WEN, estimator="tt-dq"))
    resp = tt.estimator.speed_response  # type: ignore[attr-defined]
    assert speed_loop_margin(a_t, a_c, 4 * a_t, T_WEN, resp)[0] < 5.0
    for p, name in ((WEN, "sensored"), (preset("xue2022"), "square-wave")):
        c = Controller(ControllerPars(motor=motor_model(p), T_s=p.T_s, estimator=name))
        a_s = min(2 * math.pi * 5, 2 * math.pi / (20 * p.T_s) / 10)
        assert (c.alpha_s, c.w_f) == (a_s, 4 * a_s)
    # given values are used as given
    c = Controller(
        ControllerPars(motor=WEN_MODEL, T_s=T_WEN, estimator="tt-dq", alpha_s=20.0, w_f=90.0)
    )
    assert (c.alpha_s, c.w_f) == (20.0, 90.0)


def test_designed_observer_keeps_lock_when_the_inertia_is_half() -> None:
    """Issue 15's case: xue-fig15 (3 N m step at 100 rpm) with the controller believing
    half the true inertia. The wrong inertia makes the torque feed-forward twice too large,
    a disturbance the loop has to reject (the loop itself does not depend on J). The
    designed pole (50.8 rad/s) keeps the error below 10 degrees; the old 0.1 / (3.5 T_s)
    (28.6 rad/s) loses the rotor angle."""
    import importlib.resources
    import tomllib

    from bench.nodes._loops import run_inprocess
    from bench.scenarios._schema import parse_scenario
    from bench.wire._codec import Codec
    from tests.test_parameter_mismatch import trace

    text = (importlib.resources.files("bench.scenarios") / "xue-fig15.toml").read_text()
    worst = []
    for a in (None, 0.1 / (3.5 * T_XUE)):
        d = tomllib.loads(text)
        d["controller_model"] = {"J": 0.5}
        if a is not None:
            d["estimator_options"] = {"a": a}
        scn = parse_scenario(d, "xue-fig15.toml")
        tab = trace(run_inprocess(scn, "square-wave", Codec()), scn)
        worst.append(float(np.abs(tab["theta_err_deg"][tab["t"] >= 1.0]).max()))
    assert worst[0] < 10.0
    assert worst[1] > 90.0
