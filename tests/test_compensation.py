"""The drive's countermeasures against closed forms (controller._compensation).

- dead time: the controller's own model equals the plant's (``plant_rt``'s
  ``dead_time_error``; only a test may import both), the device drops equal
  a brute-force centre-aligned leg, the smoothing laws equal the mean sign
  over the ripple, the controller's duties carry exactly the feed-forward,
  and on a plant with dead time the compensation gives back the accuracy;
- cross-saturation: the offset is the principal axis of the inductance
  matrix, the estimators lock there on synthetic HF currents, and the
  controller corrects by it;
- offset calibration: the count ``N`` of the closed form, and a known
  offset removed within ``3 sigma / sqrt(N)`` plus half an ADC step.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from controller import (
    MODE_ALIGN,
    MODE_RUN,
    CompensationPars,
    Controller,
    ControllerPars,
    EstimatorInput,
    Measurement,
)
from controller._compensation import (
    cross_saturation_offset,
    dead_time_voltage,
    offset_periods,
    smooth_sign,
)
from plant_rt import InverterPars, preset
from plant_rt._inverter import dead_time_error
from tests.loop_helpers import RPM, make_loop, motor_model, run
from tests.oracle import OracleController
from tests.oracle.blocks import OracleDeadTimeCompensator
from tests.oracle.estimators import OracleSquareWaveEstimator, make_oracle_estimator
from tests.test_controller_square_wave import MOTOR as XUE_MODEL

WEN = preset("wen2023")
T_WEN = WEN.T_s

# ------------------------------------------------------------------------------ dead time


@pytest.mark.parametrize("u_dc", [300.0, 540.0])
@pytest.mark.parametrize("i_x", [-4.0, -0.3, 0.3, 4.0])
def test_dead_time_model_equals_the_plants(u_dc: float, i_x: float) -> None:
    """Outside the smoothing band the feed-forward is the plant's own average error,
    ``-t_dead / T_s * u_dc * sign(i)``, and the duty moves by ``t_dead / T_s * sign(i)``."""
    t_dead = 2e-6
    plant = dead_time_error(i_x, u_dc, t_dead, T_WEN)
    assert plant == pytest.approx(-math.copysign(t_dead / T_WEN * u_dc, i_x), rel=1e-12)
    assert dead_time_voltage(i_x, u_dc, 0.5, t_dead, T_WEN) == pytest.approx(plant, rel=1e-12)
    comp = OracleDeadTimeCompensator(T_WEN, t_dead, 0.0, 0.0, i_band=0.1, sine=False)
    assert comp.voltage(i_x, u_dc, 0.5) == pytest.approx(plant, rel=1e-12)
    d = comp.duties(0.5, 0.5, 0.5, i_x, -i_x, 0.0, u_dc)
    assert d[0] - 0.5 == pytest.approx(math.copysign(t_dead / T_WEN, i_x), rel=1e-12)
    assert d[1] - 0.5 == pytest.approx(-math.copysign(t_dead / T_WEN, i_x), rel=1e-12)
    assert d[2] == 0.5  # zero current: nothing to compensate
    assert (
        dead_time_voltage(0.0, u_dc, 0.5, t_dead, T_WEN)
        == 0.0
        == dead_time_error(0.0, u_dc, t_dead, T_WEN)
    )


def _leg_mean_voltage(
    d: float, i_x: float, u_dc: float, t_dead: float, v_ce: float, v_f: float
) -> float:
    """Mean pole voltage of one centre-aligned period, brute force on a fine time grid.

    Gates: the upper switch is commanded on for ``|t - T/2| < d T / 2``; each turn-on
    is delayed by ``t_dead`` (both off meanwhile). Conduction: ``i > 0`` upper
    transistor (``u_dc - v_ce``) or lower diode (``-v_f``); ``i < 0`` upper diode
    (``u_dc + v_f``) or lower transistor (``+v_ce``)."""
    n = 200_000
    t = (np.arange(n) + 0.5) / n * T_WEN
    half = 0.5 * d * T_WEN
    mid = 0.5 * T_WEN
    up_cmd = np.abs(t - mid) < half
    up = up_cmd & (t >= mid - half + t_dead)  # upper turn-on delayed
    lo = ~up_cmd & ((t < mid - half) | (t >= mid + half + t_dead))  # lower turn-on delayed
    if i_x > 0:
        v = np.where(up, u_dc - v_ce, -v_f)  # lower transistor or its diode: -v_f
        v = np.where(lo, -v_f, v)
    else:
        v = np.where(up, u_dc + v_f, np.where(lo, v_ce, u_dc + v_f))
    return float(v.mean())


@pytest.mark.parametrize("d", [0.2, 0.5, 0.85])
@pytest.mark.parametrize("i_x", [-2.0, 2.0])
def test_dead_time_and_device_drops_against_a_switching_leg(d: float, i_x: float) -> None:
    """The error of the docstring (dead time and drops) is what a switching leg does."""
    u_dc, t_dead, v_ce, v_f = 540.0, 2e-6, 1.6, 1.2
    err = _leg_mean_voltage(d, i_x, u_dc, t_dead, v_ce, v_f) - d * u_dc
    assert dead_time_voltage(i_x, u_dc, d, t_dead, T_WEN, v_ce, v_f) == pytest.approx(err, abs=0.02)
    comp = OracleDeadTimeCompensator(T_WEN, t_dead, v_ce, v_f, i_band=0.0, sine=False)
    assert comp.voltage(i_x, u_dc, d) == pytest.approx(err, abs=0.02)


@pytest.mark.parametrize("i_f", [-0.3, -0.05, 0.0, 0.02, 0.1, 0.25])
def test_smoothing_is_the_mean_sign_over_the_ripple(i_f: float) -> None:
    """Sinusoid of amplitude I_h: (2/pi) asin(i/I_h); triangle: i/I_h; +-1 outside."""
    I_h = 0.2
    ph = (np.arange(100_000) + 0.5) / 100_000 * 2 * math.pi
    sine = float(np.mean(np.sign(i_f + I_h * np.sin(ph))))
    tri = float(np.mean(np.sign(i_f + I_h * (2 / math.pi) * np.arcsin(np.sin(ph)))))
    assert smooth_sign(i_f, I_h, sine=True) == pytest.approx(sine, abs=1e-4)
    assert smooth_sign(i_f, I_h, sine=False) == pytest.approx(tri, abs=1e-4)
    assert smooth_sign(i_f, 0.0, sine=False) == (0.0 if i_f == 0 else math.copysign(1.0, i_f))


def test_controller_adds_the_feedforward_to_its_duties() -> None:
    """Sensored FOC in current control: the duties with compensation are the duties
    without plus ``t_dead / T_s * sign(i_x)`` of each phase of the reference (hard sign
    without injection), the reference rotated by the angle of the next period's mid-point."""
    theta, w_e = 0.4, 50.0
    cp = CompensationPars(dead_time=True, t_dead=2e-6)
    outs = []
    for comp in (CompensationPars(), cp):
        ctrl = Controller(
            ControllerPars(
                motor=motor_model(WEN), T_s=T_WEN, estimator="sensored", compensation=comp
            )
        )
        ctrl.set_enable(True)
        ctrl.set_current_ref((-0.5, 3.0))
        outs.append(ctrl.step(Measurement(0, 0.3, -0.1, -0.2, 540.0, theta, w_e)))
    th_u = theta + 1.5 * T_WEN * w_e
    i_ab = complex(-0.5, 3.0) * complex(math.cos(th_u), math.sin(th_u))
    i_abc = [i_ab.real, -0.5 * i_ab.real + 0.5 * math.sqrt(3) * i_ab.imag]
    i_abc.append(-i_abc[0] - i_abc[1])
    for d0, d1, i_x in zip(
        (outs[0].d_a, outs[0].d_b, outs[0].d_c),
        (outs[1].d_a, outs[1].d_b, outs[1].d_c),
        i_abc,
        strict=True,
    ):
        assert d1 - d0 == pytest.approx(math.copysign(2e-6 / T_WEN, i_x), rel=1e-9)


