"""HF square-wave injection estimator for low switching frequency (Xue et al., Secs. 2-3).

Signal chain per PWM period ``k`` (all Python floats):

1. Injection, eq. (3): ``+/-U_h`` along the estimated d axis, the sign
   alternating every PWM period (at 1 kHz PWM a 500 Hz square wave,
   ``T_h = 2 T_s``).
2. HF response, eq. (7): ``h(k) = (i(k) - i(k-1)) / 2``, the response to the
   voltage of period ``k - 1``.
3. Envelope by sample-rate conversion, ``R = 0.5`` (Sec. 3.1, Fig. 4): one
   sample per injection period from its two halves,
   ``E = (h(+) - h(-)) / 2``; the fundamental's linear drift over the two
   periods cancels. ``E`` is the position quadrature signal of eq. (6)::

       E ~ (U_h T_s / (2 L_d L_q)) (L_avg e^{j phi} - L_dif e^{j(2 theta_e - phi)})

   where ``phi`` is the injection direction and ``L_dif = (L_d - L_q)/2``.
4. Single-order CIC interpolation (eq. 8, :mod:`controller._cic`) back to
   the PWM rate; ``square-wave-nocic`` holds the envelope instead (zero-order
   hold), for Xue's Figs. 11-12.
5. Normalisation and quadrature PLL error: with ``u`` the unit vector of
   the injection direction carried through the same interpolator,
   ``E conj(u) ~ L_avg - L_dif e^{j 2 dtheta}``, so::

       err = Im(E conj u) / |E| * L_q / (L_q - L_d)
           = sin(2 dtheta) (L_q - L_d) / (2 |L_avg - L_dif e^{j2 dtheta}|) * L_q / (L_q - L_d)

   which is ``dtheta`` for small errors, positive for ``0 < dtheta < pi/2``
   and has its stable zero at ``dtheta = 0`` (the zero at ``pi/2`` is
   unstable). For an IPMSM ``L_q > L_d``, so ``-L_dif > 0`` as printed in (6).
6. Luenberger observer with torque feed-forward, eqs. (9)-(12)
   (:mod:`controller._luenberger`).

Timing bookkeeping (unit ``T_s``; DESIGN.md "Timing model"):

- sample ``k`` is taken at ``k``; the injection computed from it acts over
  ``[k+1, k+2]``, mid-point ``k + 1.5``;
- ``h(k)`` covers ``[k-1, k]``, mid-point ``k - 0.5``;
- an envelope sample formed at ``k`` covers ``[k-2, k]``, mid-point ``k - 1``;
- hold and CIC (``M = R = 2``) add ``0.5 + 0.5``: the interpolated
  quadrature signal at step ``k`` describes the machine at ``k - 2``.

The HF response measures ``theta_e - phi`` over the period the voltage acts
(sin 2x averaged over a linear ramp is zero exactly at its mid-point), and
the error is formed against the injection direction that produced the
signal (``u`` travels through the same interpolator), so the measuring
chain's own age (2 periods) cannot bias the estimate: it only delays the
loop. At equilibrium ``err = 0`` means ``phi(k+1) = theta_e(k + 1.5)``.
With ``phi(k+1) = theta_hat(k) + c T_s w_hat`` the estimate refers to the
sample instant exactly when ``c = 1 + 0.5 = 1.5`` (one period of computation
delay plus half the period to its mid-point); any other ``c`` leaves a bias
``(c - 1.5) T_s w_e`` that grows with speed. Xue compensates ``3.5 T_s
w_hat``: that is this ``1.5`` plus the 2-period age of the interpolated
quadrature signal, the right amount when the PLL error is taken against
the present estimate (as in Xue Fig. 10) instead of against the injection
direction that produced the signal. Here the 2 periods plus the 1.5 add up
to the loop's latency ``tau_L = 3.5 T_s`` instead, which sets the bandwidth.

Observer pole by design (:func:`observer_pole`). The loop, broken at
the envelope (one sample every ``R = 2`` periods), is exactly linear and
shift-invariant at that slow rate; from one envelope sample to the next
(unit ``T_s``, ``z = e^{j w T_s}``):

- hold for ``R = 2`` periods, ``1 + z^-1``, then the CIC ``(1 + z^-1)/2``
  (``1`` for ``square-wave-nocic``), giving ``err``;
- the observer (:func:`controller._luenberger.observer_response`) and the
  injection angle ``phi = theta_hat + c T_s w_hat`` (the delay
  compensation ``c = 1.5`` is a lead inside the loop);
- one period of computation delay ``z^-1``: ``phi`` computed at ``k`` acts
  over period ``k + 1``; the error of each period is ``theta_e - phi``;
- the envelope formed at ``k`` from periods ``k - 2`` and ``k - 1``,
  ``(z^-1 + z^-2)/2``, read every second period.

With ``F(z)`` the product of these, the slow-rate loop gain is
``L = (F(z) + F(-z)) / 2`` (the decimation folds ``-z`` onto ``z``; the
fold is small near crossover), with no approximation. The delays add up
to the latency of the bookkeeping above: ``1 + 1 + 0.5 + 0.5 + 0.5 = 3.5
T_s``. The pole ``a`` is the largest one whose loop keeps the phase margin
:data:`controller._design.PM_TARGET_DEG` (45 degrees). At 1 kHz this
gives ``a = 50.8`` rad/s (crossover 161 rad/s, gain margin 10 dB upward
and 18 dB downward: the type-3 loop also goes unstable if its gain drops
a lot). The zero-order-hold variant has one box less in the loop and
gets its own, larger pole at the same margin (``60.9`` rad/s); ``a``
overrides both. The old ``a = 0.1 / (3.5 T_s)`` (28.6 rad/s) had a
margin of 57 degrees. It rejected load steps, and a feed-forward made
wrong by a wrong inertia, ``(50.8 / 28.6)^2 = 3.2`` times worse. The
inertia does not enter the loop (:mod:`controller._luenberger`).

Checked against Xue Secs. 3.1-3.3, block by block (issue 30; the C twin
``controller/core/cc_square_wave.c`` is the same chain, tested bit-identical):

- Rate conversion: eq. (7) with ``T_h/2 = T_s`` (the causal form
  ``h(k) = (i(k) - i(k-1))/2``), then ``R = 0.5`` (Fig. 4) to one envelope
  sample per injection period, as Xue describes. Matches.
- CIC order: single order (``N = 1``, "in this paper, the single-order CIC
  filter is used"), ``M = R`` (Sec. 3.2). Matches.
- ``R = (T_h/2)/T_PWM`` as printed under Fig. 8 is 1 at Xue's 500 Hz and
  1 kHz, which would interpolate nothing; the quadrature signal it raises
  comes at ``1/T_h`` (Sec. 3.1), and Fig. 9 shows the rate doubled, so the
  factor is ``T_h / T_PWM = 2``, which the chain uses (``R = 2``).
- Gain: eq. (8) has a DC gain of ``M``; the chain divides by ``M`` and holds
  the slow sample (instead of stuffing zeros), so the interpolated signal
  has the envelope's amplitude. The normalisation below divides it out in
  any case, so the gain moves no angle.
- Normalisation: by ``|E|`` and ``|u|`` (Sec. 3.3, "after normalizing the
  interpolated position quadrature signal"). Matches.
- Delay compensation including the CIC's own group delay: the hold and the
  CIC each delay the envelope by half a period; the chain compares it with
  the injection direction ``u`` carried through the same interpolator, so
  both have the same age and the delay leaves no bias at any speed (tested:
  ``test_speed_imposed_converges_and_error_does_not_grow_with_speed`` in
  tests/test_controller_square_wave_plant.py, with and without CIC). Xue's
  ``3.5 T_PWM`` compensates the same total against the present estimate;
  at steady speed the two are the same angle.

No block was wrong, so no number moved. What the CIC does to the quadrature
signal (Xue Figs. 11-12) is measured by :mod:`bench.studies._cic`; with the
same observer pole it leaves the max |dtheta| where the hold has it, and the
shipped ``square-wave-nocic`` gets a larger pole at the same phase margin
(below), hence its smaller peak after load steps.

Injection amplitude: at 1 kHz the d-axis current ramps by ``U_h T_s / L_d``
per period; ``U_h = 20 V`` gives 5.7 A peak to peak (+/-2.8 A) on the
xue2022 motor (``L_d = 3.53 mH``) and a q-axis error signal of
``U_h T_s (1/L_d - 1/L_q) / 2 = 1.5 A`` per radian of ``sin 2 dtheta``,
3.7 % of the 540 V bus.

Fundamental current for the current loop: the square-wave response is an
alternating triangle, so ``i_f(k) = (3 i(k) + 2 i(k-1) - i(k-2)) / 4``
removes it exactly and refers to ``k`` with no lag for a fundamental that
changes linearly over two periods (the plain mean of two samples would lag
half a period).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from controller._api import option_field
from controller._cctl import CIC_MAX
from controller._cic import CicInterpolator
from controller._design import PM_TARGET_DEG, designed, margins, solve_largest
from controller._luenberger import LuenbergerObserver, observer_response
from controller._params import MotorModel

_TWO_PI = 2.0 * math.pi

#: Loop latency of the measuring chain (periods): 1.5 to the mid-point of the
#: injected period plus 2 of envelope age (pair mid-point 1, hold 0.5, CIC 0.5).
LOOP_LATENCY_PERIODS = 3.5
#: Derived delay compensation (periods): computation delay 1 + half a period.
DELAY_COMP_PERIODS = 1.5


def open_loop(
    a: float, T_s: float, w: np.ndarray, cic: bool, M: int, delay_comp: float
) -> np.ndarray:
    """Slow-rate loop gain of the square-wave observer at ``w`` (rad/s, below ``pi / (2 T_s)``).

    Module docstring, "Observer pole by design": ``L = (F(z) + F(-z)) / 2``.
    """

    def f(z: np.ndarray) -> np.ndarray:
        zi = 1.0 / z
        hold = 1.0 + zi
        interp = hold * (sum(zi**n for n in range(M)) / M if cic else 1.0)
        th, wo = observer_response(a, T_s, z)
        pair = 0.5 * (zi + zi * zi)
        return interp * (th + delay_comp * T_s * wo) * zi * pair

    z = np.exp(1j * np.asarray(w, float) * T_s)
    return 0.5 * (f(z) + f(-z))


@designed
def loop_margins(
    a: float, T_s: float, cic: bool = True, M: int = 2, delay_comp: float = DELAY_COMP_PERIODS
) -> tuple[float, float]:
    """Phase margin (deg) and crossover (rad/s) of the observer loop (:func:`open_loop`)."""
    return margins(
        lambda w: open_loop(a, T_s, w, cic, M, delay_comp), 1e-3 * a, 0.999 * math.pi / (2 * T_s), 3
    )


@designed
@functools.lru_cache(maxsize=64)
def observer_pole(T_s: float, cic: bool, M: int, delay_comp: float, pm_deg: float) -> float:
    """Largest triple pole ``a`` (rad/s) whose loop keeps the phase margin ``pm_deg`` (deg)."""
    return solve_largest(
        lambda a: loop_margins(a, T_s, cic, M, delay_comp)[0],
        pm_deg,
        1e-3 / T_s,
        0.3 / T_s,
        rising=False,
    )


@dataclass(frozen=True, slots=True)
class SquareWaveOptions:
    """The options of the square-wave estimators (a scenario's ``[estimator_options]``).

    Parameters
    ----------
    U_h : float
        Injection amplitude (V).
    a : float or None
        Observer triple pole (rad/s); None derives it from ``pm_deg``
        (:func:`observer_pole`).
    M : int
        CIC differential delay (PWM periods), at most the core's delay line (64).
    delay_comp : float or None
        Delay compensation of the injection angle (periods); None uses the
        derived 1.5. Zero disables it (for tests and comparisons).
    pm_deg : float
        Phase-margin target of the observer loop (deg), used when ``a`` is None.

    Notes
    -----
    ``M`` is at most ``CIC_MAX`` (64): the core's delay line is a fixed array
    (``controller/core/cc_cic.h``, no allocation), and a longer one buys
    nothing. The CIC adds ``M T_s / 2`` of delay to the observer loop, so the
    derived pole (:func:`observer_pole`, ``pm_deg``) falls as ``M`` grows:
    50.8 rad/s at ``M = 2``, 15.2 at 16 and 4.45 at 64 with ``T_s`` = 1 ms
    (ten times each at 10 kHz); at 64 the observer is already seven times
    slower than the speed loop's 31.4 rad/s target, which it must follow.
    """

    U_h: float = option_field(20.0, positive=True, limit="inverter_linear")
    a: float | None = option_field(None, positive=True)
    M: int = option_field(2, kind="int", minimum=1, maximum=CIC_MAX)
    delay_comp: float | None = option_field(None, minimum=0.0)  # 0 disables it
    pm_deg: float = option_field(PM_TARGET_DEG, positive=True)


_DEFAULTS = SquareWaveOptions()


class SquareWaveEstimator:
    """Xue's square-wave injection estimator (eqs. 3-12), optionally without CIC.

    Parameters
    ----------
    motor : MotorModel
        The controller's motor model (``L_d``, ``L_q``, ``J``, ``n_p``).
    T_s : float
        PWM period = control period (s).
    cic : bool
        True: CIC interpolation of the envelope (``square-wave``);
        False: zero-order hold (``square-wave-nocic``).
    U_h, a, M, delay_comp, pm_deg
        The options (:class:`SquareWaveOptions`, which holds their defaults).
    """

    #: The injection family (``controller._registry.estimator_family``).
    injection_family: ClassVar[str] = "square"

    def __init__(
        self,
        motor: MotorModel,
        T_s: float,
        cic: bool = True,
        U_h: float = _DEFAULTS.U_h,
        a: float | None = _DEFAULTS.a,
        M: int = _DEFAULTS.M,
        delay_comp: float | None = _DEFAULTS.delay_comp,
        pm_deg: float = _DEFAULTS.pm_deg,
    ) -> None:
        if not T_s > 0.0:
            raise ValueError(f"T_s must be > 0, got {T_s}")
        if not U_h > 0.0:
            raise ValueError(f"U_h must be > 0, got {U_h}")
        if not 1 <= M <= CIC_MAX:
            raise ValueError(f"M (the CIC delay) must be in 1 .. {CIC_MAX}, got {M}")
        if not motor.L_q > motor.L_d:
            raise ValueError(
                f"square-wave injection needs saliency L_q > L_d, got "
                f"L_d={motor.L_d}, L_q={motor.L_q}"
            )
        self.motor = motor
        self.T_s = T_s
        self.cic = cic
        self.U_h = U_h
        self.R = 2  # PWM periods per injection period (500 Hz at 1 kHz)
        self.M = M
        self.delay_comp = DELAY_COMP_PERIODS if delay_comp is None else float(delay_comp)
        self.pm_deg = pm_deg
        if a is None:
            a = observer_pole(T_s, cic, M, self.delay_comp, pm_deg)
        self._t_comp = self.delay_comp * T_s
        self.observer = LuenbergerObserver(motor.J, motor.n_p, a, T_s)
        #: err = Im(E conj u)/|E| * _k_err ~ dtheta
        self._k_err = motor.L_q / (motor.L_q - motor.L_d)
        self._interp = [CicInterpolator(M, self.R) for _ in range(4)]
        # Protocol attributes
        self.theta_hat = 0.0
        self.w_hat = 0.0
        self.err = 0.0
        self.i_alpha_f = 0.0
        self.i_beta_f = 0.0
        #: interpolated (or held) position quadrature signal (A), Xue Figs. 11-12
        self.e_alpha = 0.0
        self.e_beta = 0.0
        self._u_next = (0.0, 0.0)
        self._sg0 = self._sg1 = self._sg2 = 0.0  # injection signs, see _reset_state
        self._n_tot = 0  # samples since construction
        self._ia1 = self._ib1 = 0.0  # current sample k-1 (A)
        self._id1 = self._iq1 = 0.0  # samples k-1, k-2 in the estimated rotor frame (A)
        self._id2 = self._iq2 = 0.0
        self._reset_state()

    def gains(self) -> dict[str, float]:
        """Every gain of the estimator: observer pole and gains, phase margin, delays."""
        obs = self.observer
        pm, w_c = loop_margins(obs.a, self.T_s, self.cic, self.M, self.delay_comp)
        return {
            "U_h": self.U_h,
            "a": obs.a,
            "K_1": obs.K_1,
            "K_2": obs.K_2,
            "K_3": obs.K_3,
            "J": obs.J,
            "pm_target_deg": self.pm_deg,
            "pm_deg": pm,
            "w_c": w_c,
            "delay_comp_periods": self.delay_comp,
            "loop_latency_periods": LOOP_LATENCY_PERIODS
            if self.cic
            else LOOP_LATENCY_PERIODS - 0.5,
            "cic_M": float(self.M) if self.cic else 0.0,
        }

    # -- state ---------------------------------------------------------------

    def _reset_state(self) -> None:
        self._n = 0  # samples since reset
        # injections computed at the last three updates (sign, cos phi, sin phi):
        # 0 -> period k (in flight), 1 -> period k-1 (just completed), 2 -> period k-2.
        # The sign keeps alternating across a reset (the inverter keeps injecting).
        self._c0 = self._c1 = self._c2 = 1.0
        self._s0 = self._s1 = self._s2 = 0.0
        self._ha1 = self._hb1 = 0.0  # HF response of period k-2 (eq. 7)
        self._env_n = 0  # envelope samples since reset
        self._held = (0.0, 0.0, 1.0, 0.0)
        for f in self._interp:
            f.reset()

    def reset(self, theta0: float) -> None:
        """Restart from angle ``theta0`` (rad) at zero speed; flush the envelope pipeline."""
        self.observer.reset(theta0, 0.0, 0.0)
        self.theta_hat = self.observer.theta_hat
        self.w_hat = 0.0
        self.err = 0.0
        self._n_tot = 0  # the stored rotor-frame samples refer to the old angle
        self._reset_state()

    # -- per step ------------------------------------------------------------


def create(motor: MotorModel, T_s: float, cic: bool = True, **options: Any) -> SquareWaveEstimator:
    """Build the ``square-wave`` (``cic=True``) or ``square-wave-nocic`` estimator.

    ``options`` are the keyword parameters of :class:`SquareWaveEstimator`
    (``U_h``, ``a``, ``M``, ``delay_comp``, ``pm_deg``); unknown keys raise ``TypeError``.
    """
    return SquareWaveEstimator(motor, T_s, cic=cic, **options)
