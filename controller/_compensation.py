"""What a real drive does against its inverter and sensors: dead-time feed-forward,
cross-saturation angle correction, current-offset calibration.

Every part is off in a bare :class:`CompensationPars`; whoever configures
the controller switches each on for the hardware it drives, as a drive's
firmware is configured for its own bridge, sensors and motor (a bench
scenario does so where its plant has dead time or device drops, current
offsets or cross-saturation, so the ideal plant's controller stays the
papers'). The controller never reads the plant's settings: each part works
from the controller's own idea of its hardware (``t_dead``, device drops,
ADC resolution) and of its motor (:class:`~controller.MotorModel`,
``k_dq``).

Dead time (:func:`dead_time_voltage`, :class:`DeadTimeCompensator`)
-------------------------------------------------------------------
During the dead time both switches of a leg are off and the phase current
flows through a diode: the lower one if the current flows into the machine
(``i_x > 0``), the upper one otherwise. Of the two edges of a period only
the one that turns on the switch opposite the conducting diode is delayed,
so the mean pole voltage loses ``t_dead / T_s * u_dc`` against the
current's direction. Device drops add the conduction losses of whichever
device carries the current: for ``i_x > 0`` the upper transistor (``v_ce``)
for the fraction ``d_x`` of the period and the lower diode (``v_f``) for
``1 - d_x``; for ``i_x < 0`` the upper diode and the lower transistor. The
mean pole-voltage error is therefore::

    i_x > 0:  -t_dead/T_s u_dc - (d_x v_ce + (1 - d_x) v_f)
    i_x < 0:  +t_dead/T_s u_dc + (d_x v_f + (1 - d_x) v_ce)

The compensation adds the opposite to each leg's duty, ``-du_x / u_dc``,
after the space-vector modulation, so the current PIs never integrate it.
Their anti-windup sees only their own output, as with the HF injection.

The current's sign comes from what the controller expects the current to
be in the period the duties act in, not from a noisy sample: the current
reference, rotated to the phases with the angle of that period's mid-point
(``theta_hat + 1.5 T_s w_hat``), plus the injection's HF current where the
estimator predicts it. The HF current matters: at no load it is all the
current there is, so it decides the sign. The dead-time error then
follows it at the HF, distorting the very response the estimator
demodulates. The sign is smoothed near zero. Over one PWM period the
current moves by a ripple ``i_h``, and the error of that period is the
mean of ``sign(i + i_h)`` over it, which gives the smoothing law:

- rotating injection with the HF current predicted (the estimator's
  ``hf_current_next``): the HF sinusoid moves by ``+-I_p w_h T_s / 2``
  about its mid-point value within the period (38 mA on the Wen motor),
  nearly linearly, so the law is ``i / I_h`` with ``I_h = I_p w_h T_s / 2``;
- rotating injection without that prediction: the mean over an HF period
  of a sinusoid of amplitude ``I_h = I_p``, ``(2/pi) asin(i / I_h)`` (the
  negative sequence, ``I_n``, is 6 times smaller on the Wen motor);
- square-wave injection: a triangle of amplitude ``I_h = U_h T_s / (2
  L_d)`` within the period itself, ``i / I_h``;
- each clipped to +-1 outside ``|i| < I_h``. Without injection there is
  only the PWM ripple, which shrinks with the voltage, so the sign is hard
  unless ``i_band`` is given.

Cross-saturation (:func:`cross_saturation_offset`)
--------------------------------------------------
With a cross-coupled incremental inductance ``L_dq`` the HF response sees
the matrix ``[[L_d, L_dq], [L_dq, L_q]]``. In a frame rotated by ``delta``
from the rotor's, its off-diagonal term is ``(L_q - L_d)/2 sin 2 delta +
L_dq cos 2 delta``. Every HF estimator drives that term (its quadrature
response) to zero, so it locks at ``delta = -1/2 atan(2 L_dq / (L_q -
L_d))``: ``theta_hat = theta_e + delta``. The correction adds ``-delta``
back. The model is the simplest that is consistent with a flux linkage,
``psi_d = L_d i_d + psi_f + k_dq i_q^2 / 2`` and ``psi_q = L_q i_q + k_dq
i_d i_q``, so ``L_dq = d psi_d / d i_q = d psi_q / d i_d = k_dq i_q``,
with the coefficient ``k_dq`` (H/A) in the controller's
:class:`~controller.MotorModel` (usually negative) and ``i_q`` the
reference.

Offset calibration (:func:`offset_periods`, :class:`OffsetCalibration`)
----------------------------------------------------------------------
At standstill with the PWM disabled no current flows, so the mean of the
samples is each channel's offset. The mean of ``N`` samples has the
standard deviation ``sigma / sqrt(N)``, with ``sigma^2 = sigma_n^2 +
q^2 / 12`` (noise and the rounding of an ADC step ``q``). ``N`` is the
smallest count that brings three standard deviations (99.7 %) below the
tolerance ``e``::

    N = ceil((3 sigma / e)^2)

with ``e = q / 2`` by default (half an ADC step, below the converter's
own rounding: the calibration adds nothing the ADC does not already
have). Without a known ``q``, ``e`` is 0.1 % of the current limit, a
common accuracy class for a drive's current measurement. For a 12-bit
ADC over +-12 A (``q`` = 5.9 mA) with 10 mA of noise, N = 108 (11 ms at
10 kHz), and 3 without the noise. Without dither (noise well below
``q``) the rounding is not averaged away, and the residual is then up to
``q / 2``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from controller._built import _cctl


@dataclass(frozen=True, slots=True)
class CompensationPars:
    """The drive's countermeasures (module docstring); everything off unless switched on.

    Parameters
    ----------
    dead_time : bool
        Feed-forward of the dead-time and device-drop voltage error.
    t_dead : float
        Dead time the controller assumes for its inverter (s).
    v_ce : float
        Transistor on-state drop (V).
    v_f : float
        Diode forward drop (V).
    i_band : float or None
        Smoothing band of the current sign (A); None derives it from the
        estimator's injection (module docstring), 0 gives a hard sign.
    cross_saturation : bool
        Correct the angle by the HF estimators' cross-saturation offset
        (needs ``MotorModel.k_dq``).
    offset_calibration : bool
        Measure the current offsets at standstill, PWM disabled, before
        each start; subtract them from every sample.
    offset_periods : int or None
        Calibration length (PWM periods); None derives it from
        ``current_noise``, ``adc_lsb`` and ``offset_tol``.
    current_noise : float
        Expected rms noise of one current sample (A).
    adc_lsb : float
        Current per ADC step (A); 0 for an ideal converter.
    offset_tol : float or None
        Tolerance on each offset (A), met with 99.7 % confidence; None is
        ``adc_lsb / 2``, or 0.1 % of the current limit without an ``adc_lsb``.
    """

    dead_time: bool = False
    t_dead: float = 0.0
    v_ce: float = 0.0
    v_f: float = 0.0
    i_band: float | None = None
    cross_saturation: bool = False
    offset_calibration: bool = False
    offset_periods: int | None = None
    current_noise: float = 0.0
    adc_lsb: float = 0.0
    offset_tol: float | None = None

    def __post_init__(self) -> None:
        for name in ("t_dead", "v_ce", "v_f", "current_noise", "adc_lsb"):
            v = getattr(self, name)
            if not v >= 0.0:
                raise ValueError(f"CompensationPars.{name} must be >= 0, got {v}")
        if self.i_band is not None and not self.i_band >= 0.0:
            raise ValueError(f"CompensationPars.i_band must be >= 0, got {self.i_band}")
        if self.offset_periods is not None and self.offset_periods < 1:
            raise ValueError(
                f"CompensationPars.offset_periods must be >= 1, got {self.offset_periods}"
            )
        if self.offset_tol is not None and not self.offset_tol > 0.0:
            raise ValueError(f"CompensationPars.offset_tol must be > 0, got {self.offset_tol}")


# ---------------------------------------------------------------------------- dead time


def dead_time_voltage(
    i_x: float,
    u_dc: float,
    d_x: float,
    t_dead: float,
    T_s: float,
    v_ce: float = 0.0,
    v_f: float = 0.0,
) -> float:
    """Mean pole-voltage error of one leg over a period (V), hard current sign (module docstring).

    Zero at ``i_x = 0``.
    """
    if i_x > 0.0:
        return -u_dc * t_dead / T_s - (d_x * v_ce + (1.0 - d_x) * v_f)
    if i_x < 0.0:
        return u_dc * t_dead / T_s + (d_x * v_f + (1.0 - d_x) * v_ce)
    return 0.0


def smooth_sign(i_x: float, i_band: float, sine: bool) -> float:
    """Mean of ``sign(i_x + i_h)`` over one period of a ripple ``i_h`` of amplitude ``i_band``.

    ``sine``: sinusoidal ripple, ``(2/pi) asin(i_x / i_band)``; otherwise
    triangular, ``i_x / i_band``; +-1 outside the band, hard sign if ``i_band`` is 0.
    The core's ``cc_smooth_sign`` (``controller/core/cc_compensation.c``).
    """
    return _cctl.smooth_sign(i_x, i_band, sine)


class DeadTimeCompensator:
    """Duty feed-forward of the expected dead-time and device-drop error.

    Parameters
    ----------
    T_s : float
        PWM period (s).
    t_dead, v_ce, v_f : float
        Dead time (s) and device drops (V) the controller assumes.
    i_band : float
        Smoothing band of the current sign (A).
    sine : bool
        Sinusoidal (True) or triangular ripple law in :func:`smooth_sign`.
    """

    __slots__ = ("T_s", "_k_dt", "i_band", "sine", "t_dead", "v_ce", "v_f")

    def __init__(
        self, T_s: float, t_dead: float, v_ce: float, v_f: float, i_band: float, sine: bool
    ) -> None:
        self.T_s = T_s
        self.t_dead = t_dead
        self.v_ce = v_ce
        self.v_f = v_f
        self.i_band = i_band
        self.sine = sine
        self._k_dt = t_dead / T_s

    # the expected pole-voltage error of a leg and the duties it corrects: the core's
    # cc_deadtime_voltage and cc_deadtime_duties (the controller's step runs them)


# ------------------------------------------------------------------------ cross-saturation


def cross_saturation_offset(k_dq: float, i_q: float, L_d: float, L_q: float) -> float:
    """Angle (rad) the HF estimators lock away from the rotor: ``theta_hat - theta_e``.

    ``-1/2 atan(2 L_dq / (L_q - L_d))`` with ``L_dq = k_dq i_q`` (module docstring); the
    core's ``cc_cross_saturation_offset`` (``controller/core/cc_compensation.c``).
    """
    return _cctl.cross_saturation_offset(k_dq, i_q, L_d, L_q)


# --------------------------------------------------------------------- offset calibration


def offset_periods(current_noise: float, adc_lsb: float, tol: float) -> int:
    """Samples needed for the offset mean to lie within ``tol`` (A) with 99.7 % confidence.

    ``N = ceil((3 sigma / tol)^2)``, ``sigma^2 = current_noise^2 + adc_lsb^2 / 12``; at least 1.
    """
    if not tol > 0.0:
        raise ValueError(f"offset tolerance must be > 0, got {tol}")
    sigma = math.sqrt(current_noise * current_noise + adc_lsb * adc_lsb / 12.0)
    return max(1, math.ceil((3.0 * sigma / tol) ** 2 - 1e-9))


class OffsetCalibration:
    """Mean of the phase-current samples over ``n`` periods with the PWM disabled.

    Parameters
    ----------
    n : int
        Number of samples to average.
    """

    __slots__ = ("_s_a", "_s_b", "_s_c", "k", "n", "o_a", "o_b", "o_c")

    def __init__(self, n: int) -> None:
        self.n = n
        self.o_a = self.o_b = self.o_c = 0.0
        self.k = 0
        self._s_a = self._s_b = self._s_c = 0.0

    @property
    def done(self) -> bool:
        """True once ``n`` samples have been taken."""
        return self.k >= self.n

    def restart(self) -> None:
        """Start a new calibration; the offsets in use stay until it ends."""
        self.k = 0
        self._s_a = self._s_b = self._s_c = 0.0