def test_rotating_estimator_predicts_its_hf_current() -> None:
    """hf_current_next is eq. (7) at t = (k + 1.5) T_s: one step later the sampled HF
    current (the model at (k + 1) T_s) and two steps later (k + 2) bracket it."""
    est = make_oracle_estimator("tt-dq", motor_model(WEN), T_WEN, w_o=0.0)
    theta = 0.9
    est.reset(theta)
    w_h = 2 * math.pi * 500.0
    est.update(EstimatorInput(7, 0.0, 0.0, 0.0))
    h = complex(*est.hf_current_next())  # type: ignore[attr-defined]
    t = 8.5 * T_WEN
    want = est.I_p * np.exp(1j * (w_h * t - math.pi / 2)) + est.I_n * np.exp(  # type: ignore[attr-defined]
        1j * (-w_h * t + 2 * theta + math.pi / 2)
    )
    assert abs(h - want) < 1e-12


@pytest.mark.slow
def test_dead_time_compensation_restores_tt_dq_on_a_plant_with_dead_time() -> None:
    """tt-dq at 100 rpm on the average-model plant with 2 us of dead time: without
    compensation the HF response is distorted (the dead-time error follows the HF
    current's sign at no load) and the mean error grows from 0.4 to 4 degrees (10 with
    the old 2 pi 20 PLL and 5 Hz speed loop); with the feed-forward it comes back within
    a degree of the ideal plant's (0.9)."""
    P2 = dataclasses.replace(WEN, inverter=InverterPars(u_dc=540.0, t_dead=2e-6))
    res = {}
    for label, pre, comp in (
        ("ideal", WEN, CompensationPars()),
        ("off", P2, CompensationPars()),
        ("on", P2, CompensationPars(dead_time=True, t_dead=2e-6)),
    ):
        plant, ctrl = make_loop(
            pre, "tt-dq", theta_e0=1.3, startup=False, theta0=1.3, compensation=comp
        )
        tr = run(plant, ctrl, 12000, w_m_ref=lambda t: min(t / 0.3, 1.0) * 100.0 * RPM)
        res[label] = float(np.mean(np.abs(np.degrees(tr.err[-4000:]))))
    assert res["off"] > res["ideal"] + 3.0
    assert res["on"] < res["ideal"] + 1.0


