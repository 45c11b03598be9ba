"""Rotating HF voltage injection (Wen Sec. 2), shared by the five demodulators.

Injection, Wen eq. (3): ``u_ab,h = V_h exp(j w_h t)``.

Sign of the negative sequence. Integrating eq. (2) for the voltage (3) at
standstill gives, in the rotor frame with ``phi = w_h t - theta_e``,
``i_d = V_h/(w_h L_d) sin(phi)``, ``i_q = -V_h/(w_h L_q) cos(phi)``, i.e. eq. (4)

    i_dq,h = I_p exp(j(w_h t - theta_e - pi/2)) + I_n exp(j(-w_h t + theta_e + pi/2))

with ``I_p = V_h (L_d + L_q) / (2 w_h L_d L_q)`` (eq. 5) and

    I_n = V_h (L_q - L_d) / (2 w_h L_d L_q) > 0   for an IPMSM (L_d < L_q).

Eq. (6) as printed has ``(L_d - L_q)``; every error signal here is built
with the derived sign above, so each observer locks at ``theta_hat =
theta_e`` (and ``theta_e + pi``), not at 90 degrees.

Timing. The command computed from sample ``k`` acts over ``[(k+1) T_s,
(k+2) T_s]``; the injected voltage for that period is the value of eq. (3)
at the mid-point, ``V_h exp(j w_h (k + 1.5) T_s)``. For a piecewise-constant
voltage ``V exp(j w_h (n + 1/2) T_s)`` on ``[n T_s, (n+1) T_s]`` an
inductance integrates exactly to a current at the sample instants
``t = k T_s`` of ``V / (j w_h L) * x/sin(x) * exp(j w_h k T_s)``, ``x = w_h T_s/2``:
the HF current *sampled at* ``k T_s`` has the phase of eq. (4)/(7) with
``t = k T_s`` and no delay, and an amplitude larger by ``x/sin(x)`` (1.004
at 500 Hz and 10 kHz). Hence every demodulation reference ``w_h t`` uses
``t = k T_s``, the sample instant, and the model amplitudes include the
factor ``x/sin(x)``.

PLL bandwidth by design (:func:`controller._pll.design_bandwidth`). The
observer closes its loop through whatever part of the demodulation comes
after ``theta_hat`` enters it; the injection itself does not depend on
``theta_hat``, so the computation delay of the PWM is not in this loop,
only the PLL's own one-period update. Small-signal, with the error
normalised to ``err ~ theta_e - theta_hat``, the response ``G`` from
``theta_hat`` to ``err`` is

- ``sfhf``: the heterodyne with ``2 theta_hat`` comes after the BPF and
  HPF, before the LPF: ``G = k LPF(z)``, with ``k = |H_B(-w_h)
  H_H(-2 w_h)|`` (0.98 here: the negative sequence that reaches the
  heterodyne is that much smaller than the ``I_n`` it is normalised by);
- ``tt-ab``: ``theta_hat`` enters after the LPF: ``G = |H_B(w_h)|^2``
  (1 with the BPF pre-warped at ``w_h``);
- ``tt-dq``: the current is rotated by ``theta_hat`` before the BPF, so a
  change of ``theta_hat`` phase-modulates both sequences, at ``+w_h`` and
  ``-w_h`` in the estimated frame, and the product ``i_dh i_qh`` adds the
  two envelopes::

      G(W) = |H(w_h)|^2 [H(w_h + W) / H(w_h) + H(W - w_h) / H(-w_h)] / 2 * LPF(W)

  with ``H`` the discrete BPF (each sequence's envelope seen through the
  BPF, normalised to the carrier it rides on), evaluated at
  standstill.
- ``epf`` ([25], reconstructed): the same as tt-dq; ``theta_hat`` also
  enters the two demodulation signals after the BPF, but those direct
  parts cancel in the product of the two sequences (:mod:`controller._epf`);
- ``self-demod`` ([27], reconstructed): the heterodyne with ``2 theta_hat``
  comes after the BPF and the sequence separation, before the LPF:
  ``G = |H_B(w_h) H_B(-w_h)| LPF(z)`` (``"pn+lpf"``; the separation passes
  each sequence whole at ``+-w_h``, :func:`separation_gains`).

``w_o`` is the largest bandwidth that keeps the phase margin at
:data:`controller._design.PM_TARGET_DEG` with the actual discretised
filters, and the crossover below the LPF's -3 dB corner. At 10 kHz with
eqs. (11)-(13) this gives ``tt-dq`` 58.5 rad/s (2 pi 9.3 Hz) and ``sfhf``
190 rad/s (2 pi 30 Hz), both at 45 degrees, and ``tt-ab`` 303 rad/s
(2 pi 48 Hz): its crossover sits at the LPF corner, with 75 degrees of margin.
The old common ``2 pi 20`` left ``tt-dq`` 21 degrees and a noise
amplification peak of 2.9 (1.35 now).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from controller._api import option_field
from controller._design import PM_TARGET_DEG, designed, freq_response
from controller._filters import BPF_WEN, HPF_WEN, LPF_WEN, bandpass_coefficients, discretize
from controller._luenberger import LuenbergerObserver, design_pole, observer_response
from controller._params import MotorModel
from controller._pll import PositionObserver, design_bandwidth

_TWO_PI = 2.0 * math.pi


#: How the docs state the filters' defaults.
_WEN_FILTERS = "Wen eqs. (11)-(13)"


@dataclass(frozen=True, slots=True)
class RotatingInjectionPars:
    """Settings shared by the rotating-injection estimators.

    Parameters
    ----------
    V_h : float
        Injection amplitude (V), eq. (3). 50 V gives ``I_n`` = 43 mA and
        ``I_p`` = 0.24 A on the wen2023 motor at 500 Hz.
    f_h : float
        Injection frequency (Hz), eq. (3).
    w_o : float or None
        Position-observer (PLL) bandwidth (rad/s); 0 freezes the observer.
        None derives it for each demodulator from ``pm_deg`` with its
        in-loop filters (module docstring). A lower value tracks
        accelerations worse (steady error ``a / w_o^2`` for an angular
        acceleration ``a``), a higher one loses phase margin.
    pm_deg : float
        Phase-margin target of the PLL loop (deg), used when ``w_o`` is None.
    observer : str
        Position observer driven by the demodulated error. ``"pll"``
        (default, Wen Fig. 4: a PI regulator, then an integrator;
        :class:`controller._pll.PositionObserver`, bandwidth ``w_o``) or
        ``"mechanical"``: the third-order observer of
        :class:`controller._luenberger.LuenbergerObserver` (a model of the
        mechanics with the controller's torque as feed-forward and an
        integral load state; Xue eqs. 9-12, Lorenz's motion observer),
        angle poles ``a`` (double) and load pole ``LOAD_POLE_RATIO a``. The PLL follows an angular acceleration ``alpha``
        with a steady error ``alpha / w_o^2``; the mechanical observer is
        told the acceleration by the torque it commands, so speed steps and
        reversals under load leave it only the error of its model (inertia,
        load changes), and its speed estimate needs no lag compensation in
        the speed loop (:meth:`RotatingHFEstimator.speed_response` is 1 for
        tt-dq with an exact model). Not the paper's: an option a drive uses.
        Its weakness is an unmodelled load change: the speed loop's answer
        to it is fed forward as acceleration the rotor does not make, so the
        speed loop regulates the observer's model until the load state has
        learned the load (``1 / b``); on wen2023's full-load ramps (7.5 N m
        on 0.003 kg m^2 in 0.3 s, wen-5.3 and wen-5.4) that loses the rotor,
        where the PLL keeps it. It suits speed steps and ramps under a known
        or slowly changing load (wen-5.2); ``bench sweep SCENARIO --grid
        estimator_options.observer=pll,mechanical`` compares the two.
    a : float or None
        Angle poles of the mechanical observer (rad/s); None derives them
        from ``pm_deg`` with the in-loop filters
        (:func:`controller._luenberger.design_pole`).
    normalise : str
        ``"model"``: divide the demodulated signal by the model amplitudes
        (``2 I_p I_n`` or ``2 I_n`` from :func:`hf_amplitudes`);
        ``"measured"``: by the amplitudes measured from the same signals
        (the quadrature component is demodulated with the same LPF, and
        ``hypot`` of the two is ``I_p I_n`` or ``I_n``), floored at 10 % of
        the model value.
    bpf_tracking : bool
        tt-dq only (the other demodulators raise ``ValueError``). False (the
        paper's): the BPF stays centred on ``w_h``. True: every period its
        centre moves to ``|w_h - w_t|``, with the same bandwidth, because that
        is where both sequences sit in the estimated frame at the electrical
        speed (:mod:`controller._tt_dq`); ``w_t`` is the tracker's speed state,
        free of the demodulation ripple: the PLL's integral ``w_i``, or the
        mechanical observer's ``w_hat``. Why it matters outside the papers'
        speeds: with a fixed centre each sequence is ``w_e`` off it, the
        demodulated error's gain falls to ``|H(w_h - w_e)|^2`` (a slower PLL,
        which lags an acceleration ``alpha`` by ``alpha / (K w_o^2)`` with
        that gain ``K``), and the BPF leaves ``|1 - H(w_h - w_e)|`` of each
        sequence in the fundamental current, which the current PI answers
        with HF voltage that biases the demodulation, unequally for the two
        directions of rotation. Tracking keeps the gain 1 and the residual 0
        at every speed (tests/test_controller_rotating.py, on the synthetic
        currents of eq. 4). The hybrid ``hybrid-tt-dq``, which uses tt-dq
        through its band, turns it on by default. The BPF must have the form
        of eq. (11), ``B s / (s^2 + B s + w_0^2)``; its centre is replaced by
        ``w_h`` at standstill (Wen's eq. 11 has 3140 rad/s for the 3141.6 of
        500 Hz), and the PLL is designed with that filter.
    accel_ff : bool
        tt-dq with the PLL only (the other demodulators and the mechanical
        observer raise ``ValueError``). False (the paper's). True: the
        acceleration the speed loop is designed to give from the speed
        reference (``EstimatorInput.accel_ref``,
        :class:`controller._controller.ReferenceModel`: the slope of
        ``alpha_s / (s + alpha_s)`` applied to ``w_m_ref``, times ``n_p``) is
        fed into the PLL's integral (:meth:`controller._pll.PositionObserver.update`).
        What a drive knows of its own acceleration without an estimate: it
        never reads ``theta_hat`` or ``w_hat``, so it is an input beside the
        loop, and the loop from the error to the angle, hence the phase
        margin (45 degrees) and the noise gain (the peak of ``|L / (1 + L)|``,
        1.35), are exactly the PLL's without it (tests/test_accel_ff.py). The
        PLL's lag ``a / w_o^2`` then remains only for the acceleration the
        reference does not explain: an unknown load change, and the speed
        loop's departure from its design. The torque reference is no such
        input: the speed PI makes it from ``w_hat``, and fed forward through
        ``J`` it turns an unknown load into a standing acceleration the PLL
        must absorb (``n_p tau_L / (J w_o^2)``, 2.9 rad at full load on
        wen2023), the way the mechanical observer loses the rotor. What it does
        to Wen Tables 6-8 (met where the speed reference explains the largest
        error, not where an unknown load change does) is measured in
        :mod:`bench.studies._accel_ff` and the suite's report.
    bpf, hpf, lpf : tuple
        Continuous prototypes ``(b, a)``; defaults Wen eqs. (11)-(13). If
        ``f_h`` is not 500 Hz and ``bpf`` is the default, the BPF centre
        moves to ``2 pi f_h`` with the same bandwidth. The BPF and HPF are
        pre-warped at ``w_h`` (where Wen Fig. 5 states their phase), the LPF
        at its corner.
    """

    # the checks each option takes as a scenario's [estimator_options] key (option_field)
    V_h: float = option_field(50.0, positive=True, limit="inverter_linear")
    f_h: float = option_field(500.0, positive=True, limit="below_nyquist")
    w_o: float | None = option_field(None, minimum=0.0)  # 0 freezes the PLL
    pm_deg: float = option_field(PM_TARGET_DEG, positive=True)
    observer: str = option_field("pll", choices=("pll", "mechanical"))
    a: float | None = option_field(None, positive=True)
    normalise: str = option_field("model", choices=("model", "measured"))
    bpf_tracking: bool = False
    accel_ff: bool = False
    bpf: tuple[tuple[float, ...], tuple[float, ...]] = option_field(
        BPF_WEN, default_doc=_WEN_FILTERS
    )
    hpf: tuple[tuple[float, ...], tuple[float, ...]] = option_field(
        HPF_WEN, default_doc=_WEN_FILTERS
    )
    lpf: tuple[tuple[float, ...], tuple[float, ...]] = option_field(
        LPF_WEN, default_doc=_WEN_FILTERS
    )


def hf_amplitudes(motor: MotorModel, V_h: float, w_h: float, T_s: float) -> tuple[float, float]:
    """Model amplitudes ``(I_p, I_n)`` (A) of the sampled HF current.

    Wen eqs. (5)-(6) with the derived sign ``I_n ~ (L_q - L_d) > 0`` and the
    zero-order-hold factor ``x/sin(x)``, ``x = w_h T_s / 2`` (module docstring).
    """
    x = 0.5 * w_h * T_s
    kappa = x / math.sin(x) if x > 0.0 else 1.0
    k = kappa * V_h / (2.0 * w_h * motor.L_d * motor.L_q)
    return k * (motor.L_d + motor.L_q), k * (motor.L_q - motor.L_d)


@designed
def lpf_corner(lpf_z: tuple[tuple[float, ...], tuple[float, ...]], T_s: float) -> float:
    """-3 dB corner (rad/s) of the discrete low-pass ``lpf_z`` (unity DC gain assumed)."""
    from scipy.optimize import brentq

    b, a = lpf_z
    g0 = abs(complex(freq_response(b, a, np.array([0.0]), T_s)[0]))

    def f(w: float) -> float:
        return abs(complex(freq_response(b, a, np.array([w]), T_s)[0])) / g0 - math.sqrt(0.5)

    w_n = 0.999 * math.pi / T_s
    if f(w_n) > 0.0:
        return w_n
    return float(brentq(f, 1e-6 / T_s, w_n, xtol=1e-9))


def in_loop_response(
    loop: str,
    T_s: float,
    w_h: float,
    filters: tuple[tuple[tuple[float, ...], tuple[float, ...]], ...],
    w: np.ndarray,
) -> np.ndarray:
    """Response ``G`` from ``theta_hat`` to ``err`` of a demodulator (module docstring).

    ``loop`` is ``"none"`` (tt-ab), ``"lpf"`` (sfhf), ``"pn+lpf"`` (self-demod:
    ``theta_hat`` enters after the BPF and the sequence separation, before the
    LPF; the separation passes each sequence at ``+-w_h`` with gain 1,
    :mod:`controller._self_demod`) or ``"bpf+lpf"`` (tt-dq, epf); ``filters``
    the discrete ``(bpf_z, hpf_z, lpf_z)``.
    """
    bpf_z, hpf_z, lpf_z = filters
    w = np.asarray(w, float)
    one = np.array([1.0])
    h_p = complex(freq_response(*bpf_z, w_h * one, T_s)[0])
    h_n = complex(freq_response(*bpf_z, -w_h * one, T_s)[0])
    if loop == "none":
        return np.full(w.shape, abs(h_p * h_n), dtype=complex)
    g = freq_response(*lpf_z, w, T_s)
    if loop == "lpf":
        k = abs(h_n * complex(freq_response(*hpf_z, -2.0 * w_h * one, T_s)[0]))
        return k * g
    if loop == "pn+lpf":
        return abs(h_p * h_n) * g
    if loop != "bpf+lpf":
        raise ValueError(f"unknown loop {loop!r}")
    env = 0.5 * (
        freq_response(*bpf_z, w_h + w, T_s) / h_p + freq_response(*bpf_z, w - w_h, T_s) / h_n
    )
    return abs(h_p * h_n) * env * g


def theta_response(
    loop: str,
    T_s: float,
    w_h: float,
    filters: tuple[tuple[tuple[float, ...], tuple[float, ...]], ...],
    w: np.ndarray,
) -> np.ndarray:
    """Response from the rotor angle ``theta_e`` to ``err`` (small signal, at standstill).

    The rotor angle phase-modulates the negative sequence only (``2 theta_e``
    in eq. 7), before every filter: a phase modulation through a filter
    ``H`` on a carrier ``w_0`` comes out as ``(P(W) + conj P(-W)) / 2``
    with ``P(W) = H(w_0 + W) / H(w_0)``. For tt-dq and tt-ab that is the
    BPF's on ``-w_h``, then the LPF. For sfhf it is the BPF's on ``-w_h``
    times the HPF's on ``-2 w_h`` (the synchronous frame), then the LPF. The
    static gains are those of :func:`in_loop_response`. For tt-dq (and epf) it
    equals the in-loop response: at standstill the two sequences' envelopes
    are alike. For self-demod it is the BPF's on ``-w_h`` times the sequence
    separation's negative-sequence gain (:func:`separation_gains`), then the
    LPF.
    """
    bpf_z, hpf_z, lpf_z = filters
    w = np.asarray(w, float)
    one = np.array([1.0])
    h_p = complex(freq_response(*bpf_z, w_h * one, T_s)[0])
    h_n = complex(freq_response(*bpf_z, -w_h * one, T_s)[0])

    def p(x: np.ndarray) -> np.ndarray:
        out = freq_response(*bpf_z, x - w_h, T_s) / h_n
        if loop == "lpf":
            h_h = complex(freq_response(*hpf_z, -2.0 * w_h * one, T_s)[0])
            out = out * freq_response(*hpf_z, x - 2.0 * w_h, T_s) / h_h
        elif loop == "pn+lpf":
            out = out * separation_gains(x - w_h, w_h, T_s)[1]
        return out

    env = 0.5 * (p(w) + np.conj(p(-w)))
    g = freq_response(*lpf_z, w, T_s)
    if loop == "lpf":
        k = abs(h_n * complex(freq_response(*hpf_z, -2.0 * w_h * one, T_s)[0]))
        return k * env * g
    return abs(h_p * h_n) * env * g


def separation_gains(w: np.ndarray, w_h: float, T_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Gains ``(S_p, S_n)`` of self-demod's sequence separation for a component at ``w``.

    The separation (:mod:`controller._self_demod`) takes the BPF's output ``d``
    and its quadrature twin ``q = (s / w_h) d`` (the same filter times
    ``s / w_h``, discretised with the same bilinear map pre-warped at ``w_h``),
    and forms ``i_p = (d - j q) / 2`` and ``i_n = (d + j q) / 2``. For a
    component at ``w`` (rad/s, signed) the map gives ``q = j (W / w_h) d``
    with the warped frequency ``W = w_h tan(w T_s / 2) / tan(w_h T_s / 2)``,
    so ``S_p = (1 + W / w_h) / 2`` and ``S_n = (1 - W / w_h) / 2``: real (the
    separation adds no phase), ``S_p(w_h) = S_n(-w_h) = 1`` and
    ``S_p(-w_h) = S_n(w_h) = 0`` exactly.
    """
    r = np.tan(0.5 * np.asarray(w, float) * T_s) / math.tan(0.5 * w_h * T_s)
    return 0.5 * (1.0 + r), 0.5 * (1.0 - r)


@designed
@functools.lru_cache(maxsize=64)
def pll_design(
    loop: str,
    T_s: float,
    w_h: float,
    filters: tuple[tuple[tuple[float, ...], tuple[float, ...]], ...],
    pm_deg: float,
) -> tuple[float, float, float]:
    """``(w_o, pm, w_c)`` of :func:`controller._pll.design_bandwidth` for a demodulator
    (``filters``: the discrete ``(bpf_z, hpf_z, lpf_z)``)."""
    return design_bandwidth(
        lambda w: in_loop_response(loop, T_s, w_h, filters, w),
        T_s,
        pm_deg,
        lpf_corner(filters[2], T_s),
    )


#: Load pole of the mechanical observer as a fraction of its angle poles
#: (``b = 0.1 a``, :class:`controller._luenberger.LuenbergerObserver`). A decade
#: below: the load state then costs little of the angle loop (with nothing in
#: the loop its margin is 75.3 degrees against the PI tracker's 75.9; with
#: tt-dq's filters the 45-degree design gives ``a`` = 54.2 rad/s against the
#: PLL's 58.5), so an unmodelled load step is followed as the paper's PLL
#: follows it, and the load estimate settles in ``1 / b`` (about 0.2 s).
#: Xue's triple pole (``b = a``) would give 32.5 rad/s: too slow for the full
#: load steps of wen-5.3 and 5.4 (peak error ``2 e^-2 n_p tau_L / (J a^2)``,
#: 2.6 rad for 7.5 N m).
LOAD_POLE_RATIO = 0.1


@designed
@functools.lru_cache(maxsize=64)
def mechanical_design(
    loop: str,
    T_s: float,
    w_h: float,
    filters: tuple[tuple[tuple[float, ...], tuple[float, ...]], ...],
    pm_deg: float,
) -> tuple[float, float, float]:
    """``(a, pm, w_c)`` of :func:`controller._luenberger.design_pole` for a demodulator,
    with the same in-loop response and crossover bound as :func:`pll_design`."""
    return design_pole(
        lambda w: in_loop_response(loop, T_s, w_h, filters, w),
        T_s,
        pm_deg,
        lpf_corner(filters[2], T_s),
        LOAD_POLE_RATIO,
    )


@designed
def observer_margins(
    loop: str,
    T: float,
    w_h: float,
    filters: tuple[tuple[tuple[float, ...], tuple[float, ...]], ...],
    w_o: float,
    mechanical: bool,
) -> tuple[float, float]:
    """Phase margin (deg) and crossover (rad/s) of a demodulator's angle loop with its
    observer at ``w_o`` (the PLL, or the mechanical observer; NaN if frozen)."""
    from controller._design import margins
    from controller._pll import open_loop

    if w_o <= 0.0:
        return math.nan, math.nan
    if mechanical:
        return margins(
            lambda w: (
                observer_response(w_o, T, np.exp(1j * w * T), LOAD_POLE_RATIO * w_o)[0]
                * in_loop_response(loop, T, w_h, filters, w)
            ),
            1e-3 * w_o,
            0.999 * math.pi / T,
            3,
        )
    return margins(
        lambda w: open_loop(w_o, T, w) * in_loop_response(loop, T, w_h, filters, w),
        1e-3 * w_o,
        0.999 * math.pi / T,
        2,
    )


class RotatingHFEstimator:
    """Common part: injection, discrete filters, observer, estimator attributes.

    The design: the injection, the discrete filters and the observer with
    their derivations. The period (each demodulator's ``update``, the
    ``injection`` and the predicted HF current) runs in the controller's core
    (``controller/core/cc_rotating.c`` and one file per demodulator); its
    readable Python is the tests' oracle (``tests/oracle/estimators.py``).
    What each quantity refers to
    in time: ``theta_hat`` and ``err`` belong to the sample instant
    ``k T_s`` of the last ``update``; ``injection`` is the voltage
    averaged over period ``k + 1``.

    Parameters
    ----------
    motor : MotorModel
        The controller's motor model (for ``I_p``, ``I_n``).
    T_s : float
        Sampling period (s).
    pars : RotatingInjectionPars
        Injection, filter and observer settings.

    Attributes
    ----------
    injection_family : str
        ``"rotating"``: the controller's start-up and the dead-time band follow
        from it (``controller._registry.estimator_family``), for this estimator
        built by name or by a plug-in that wraps it.
    """

    injection_family: ClassVar[str] = "rotating"

    #: The period predicts its HF current at the mid-point of the next one (eq. 4/7 with
    #: the model amplitudes and ``theta_hat``): the dead-time compensation adds it to the
    #: reference's current for the sign of each phase current
    #: (:mod:`controller._compensation`).
    predicts_hf: ClassVar[bool] = True

    #: What of the demodulation lies between ``theta_hat`` and ``err``
    #: (:func:`in_loop_response`): ``"none"``, ``"lpf"`` or ``"bpf+lpf"``.
    IN_LOOP: ClassVar[str] = "none"
    #: Whether the demodulator takes the ``accel_ff`` option (tt-dq).
    ACCEL_FF: ClassVar[bool] = False

    def __init__(self, motor: MotorModel, T_s: float, pars: RotatingInjectionPars) -> None:
        if motor.L_q <= motor.L_d:
            raise ValueError("rotating HF injection needs saliency L_q > L_d")
        self.pars = pars
        self.T_s = T_s
        self.V_h = pars.V_h
        self.w_h = _TWO_PI * pars.f_h
        if self.w_h * T_s >= math.pi:
            raise ValueError(f"injection frequency {pars.f_h} Hz above Nyquist for T_s={T_s}")
        self.wT = self.w_h * T_s
        self.I_p, self.I_n = hf_amplitudes(motor, pars.V_h, self.w_h, T_s)
        b, a = pars.bpf
        if pars.bpf == BPF_WEN and pars.f_h != 500.0:
            a = (1.0, a[1], self.w_h * self.w_h)
        #: The continuous BPF ``(b, a)`` in use (eq. 11, centred on ``w_h``).
        self.bpf_s = (tuple(b), tuple(a))
        self.bpf_z = discretize(b, a, T_s, self.w_h)
        self.bpf_tracking = bool(pars.bpf_tracking)
        #: Bandwidth (rad/s) of the tracking BPF (``bpf_tracking``), 0 when it is fixed.
        self.bpf_B = 0.0
        if self.bpf_tracking:
            if self.IN_LOOP != "bpf+lpf":
                raise ValueError(
                    "bpf_tracking is a tt-dq option (its BPF runs in the estimated frame)"
                )
            if not (
                len(b) == 2 and len(a) == 3 and b[1] == 0.0 and a[0] == 1.0 and b[0] == a[1] > 0.0
            ):
                raise ValueError(
                    "bpf_tracking needs a BPF of the form of Wen eq. (11), "
                    f"B s / (s^2 + B s + w_0^2); got b={b}, a={a}"
                )
            self.bpf_B = float(a[1])
            b0, a1, a2 = bandpass_coefficients(self.w_h, self.bpf_B, T_s)
            self.bpf_z = ((b0, 0.0, -b0), (1.0, a1, a2))
        self.hpf_z = discretize(*pars.hpf, T_s, self.w_h)
        a_l = pars.lpf[1]
        w_lpf = abs(a_l[-1] / a_l[0]) if len(a_l) == 2 else self.w_h / 5.0
        self.lpf_z = discretize(*pars.lpf, T_s, w_lpf)
        self.filters_z = (self.bpf_z, self.hpf_z, self.lpf_z)
        if pars.normalise not in ("model", "measured"):
            raise ValueError(f"normalise must be 'model' or 'measured', got {pars.normalise!r}")
        self.measured = pars.normalise == "measured"
        if pars.observer not in ("pll", "mechanical"):
            raise ValueError(f"observer must be 'pll' or 'mechanical', got {pars.observer!r}")
        self.mechanical = pars.observer == "mechanical"
        self.accel_ff = bool(pars.accel_ff)
        if self.accel_ff and not (self.ACCEL_FF and not self.mechanical):
            raise ValueError("accel_ff is an option of tt-dq with its PLL (observer = 'pll')")
        #: The acceleration fed forward into the PLL this period (rad/s^2, ``accel_ff``).
        self.accel = 0.0
        self.pll: PositionObserver | LuenbergerObserver
        if self.mechanical:
            a_o = pars.a
            if a_o is None:
                a_o = mechanical_design(self.IN_LOOP, T_s, self.w_h, self.filters_z, pars.pm_deg)[0]
            elif not a_o > 0.0:
                raise ValueError(f"a must be > 0, got {a_o}")
            self.w_o = float(a_o)
            self.pll = LuenbergerObserver(
                motor.J, motor.n_p, self.w_o, T_s, LOAD_POLE_RATIO * self.w_o
            )
            self._l3 = self.pll.K_3 / motor.J
        else:
            w_o = pars.w_o
            if w_o is None:
                w_o = pll_design(self.IN_LOOP, T_s, self.w_h, self.filters_z, pars.pm_deg)[0]
            elif w_o < 0.0:
                raise ValueError(f"w_o must be >= 0, got {w_o}")
            self.w_o = float(w_o)
            self.pll = PositionObserver(self.w_o, T_s)
        self.theta_hat = 0.0
        self.w_hat = 0.0
        self.err = 0.0
        self.f = 0.0
        self.i_alpha_f = 0.0
        self.i_beta_f = 0.0
        self._k = 0

    def gains(self) -> dict[str, float]:
        """Every gain and corner of the estimator (rad/s unless named otherwise)."""
        pm, w_c = self.phase_margin()
        pll = self.pll
        observer = (
            {"w_o": self.w_o, "k_p": pll.k_p, "k_i": pll.k_i}
            if isinstance(pll, PositionObserver)
            else {"a": self.w_o, "K_1": pll.K_1, "K_2": pll.K_2, "K_3": pll.K_3}
        )
        return {
            "V_h": self.V_h,
            "w_h": self.w_h,
            **observer,
            "pm_target_deg": self.pars.pm_deg,
            "pm_deg": pm,
            "w_c": w_c,
            "lpf_corner": lpf_corner(self.lpf_z, self.T_s),
            "I_p": self.I_p,
            "I_n": self.I_n,
        }

    def phase_margin(self) -> tuple[float, float]:
        """Phase margin (deg) and crossover (rad/s) of the PLL loop as built (NaN if frozen)."""
        return observer_margins(
            self.IN_LOOP, self.T_s, self.w_h, self.filters_z, self.w_o, self.mechanical
        )

    def speed_response(self, w: np.ndarray) -> np.ndarray:
        """Response from the true electrical speed to ``w_hat`` at ``w`` (rad/s).

        With ``G_m`` (:func:`theta_response`), ``G`` (:func:`in_loop_response`),
        the PLL's ``O`` (:func:`controller._pll.open_loop`) and ``C_w = k_p + T
        k_i z / (z - 1)`` (``w_hat`` from ``err``): ``err = G_m theta / (1 + G
        O)`` and ``theta = T w / (z - 1)``, so ``w_hat / w = C_w G_m T / ((z - 1)
        (1 + G O))``, 1 at DC. The controller designs its speed loop with it.

        Mechanical observer (``Theta_E``, ``W_E``:
        :func:`controller._luenberger.observer_response`): with its model of
        the mechanics exact, the torque drives the true and the estimated
        angle alike, and only the difference ``G_m - G`` of what the
        demodulator sees of the two reaches its error, so ``w_hat / w = 1 +
        R_E (G_m - G) T / ((z - 1) (1 + G Theta_E))`` with ``R_E = Theta_E (1 -
        z^-1) / T`` (the published ``w_hat`` is the rate the step gives the
        angle, as the PLL's, not the observer's speed state): exactly 1 for tt-dq
        (``G_m = G``), as for the square-wave observer.
        """
        from controller._pll import open_loop

        w = np.asarray(w, float)
        T = self.T_s
        z = np.exp(1j * w * T)
        f = self.filters_z
        g = in_loop_response(self.IN_LOOP, T, self.w_h, f, w)
        g_m = theta_response(self.IN_LOOP, T, self.w_h, f, w)
        pll = self.pll
        if not isinstance(pll, PositionObserver):
            th_e = observer_response(self.w_o, T, z, LOAD_POLE_RATIO * self.w_o)[0]
            r_e = th_e * (z - 1.0) / (z * T)  # the angle's rate of the step (w_hat)
            return 1.0 + r_e * (g_m - g) * T / ((z - 1.0) * (1.0 + g * th_e))
        c_w = pll.k_p + T * pll.k_i * z / (z - 1.0)
        return c_w * g_m * T / ((z - 1.0) * (1.0 + g * open_loop(self.w_o, T, w)))

    def _reset_filters(self) -> None:
        raise NotImplementedError

    def reset(self, theta0: float) -> None:
        """Restart from ``theta0`` (rad) at zero speed; clears the filters."""
        self.pll.reset(theta0)
        self.theta_hat = self.pll.theta_hat
        self.w_hat = 0.0
        self.err = 0.0
        self.f = 0.0
        self._reset_filters()
