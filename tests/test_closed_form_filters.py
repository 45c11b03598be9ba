"""Complex frequency response (gain and phase) of the estimators' discrete filters,
measured by running sines through their per-sample ``update``, against closed forms.

Closed form of a bilinear transform pre-warped at ``w_p`` (controller._filters):
``s = K (z - 1)/(z + 1)``, ``K = w_p / tan(w_p T_s / 2)``; on the unit circle
``z = e^{j w T_s}`` this is ``s = j K tan(w T_s / 2)``, so

    H_d(e^{j w T_s}) = H_c(j K tan(w T_s / 2))

evaluated from the continuous prototype's polynomials (Wen eqs. (11)-(13)). It is
exact at ``w = w_p`` and shows the frequency warping elsewhere; ``scipy.signal.freqz``
of the coefficients is a second reference. The pair filters run a space vector:
``(cos, sin)`` of ``+w`` must come out as ``H e^{j w k T}`` and ``(cos, -sin)`` as
``conj(H) e^{-j w k T}``.

Measurement: skip the transient until the slowest pole has decayed below 1e-12
(``n_skip = ln(1e-12) / ln(max |pole|)``), then fit the complex gain by least squares
over >= 1000 samples, so the comparison tolerance is rounding-level (1e-9).
"""

from __future__ import annotations

import cmath
import math

import numpy as np
import pytest
from scipy import signal

from bench.scenarios._setup import motor_model
from controller import BPF_WEN, HPF_WEN, LPF_WEN, EstimatorInput
from controller._filters import lpf_first_order
from controller._rotating import RotatingInjectionPars
from plant_rt import preset
from tests.oracle.blocks import OracleBiquad2, OracleFirstOrder, OracleFirstOrder2, oracle
from tests.oracle.estimators import OracleSFHFEstimator, make_oracle_estimator

T_S = 1e-4  # wen2023: 10 kHz
W_H = 2.0 * math.pi * 500.0  # Wen's injection (rad/s)
FREQS_HZ = [20.0, 100.0, 300.0, 500.0, 1000.0, 2500.0]
MODEL = motor_model(preset("wen2023"))
Proto = tuple[tuple[float, ...], tuple[float, ...]]


def _warped(
    proto: tuple[tuple[float, ...], tuple[float, ...]], w_p: float, w: float, T_s: float
) -> complex:
    """H_c(j K tan(w T/2)) with K = w_p / tan(w_p T/2): the prewarped bilinear closed form."""
    s = 1j * w_p / math.tan(0.5 * w_p * T_s) * math.tan(0.5 * w * T_s)
    b, a = proto
    return complex(np.polyval(b, s) / np.polyval(a, s))


def _n_skip(a: tuple[float, ...]) -> int:
    r = float(np.max(np.abs(np.roots(a))))
    return math.ceil(math.log(1e-12) / math.log(r)) + 10


def _gain_single(filt: OracleFirstOrder, a: tuple[float, ...], w: float, T_s: float) -> complex:
    """Fit y = Re{G e^{j w k T}} for the input cos(w k T)."""
    n0 = _n_skip(a)
    n1 = n0 + max(1000, math.ceil(4.0 * math.pi / (w * T_s)))
    y = np.empty(n1)
    for k in range(n1):
        y[k] = filt.update(math.cos(w * k * T_s))
    ks = np.arange(n0, n1)
    basis = np.column_stack([np.cos(w * ks * T_s), -np.sin(w * ks * T_s)])
    (g_re, g_im), *_ = np.linalg.lstsq(basis, y[n0:], rcond=None)
    return complex(g_re, g_im)


def _gain_pair(
    filt: OracleFirstOrder2 | OracleBiquad2, a: tuple[float, ...], w: float, T_s: float
) -> complex:
    """Input the space vector e^{j w k T} as (cos, sin); return mean(y e^{-j w k T})."""
    n0 = _n_skip(a)
    n1 = n0 + max(1000, math.ceil(4.0 * math.pi / abs(w * T_s)))
    acc = 0j
    for k in range(n1):
        x = cmath.exp(1j * w * k * T_s)
        y1, y2 = filt.update(x.real, x.imag)
        if k >= n0:
            acc += complex(y1, y2) * cmath.exp(-1j * w * k * T_s)
    return acc / (n1 - n0)