# ------------------------------------------------------------------------ cross-saturation


@pytest.mark.parametrize("i_q", [-8.0, 3.0, 10.0])
def test_cross_saturation_offset_is_the_principal_axis(i_q: float) -> None:
    """The angle of the smaller eigenvalue's eigenvector of [[L_d, L_dq], [L_dq, L_q]]."""
    L_d, L_q, k_dq = 3.53e-3, 7.48e-3, -1.5e-4
    L_dq = k_dq * i_q
    vals, vecs = np.linalg.eigh(np.array([[L_d, L_dq], [L_dq, L_q]]))
    v = vecs[:, int(np.argmin(vals))]
    axis = math.atan2(v[1], v[0])
    axis = (axis + math.pi / 2) % math.pi - math.pi / 2  # an axis: modulo pi
    delta = cross_saturation_offset(k_dq, i_q, L_d, L_q)
    assert delta == pytest.approx(axis, abs=1e-12)
    assert delta == pytest.approx(-0.5 * math.atan(2 * L_dq / (L_q - L_d)), abs=1e-15)


def _L_inv_ab(theta: float, L_d: float, L_q: float, L_dq: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    R = np.array([[c, -s], [s, c]])
    return R @ np.linalg.inv(np.array([[L_d, L_dq], [L_dq, L_q]])) @ R.T


@pytest.mark.parametrize("name", ["square-wave", "tt-dq"])
def test_estimators_lock_at_the_cross_saturation_offset(name: str) -> None:
    """On synthetic HF currents from a cross-coupled inductance, at standstill, the
    estimate settles at ``theta_e + delta`` with delta of the closed form."""
    theta = 0.8
    if name == "square-wave":
        model, T_s, n = XUE_MODEL, 1e-3, 3000
        est = OracleSquareWaveEstimator(model, T_s)
    else:
        model, T_s, n = motor_model(WEN), T_WEN, 20000
        est = make_oracle_estimator(name, model, T_s)  # type: ignore[assignment]
    k_dq = -0.15 * (model.L_q - model.L_d) / 8.0  # L_dq = -15 % of L_q - L_d at 8 A
    i_q = 8.0
    delta = cross_saturation_offset(k_dq, i_q, model.L_d, model.L_q)
    G = _L_inv_ab(theta, model.L_d, model.L_q, k_dq * i_q)
    est.reset(theta - 0.3)
    psi = np.zeros(2)
    u = np.zeros(2)
    th = []
    for k in range(n):
        i = G @ psi
        est.update(EstimatorInput(k, float(i[0]), float(i[1]), 0.0))
        th.append(est.theta_hat)
        psi = psi + T_s * u  # the voltage of the period that ends at the next sample
        u = np.array(est.injection())
    e = np.array(th[-200:]) - theta
    e = (e + math.pi / 2) % math.pi - math.pi / 2
    assert abs(delta) > math.radians(3.0)  # a real offset
    assert float(np.mean(e)) == pytest.approx(delta, abs=math.radians(0.3))


def test_controller_corrects_the_angle_by_the_offset() -> None:
    """With ``cross_saturation`` on, the angle the controller uses and reports is the
    estimator's minus the offset at the q-current reference in force."""
    model = dataclasses.replace(motor_model(WEN), k_dq=-2e-3)
    cp = CompensationPars(cross_saturation=True)
    ctrl = Controller(
        ControllerPars(motor=model, T_s=T_WEN, estimator="tt-dq", startup=False, compensation=cp)
    )
    ctrl.set_enable(True)
    ctrl.set_current_ref((0.0, 4.0))
    ctrl.step(Measurement(0, 0.0, 0.0, 0.0, 540.0))
    out = ctrl.step(Measurement(1, 0.0, 0.0, 0.0, 540.0))
    delta = cross_saturation_offset(-2e-3, 4.0, model.L_d, model.L_q)
    assert abs(delta) > 0.05
    assert out.theta_hat == pytest.approx(
        (ctrl.estimator.theta_hat - delta) % (2 * math.pi), abs=1e-12
    )
    assert out.mode == MODE_RUN


@pytest.mark.parametrize("weight", [0.0, 0.5, 1.0])
def test_the_hybrid_corrects_its_injection_estimate_only(weight: float) -> None:
    """The offset is the saliency's, so a hybrid (``hybrid-tt-dq``) takes it from the
    controller (``saliency_offset``) and subtracts it from its injection estimate before
    the blend: the controller reports the hybrid's angle as it is, which is the
    injection's corrected angle below the band, the observer's alone above it (no
    offset), and the blend of the two in between; the observer, slaved below the band,
    follows the corrected angle."""
    model = dataclasses.replace(motor_model(WEN), k_dq=-2e-3)
    cp = CompensationPars(cross_saturation=True)
    ctrl = OracleController(  # the Python step: the test sets and reads the estimator's objects
        ControllerPars(
            motor=model, T_s=T_WEN, estimator="hybrid-tt-dq", startup=False, compensation=cp
        )
    )
    est = ctrl.estimator
    ctrl.set_enable(True)
    ctrl.set_current_ref((0.0, 4.0))
    ctrl.step(Measurement(0, 0.1, -0.05, -0.05, 540.0))
    est.weight = weight  # type: ignore[attr-defined]
    out = ctrl.step(Measurement(1, 0.2, -0.1, -0.1, 540.0))
    delta = cross_saturation_offset(-2e-3, 4.0, model.L_d, model.L_q)
    assert est.saliency_offset == delta  # type: ignore[attr-defined]
    assert out.theta_hat == pytest.approx(est.theta_hat % (2 * math.pi), abs=1e-12)
    th_hf = est.hf.theta_hat - delta  # type: ignore[attr-defined]
    th_obs = est.observer.theta_hat  # type: ignore[attr-defined]
    d = (th_obs - th_hf + math.pi) % (2 * math.pi) - math.pi
    want = th_hf + weight * d
    assert (out.theta_hat - want + math.pi) % (2 * math.pi) - math.pi == pytest.approx(
        0.0, abs=1e-12
    )
    if weight == 0.0:
        assert th_obs == pytest.approx(th_hf % (2 * math.pi), abs=1e-12)
    if weight == 1.0:
        # the injection tracker, slaved, waits where it will lock: the output plus the
        # offset, one period ahead
        pll = est.hf.pll  # type: ignore[attr-defined]
        ahead = est.theta_hat + delta + T_WEN * est.observer.w_hat  # type: ignore[attr-defined]
        assert (pll.theta_hat - ahead + math.pi) % (2 * math.pi) - math.pi == pytest.approx(
            0.0, abs=1e-12
        )


# ---------------------------------------------------------------------- offset calibration


def test_offset_periods_closed_form() -> None:
    q = 24.0 / 4096  # 12-bit ADC over +-12 A
    sigma = math.sqrt(0.01**2 + q * q / 12)
    n = offset_periods(0.01, q, q / 2)
    assert n == math.ceil((3 * sigma / (q / 2)) ** 2)
    assert 3 * sigma / math.sqrt(n) <= q / 2 < 3 * sigma / math.sqrt(n - 1)
    assert offset_periods(0.0, 0.0, 1e-3) == 1


def test_offset_calibration_removes_a_known_offset() -> None:
    """PWM disabled for N periods, then every sample has the mean subtracted: the offset
    left is below 3 sigma / sqrt(N) + q/2 on each phase, with sigma the noise and q the step."""
    rng = np.random.default_rng(15)
    q = 24.0 / 4096
    noise = 0.01
    offs = (0.12, -0.07, 0.03)
    cp = CompensationPars(offset_calibration=True, current_noise=noise, adc_lsb=q)
    ctrl = OracleController(  # the Python step: the test reads the calibration's object
        ControllerPars(motor=motor_model(WEN), T_s=T_WEN, estimator="sensored", compensation=cp)
    )
    n = ctrl.calibration.n  # type: ignore[union-attr]
    sigma = math.sqrt(noise**2 + q * q / 12)
    assert n == offset_periods(noise, q, q / 2) > 1
    ctrl.set_enable(True)

    def sample(k: int, i: tuple[float, float, float]) -> Measurement:
        v = [
            q * round((o + x + noise * rng.standard_normal()) / q)
            for o, x in zip(offs, i, strict=True)
        ]
        return Measurement(k, v[0], v[1], v[2], 540.0, 0.0, 0.0)

    for k in range(n):
        out = ctrl.step(sample(k, (0.0, 0.0, 0.0)))
        assert not out.enable and out.mode == MODE_ALIGN  # PWM off while calibrating
    cal = ctrl.calibration
    assert cal is not None and cal.done
    bound = 3 * sigma / math.sqrt(n) + q / 2
    for got, want in zip((cal.o_a, cal.o_b, cal.o_c), offs, strict=True):
        assert abs(got - want) < bound
    # afterwards the controller runs and sees the current without the offsets
    out = ctrl.step(Measurement(n, 1.0 + offs[0], -0.5 + offs[1], -0.5 + offs[2], 540.0, 0.0, 0.0))
    assert out.enable and out.mode == MODE_RUN
    assert ctrl.estimator.i_alpha_f == pytest.approx(1.0, abs=bound)
    # a second start calibrates again
    ctrl.set_enable(False)
    ctrl.set_enable(True)
    assert not ctrl.step(sample(0, (0.0, 0.0, 0.0))).enable


def test_everything_is_off_by_default() -> None:
    ctrl = Controller(ControllerPars(motor=motor_model(WEN), T_s=T_WEN, estimator="tt-dq"))
    assert ctrl.dead_time is None and ctrl.calibration is None and not ctrl.cross_sat
    assert not ctrl.raw_feedback
    g = ctrl.gains()
    assert g["comp.dead_time"] == g["comp.offset_calibration"] == g["comp.cross_saturation"] == 0.0
