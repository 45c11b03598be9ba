"""TT current self-demodulation in the estimated d-q axes (Wen Sec. 4.3, the paper's method).

The measured current is rotated into the estimated frame, the BPF of eq.
(11) extracts the HF part there, and one product and one LPF (eq. 13) give
the error, Wen eqs. (31)-(34):

    i_dh i_qh = I_p^2/2 sin 2A + I_n^2/2 sin 2B + I_p I_n sin(A + B),
    A + B = 2 (theta_e - theta_hat)                               (32)-(33)
    LPF(i_dh i_qh) = I_p I_n sin(2 dtheta)                        (34)

with ``I_n > 0`` as derived in :mod:`controller._rotating`. In the estimated
frame the positive and negative sequences sit at ``+(w_h - w_e)`` and
``-(w_h - w_e)`` (Table 2), so the phase shifts of the BPF (odd in
frequency) and of any pure delay cancel in ``A + B``; at constant speed the
product's useful part is DC, so the LPF adds no phase (Sec. 4.3). The
normalised error ``err = LPF(i_dh i_qh) / (2 I_p I_n)`` (about ``dtheta``)
drives the PI position observer (Fig. 4). The fundamental current for the
current loop is the estimated-frame current minus the BPF output, rotated
back to alpha-beta.

At speed the two sequences sit ``w_e`` away from the BPF's centre: with
``bpf_tracking`` (:class:`controller.RotatingInjectionPars`) the centre
follows them, at ``|w_h - w_t|`` with the tracker's speed state ``w_t``
(the PLL's integral ``w_i``, or the mechanical observer's ``w_hat``),
recomputed every period (:func:`controller._filters.bandpass_coefficients`).

Time stamps: the sample ``k`` is rotated with ``theta_hat`` at ``k T_s``;
``err`` and ``theta_hat`` refer to ``k T_s``.
"""

from __future__ import annotations

from typing import Any

from controller._filters import Biquad2, FirstOrder, FirstOrder2
from controller._params import MotorModel
from controller._rotating import RotatingHFEstimator, RotatingInjectionPars


class TTDQEstimator(RotatingHFEstimator):
    """Rotating injection with TT demodulation in the estimated d-q axes (Wen eqs. 31-34)."""

    IN_LOOP = "bpf+lpf"
    ACCEL_FF = True

    def __init__(self, motor: MotorModel, T_s: float, pars: RotatingInjectionPars) -> None:
        super().__init__(motor, T_s, pars)
        self._bpf = Biquad2(*self.bpf_z)
        self._lpf = FirstOrder(*self.lpf_z)
        self._lpf2 = FirstOrder2(*self.lpf_z)
        self._inv_norm = 1.0 / (2.0 * self.I_p * self.I_n)
        self._floor = 0.1 * self.I_p * self.I_n
        # the tracking BPF's lowest centre: a speed of 3/4 of the injection frequency is
        # outside any use of an injection estimator, and the bilinear map needs w_0 > 0
        self._w0_min = 0.25 * self.w_h

    def _reset_filters(self) -> None:
        self._bpf.reset()
        self._lpf.reset()
        self._lpf2.reset()


def create(motor: MotorModel, T_s: float, **options: Any) -> TTDQEstimator:
    """Build the ``tt-dq`` estimator; ``options`` are fields of :class:`RotatingInjectionPars`."""
    return TTDQEstimator(motor, T_s, RotatingInjectionPars(**options))
