"""Rotating HF injection and the five demodulators on synthetic currents (Wen Secs. 2-4).

The synthetic currents are eq. (7)/(18) with the derived sign of the negative
sequence, ``I_n = V_h (L_q - L_d) / (2 w_h L_d L_q) > 0``, sampled at
``t = k T_s``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from controller import EstimatorInput, hf_amplitudes
from plant_rt import preset
from tests.loop_helpers import motor_model
from tests.oracle.estimators import OracleTTDQEstimator, make_oracle_estimator

P = preset("wen2023")
T_S = P.T_s
MODEL = motor_model(P)
W_H = 2.0 * math.pi * 500.0


def _h(z: tuple[tuple[float, ...], tuple[float, ...]], w: float) -> complex:
    """Discrete frequency response at signed angular frequency ``w`` (rad/s)."""
    _, h = signal.freqz(*z, worN=[abs(w) * T_S])
    return complex(h[0]) if w >= 0 else complex(h[0]).conjugate()


def _currents(k: int, theta: float, I_p: float, I_n: float, phi_p: float, phi_n: float) -> complex:
    """Eq. (18) at ``t = k T_s`` plus a fundamental current of 1 - 0.5j A."""
    t = k * T_S
    return (
        I_p * np.exp(1j * (W_H * t + phi_p - math.pi / 2))
        + I_n * np.exp(1j * (-W_H * t + 2 * theta + phi_n + math.pi / 2))
        + (1.0 - 0.5j)
    )


def test_injection_response_of_rotor_frame_inductances_is_eq4_with_derived_sign() -> None:
    """Integrate eq. (2) exactly for the piecewise-constant injection the estimator
    commands (eq. (3) at the mid-point of each period): the sampled HF current is
    eq. (4) at ``t = k T_s`` with ``I_p``, ``I_n`` of :func:`hf_amplitudes`,
    i.e. ``I_n`` has the sign of ``L_q - L_d`` (eq. (6) as printed has the other)."""
    est = make_oracle_estimator("tt-dq", MODEL, T_S)
    theta = 0.4
    n = 400
    i_dq = np.zeros(n, complex)
    acc = 0j
    for k in range(n):
        i_dq[k] = acc
        est._k = k  # type: ignore[attr-defined]  # injection() for period k + 1
        u_al, u_be = est.injection()
        u_dq = complex(u_al, u_be) * np.exp(-1j * theta)
        # period k + 1 spans [(k+1) T, (k+2) T]; the sample at k + 2 sees it
        acc_next = acc + T_S * complex(u_dq.real / MODEL.L_d, u_dq.imag / MODEL.L_q)
        acc = acc_next
    # sample k holds the sum of the periods 1..k-1 -> shift by one
    i_s = np.concatenate(([0j], i_dq[:-1]))[200:]
    i_s = i_s - i_s.mean()  # 200 samples = 10 HF periods: the constant of integration
    I_p, I_n = hf_amplitudes(MODEL, 50.0, W_H, T_S)
    assert I_n > 0.0
    t = np.arange(200, n) * T_S
    want = I_p * np.exp(1j * (W_H * t - theta - math.pi / 2)) + I_n * np.exp(
        1j * (-W_H * t + theta + math.pi / 2)
    )
    assert np.abs(i_s - want).max() < 1e-6 * I_p
    assert I_n == pytest.approx(0.0426, rel=0.01)  # tens of mA at V_h = 50 V


@pytest.mark.parametrize("name", ["tt-dq", "tt-ab", "sfhf", "self-demod", "epf"])
@pytest.mark.parametrize(
    ("dtheta", "phi_p", "phi_n"), [(0.3, 0.0, 0.0), (-0.5, 0.2, -0.2), (1.0, 0.1, 0.05)]
)
def test_demodulator_returns_closed_form(
    name: str, dtheta: float, phi_p: float, phi_n: float
) -> None:
    """Observer frozen at ``theta_hat = theta - dtheta``; the error signal, averaged
    over one HF period in steady state, equals the closed form within 1 %:

    - ``tt-dq`` (eq. 34) and ``tt-ab`` (eq. 28): ``I_p I_n |H_B|^2 sin(2 dtheta + phi_p + phi_n)``
      (the BPF phases at +-w_h cancel), and so do ``self-demod`` ([27], the product of the
      separated sequences) and ``epf`` ([25], the product of the two demodulated ones);
    - ``sfhf`` (eq. 9): ``I_n |H_B H_H| sin(2 dtheta + phi_n + arg H_B(-w_h) + arg H_H(-2 w_h))``
      (the negative sequence keeps the filter phases: Table 3, conventional).
    """
    est = make_oracle_estimator(name, MODEL, T_S, w_o=0.0)
    theta = 1.1
    est.reset(theta - dtheta)
    I_p, I_n = est.I_p, est.I_n  # type: ignore[attr-defined]
    fs = []
    for k in range(3000):
        z = _currents(k, theta, I_p, I_n, phi_p, phi_n)
        est.update(EstimatorInput(k, z.real, z.imag, 0.0))
        fs.append(est.f)  # type: ignore[attr-defined]
    f = float(np.mean(fs[-20:]))
    h_b = _h(est.bpf_z, W_H)  # type: ignore[attr-defined]
    if name == "sfhf":
        h_n = _h(est.bpf_z, -W_H) * _h(est.hpf_z, -2 * W_H)  # type: ignore[attr-defined]
        amp = I_n * abs(h_n)
        want = amp * math.sin(2 * dtheta + phi_n + np.angle(h_n))
    else:
        amp = I_p * I_n * abs(h_b) ** 2
        want = amp * math.sin(2 * dtheta + phi_p + phi_n)
    assert abs(f - want) < 0.01 * amp
    # the fundamental passes to the current loop with the HF removed
    assert est.i_alpha_f == pytest.approx(1.0, abs=0.01 * I_p + 1e-3)
    assert est.i_beta_f == pytest.approx(-0.5, abs=0.01 * I_p + 1e-3)


@pytest.mark.parametrize("name", ["tt-dq", "tt-ab", "sfhf", "self-demod", "epf"])
@pytest.mark.parametrize("err0_deg", [30.0, 80.0, 100.0, -60.0])
def test_observer_locks_at_zero_error_not_ninety(name: str, err0_deg: float) -> None:
    """Observer running on eq. (7) at standstill: from 30, 80, 100 and -60 degrees it
    settles at ``theta`` or ``theta + pi`` (the saliency repeats every pi), never at
    the other equilibrium of ``sin 2 dtheta`` (90 degrees). ``sfhf`` settles at the
    offset of its uncompensated negative-sequence filter phase,
    ``-(arg H_B(-w_h) + arg H_H(-2 w_h))/2`` (Table 3, conventional, ``w_e = 0``)."""
    est = make_oracle_estimator(name, MODEL, T_S)
    theta = 2.0
    est.reset(theta - math.radians(err0_deg))
    I_p, I_n = est.I_p, est.I_n  # type: ignore[attr-defined]
    es = []
    wis = []
    for k in range(4000):
        z = _currents(k, theta, I_p, I_n, 0.0, 0.0)
        est.update(EstimatorInput(k, z.real, z.imag, 0.0))
        es.append((theta - est.theta_hat + math.pi / 2) % math.pi - math.pi / 2)  # modulo pi
        wis.append(est.pll.w_i)  # type: ignore[attr-defined]
    # mean over the last HF period: tt-ab's PLL (no filter in its loop, crossover at the
    # LPF corner) passes about 0.8 degrees of the demodulation ripple at 2 w_h
    e = float(np.mean(es[-20:]))
    want = 0.0
    if name == "sfhf":
        h_n = _h(est.bpf_z, -W_H) * _h(est.hpf_z, -2 * W_H)  # type: ignore[attr-defined]
        want = -float(np.angle(h_n)) / 2
    assert math.degrees(abs(e - want)) < 0.5
    assert abs(float(np.mean(wis[-20:]))) < 0.5  # integral part: no drift


def test_printed_sign_of_eq6_would_lock_at_ninety_degrees() -> None:
    """Counter-check: feeding currents with the printed sign of eq. (6) (``I_n < 0``)
    makes the same observer settle 90 degrees off, so the lock test above can fail."""
    est = make_oracle_estimator("tt-dq", MODEL, T_S)
    theta = 2.0
    est.reset(theta - math.radians(30.0))
    I_p, I_n = est.I_p, est.I_n  # type: ignore[attr-defined]
    for k in range(4000):
        z = _currents(k, theta, I_p, -I_n, 0.0, 0.0)
        est.update(EstimatorInput(k, z.real, z.imag, 0.0))
    e = (theta - est.theta_hat) % math.pi
    assert math.degrees(e) == pytest.approx(90.0, abs=1.0)


@pytest.mark.parametrize("name", ["tt-dq", "tt-ab", "sfhf", "self-demod", "epf"])
def test_measured_normalisation_is_independent_of_amplitude(name: str) -> None:
    """With ``normalise="measured"`` the error is ``sin(2 dtheta)/2`` whatever the HF
    amplitude (here the currents are 3 times the model's, as for a motor whose
    inductances are a third of the model's); the model normalisation scales with the
    amplitude (9 times for the TT products, 3 times for sfhf). epf within 3 %: its
    product of two low-passed sequences ripples at ``2 w_h`` by half its size (each LPF
    of eq. 13 passes a tenth of the other sequence, ``I_p`` about 5.6 ``I_n``), and the tenth
    of it that its normaliser's LPF passes correlates with the ripple of the error (2.5 %)."""
    dtheta, theta, scale = 0.25, 0.7, 3.0
    errs = {}
    for norm in ("model", "measured"):
        est = make_oracle_estimator(name, MODEL, T_S, w_o=0.0, normalise=norm)
        est.reset(theta - dtheta)
        I_p, I_n = est.I_p, est.I_n  # type: ignore[attr-defined]
        acc = []
        for k in range(3000):
            z = _currents(k, theta, scale * I_p, scale * I_n, 0.0, 0.0)
            est.update(EstimatorInput(k, z.real, z.imag, 0.0))
            acc.append(est.err)
        errs[norm] = float(np.mean(acc[-20:]))
    if name == "sfhf":
        h_n = _h(est.bpf_z, -W_H) * _h(est.hpf_z, -2 * W_H)  # type: ignore[attr-defined]
        want = 0.5 * math.sin(2 * dtheta + np.angle(h_n))
        ratio = scale * abs(h_n)
    else:
        want = 0.5 * math.sin(2 * dtheta)
        ratio = scale**2 * abs(_h(est.bpf_z, W_H)) ** 2  # type: ignore[attr-defined]
    assert errs["measured"] == pytest.approx(want, rel=0.03 if name == "epf" else 0.02)
    assert errs["model"] == pytest.approx(ratio * want, rel=0.02)


def _ttdq_gain_at_speed(rpm: float, tracking: bool) -> tuple[float, float, float]:
    """tt-dq's demodulated error gain ``K``, bias (rad) and the largest HF residual left in
    the fundamental current (A), with the observer frozen at ``theta_e - dtheta`` on the
    synthetic currents of eq. (4) at the electrical speed of ``rpm``."""
    from controller import RotatingInjectionPars

    w = rpm * P.motor.n_p * 2.0 * math.pi / 60.0
    d = math.radians(3.0)
    out = []
    resid = 0.0
    for dth in (-d, d):
        est = OracleTTDQEstimator(MODEL, T_S, RotatingInjectionPars(w_o=0.0, bpf_tracking=tracking))
        I_p, I_n = est.I_p, est.I_n
        acc = []
        for k in range(6000):
            t = k * T_S
            th = w * t
            i_f = 2.0 * np.exp(1j * (th + math.pi / 2))  # 2 A on q
            i = (
                I_p * np.exp(1j * (W_H * t - math.pi / 2))
                + I_n * np.exp(1j * (2 * th - W_H * t + math.pi / 2))
                + i_f
            )
            est.pll.reset(th - dth, w)
            est.update(EstimatorInput(k, i.real, i.imag, 0.0))
            if k > 3000:
                acc.append(est.err)
                resid = max(resid, abs(complex(est.i_alpha_f, est.i_beta_f) - i_f))
        out.append(float(np.mean(acc)))
    g = math.sin(2.0 * d) / 2.0  # err = sin(2 dtheta) / 2 for the exact sequences
    return (out[1] - out[0]) / (2.0 * g), 0.5 * (out[0] + out[1]), resid


@pytest.mark.parametrize("rpm", [-600.0, -300.0, 300.0, 600.0])
def test_tracking_bpf_keeps_the_error_gain_at_speed(rpm: float) -> None:
    """At speed both sequences sit at ``+-(w_h - w_e)`` in the estimated frame (Wen Table
    2). A fixed BPF sees them off centre: the error's gain is ``|H(w_h - w_e)|^2``
    (closed form, the discrete filter) and a residual ``|1 - H|`` of each sequence stays
    in the fundamental current. The tracking BPF (``bpf_tracking``), centred on ``|w_h -
    w_i|``, keeps the gain 1, no bias and no residual."""
    from controller import RotatingInjectionPars

    fixed = OracleTTDQEstimator(MODEL, T_S, RotatingInjectionPars())
    w = rpm * P.motor.n_p * 2.0 * math.pi / 60.0
    h = _h(fixed.bpf_z, W_H - w)
    k_fixed, _, r_fixed = _ttdq_gain_at_speed(rpm, False)
    assert k_fixed == pytest.approx(abs(h) ** 2, rel=0.01)
    assert r_fixed > 0.3 * abs(1.0 - h) * fixed.I_p
    k, bias, resid = _ttdq_gain_at_speed(rpm, True)
    assert k == pytest.approx(1.0, abs=2e-3)
    assert abs(bias) < 1e-3
    assert resid < 0.02 * fixed.I_n


def test_tracking_bpf_at_standstill_is_eq11_and_only_for_tt_dq() -> None:
    """At standstill the tracking BPF is eq. (11)'s shape centred on ``w_h`` (the PLL is
    designed with it, within 0.1 % of the fixed filter's bandwidth); the stationary-frame
    demodulators and a BPF of another form refuse the option."""
    from controller import RotatingInjectionPars
    from controller._filters import BPF_WEN, discretize
    from controller._rotating import pll_design

    est = OracleTTDQEstimator(MODEL, T_S, RotatingInjectionPars(bpf_tracking=True))
    ref = discretize(BPF_WEN[0], (1.0, 628.0, W_H * W_H), T_S, W_H)
    assert np.allclose(est.bpf_z[0], ref[0], rtol=1e-9, atol=1e-15)
    assert np.allclose(est.bpf_z[1], ref[1], rtol=1e-9)
    fixed = OracleTTDQEstimator(MODEL, T_S, RotatingInjectionPars())
    assert est.w_o == pll_design("bpf+lpf", T_S, W_H, est.filters_z, est.pars.pm_deg)[0]
    assert est.filters_z[0] == est.bpf_z != fixed.bpf_z
    assert est.w_o == pytest.approx(fixed.w_o, rel=1e-3)
    for name in ("tt-ab", "sfhf"):
        with pytest.raises(ValueError, match="tt-dq"):
            make_oracle_estimator(name, MODEL, T_S, bpf_tracking=True)
    with pytest.raises(ValueError, match=r"eq\. \(11\)"):
        OracleTTDQEstimator(
            MODEL,
            T_S,
            RotatingInjectionPars(bpf_tracking=True, bpf=((600.0, 0.0), (1.0, 628.0, W_H**2))),
        )