def _estimator() -> OracleSFHFEstimator:
    return OracleSFHFEstimator(MODEL, T_S, RotatingInjectionPars(w_o=0.0))


def test_estimators_share_wen_prototypes() -> None:
    """All three rotating estimators run the same discretised eqs. (11)-(13); BPF and HPF
    pre-warped at w_h, LPF at its corner 628 rad/s (what the closed forms below assume)."""
    ref = _estimator()
    for name in ("sfhf", "tt-ab", "tt-dq"):
        est = make_oracle_estimator(name, MODEL, T_S)
        for attr in ("bpf_z", "hpf_z", "lpf_z"):
            assert getattr(est, attr) == getattr(ref, attr)
    for proto, coefs, w_p in (
        (BPF_WEN, ref.bpf_z, W_H),
        (HPF_WEN, ref.hpf_z, W_H),
        (LPF_WEN, ref.lpf_z, 628.0),
    ):
        _, h = signal.freqz(coefs[0], coefs[1], worN=[w_p * T_S])
        assert complex(h[0]) == pytest.approx(_warped(proto, w_p, w_p, T_S), abs=1e-12)


@pytest.mark.parametrize("f", FREQS_HZ)
@pytest.mark.parametrize("which", ["bpf", "hpf", "lpf2"])
def test_pair_filter_response(which: str, f: float) -> None:
    """BPF (Biquad2), HPF and LPF (FirstOrder2) of the estimator, +w and -w.

    Catches: no pre-warping (BPF centre 0.8 % off: ~5 degrees at 500 Hz), pre-warping
    at the wrong frequency, a sign error in a feedback coefficient (unstable or a
    different response), channels mixed in the pair filter (the -w response would not
    be the conjugate), and a one-sample delay (phase -w T: 18 degrees at 500 Hz)."""
    est = _estimator()
    cases: dict[str, tuple[OracleFirstOrder2 | OracleBiquad2, Proto, Proto, float]] = {
        "bpf": (est._bpf, BPF_WEN, est.bpf_z, W_H),
        "hpf": (est._hpf, HPF_WEN, est.hpf_z, W_H),
        "lpf2": (est._lpf2, LPF_WEN, est.lpf_z, 628.0),
    }
    filt, proto, coefs, w_p = cases[which]
    w = 2.0 * math.pi * f
    want = _warped(proto, w_p, w, T_S)
    _, h = signal.freqz(coefs[0], coefs[1], worN=[w * T_S])
    assert complex(h[0]) == pytest.approx(want, abs=1e-12)  # freqz agrees with the closed form
    filt.reset()
    g_pos = _gain_pair(filt, coefs[1], w, T_S)
    filt.reset()
    g_neg = _gain_pair(filt, coefs[1], -w, T_S)
    assert g_pos == pytest.approx(want, abs=1e-9)
    assert g_neg == pytest.approx(want.conjugate(), abs=1e-9)
    if f == 500.0 and which != "lpf2":
        # pre-warped at w_h: equal to the continuous prototype at 500 Hz (for the BPF
        # |H| = 0.99999, phase -0.29 deg: eq. (11) is centred at 3140 rad/s = 499.7 Hz)
        b, a = proto
        h_c = complex(np.polyval(b, 1j * w) / np.polyval(a, 1j * w))
        assert g_pos == pytest.approx(h_c, abs=1e-9)


@pytest.mark.parametrize("f", FREQS_HZ)
def test_single_lpf_response(f: float) -> None:
    """LPF of eq. (13) on one signal (FirstOrder, SFHF / TT-dq error path)."""
    est = _estimator()
    w = 2.0 * math.pi * f
    g = _gain_single(est._lpf, est.lpf_z[1], w, T_S)
    assert g == pytest.approx(_warped(LPF_WEN, 628.0, w, T_S), abs=1e-9)


@pytest.mark.parametrize("T_s", [1e-4, 1e-3])
@pytest.mark.parametrize("w_c", [50.0, 400.0])
def test_speed_lpf_response(T_s: float, w_c: float) -> None:
    """lpf_first_order(w_c, T_s) (the controller's speed filter) is w_c / (s + w_c),
    pre-warped at w_c: exactly 1/sqrt(2) at -45 degrees at the corner, unity at DC, and
    the warped closed form at 0.3 w_c and 3 w_c. Without pre-warping the corner gain is
    0.7 % low (-45.4 deg) at 1 kHz and 400 rad/s; forward Euler is further off."""
    filt = oracle(lpf_first_order(w_c, T_s))
    a = (1.0, filt.a1)
    proto = ((w_c,), (1.0, w_c))
    for w in (0.3 * w_c, w_c, 3.0 * w_c):
        filt.reset()
        g = _gain_single(filt, a, w, T_s)
        assert g == pytest.approx(_warped(proto, w_c, w, T_s), abs=1e-9)
    filt.reset()
    g_c = _gain_single(filt, a, w_c, T_s)
    assert abs(g_c) == pytest.approx(1.0 / math.sqrt(2.0), abs=1e-9)
    assert math.degrees(cmath.phase(g_c)) == pytest.approx(-45.0, abs=1e-7)
    filt.reset()
    y = 0.0
    for _ in range(_n_skip(a)):
        y = filt.update(1.0)
    assert y == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize(
    ("f", "label"),
    [
        (-500.0, "negative sequence, standstill"),
        (-460.0, "negative sequence, 20 Hz"),
        (500.0, "positive sequence"),
        (50.0, "fundamental"),
    ],
    ids=["neg-0", "neg-20Hz", "pos", "fund"],
)
def test_sfhf_chain_response(f: float, label: str) -> None:
    """SFHF demodulation (Wen Fig. 3 + eq. (9)) for a current A e^{j(w k T + phi)}.

    Closed form in steady state (observer frozen at theta_hat by w_o = 0):
    BPF at w, HPF at w - w_h in the injection frame, heterodyne to w + w_h, LPF there:

        f_k = Im{ A e^{j phi} H_b(w) H_h(w - w_h) H_l(w + w_h) e^{j (w + w_h) k T}
                  e^{-j (2 theta_hat + pi/2)} }

    with each H the warped closed form. The positive sequence (w = w_h) lands at DC in
    the injection frame, where the bilinear HPF has its zero: f = 0. Catches a wrong
    rotation direction (the positive sequence would leak), a wrong heterodyne sign
    (f sign / phase), and the reference phase taken at another instant than k T.
    """
    del label
    est = _estimator()
    th_hat = 0.4
    est.reset(th_hat)
    A, phi = 0.05, 0.7
    w = 2.0 * math.pi * f
    n0, n1 = 3000, 4000
    G = (
        A
        * cmath.exp(1j * phi)
        * _warped(BPF_WEN, W_H, w, T_S)
        * _warped(HPF_WEN, W_H, w - W_H, T_S)
        * _warped(LPF_WEN, 628.0, w + W_H, T_S)
        * cmath.exp(-1j * (2.0 * th_hat + 0.5 * math.pi))
    )
    worst = 0.0
    for k in range(n1):
        i = A * cmath.exp(1j * (w * k * T_S + phi))
        est.update(EstimatorInput(k, i.real, i.imag, 0.0))
        if k >= n0:
            want = (G * cmath.exp(1j * (w + W_H) * k * T_S)).imag
            worst = max(worst, abs(est.f - want))
    assert est.theta_hat == th_hat  # frozen observer: the reference is known
    assert worst < 1e-9 * A
    if f == 500.0:
        assert abs(G) < 1e-12 * A  # positive sequence fully rejected
    if f == -500.0:
        # standstill: DC scaled by |H_b(w_h)| |H_h(2 w_h)| (0.982), with the BPF/HPF
        # phase shift the conventional method leaves uncompensated (Table 3)
        h_b = _warped(BPF_WEN, W_H, W_H, T_S)
        h_h = _warped(HPF_WEN, W_H, 2.0 * W_H, T_S)
        assert abs(G) == pytest.approx(A * abs(h_b) * abs(h_h), rel=1e-12)
        assert abs(G) < 0.99 * A
