"""Estimated position feedback current demodulation: Wen's reference [25] (Mai et al. 2022),
reconstructed.

A reconstruction, not Mai et al.'s code: the bench has only what Wen et al.
say of [25], and builds the simplest demodulator that does all of it.

What Wen says (Secs. 1, 4.2 with Fig. 7, 4.4 with Fig. 11, Table 3, Sec. 5):

- it demodulates in the estimated d-q axes (Sec. 5: "[23] and [25] ... are
  demodulation methods for estimating the d-q axis") with the estimated
  position fed back, to remove the effect of speed on the error (Sec. 1);
- it constructs two demodulation signals, to separate the positive and
  negative sequences and to compensate the position error (Sec. 1, Fig. 7);
- two demodulation signals, two filters, 8 multiplications and 5 additions
  (Sec. 4.4);
- its error is 0 at standstill and at speed, without speed correlation
  (Table 3).

What is built, on the BPF of eq. (11) and the LPF of eq. (13) (the HPF of
eq. (12) is not used):

1. The measured current is rotated into the estimated frame by
   ``theta_hat`` (the estimated position fed back; 4 multiplications) and the
   BPF extracts its HF part there, as tt-dq does (eq. 19/22); the rest is
   the fundamental current for the current loops.
2. The two demodulation signals (assumed): ``exp(-j psi)`` and ``exp(+j psi)``
   with ``psi = w_h t - theta_hat``, the phase of the positive sequence in the
   estimated frame. ``i_dqh exp(-j psi)`` turns the positive sequence into a
   constant, ``i_dqh exp(+j psi)`` the negative; the two products share the
   same four real products (4 multiplications: 8 with the rotation, as
   Sec. 4.4 counts). Each is low-passed by the LPF of eq. (13) (the two
   filters), which separates the sequences:
   ``P_p = I_p exp(j(phi_p - pi/2))`` and
   ``P_n = I_n exp(j(2 dtheta + phi_n + pi/2))``.
3. Position error compensation (assumed): the positive sequence carries the
   phase shift ``phi_p`` that the same non-ideal factors give the
   negative's, with the opposite sign, because in the estimated frame the
   two sit at ``+(w_h - w_e)`` and ``-(w_h - w_e)`` (Table 2). The product
   ``P_p P_n = I_p I_n exp(j(2 dtheta + phi_p + phi_n))`` removes it:
   ``f = Im{P_p P_n} = I_p I_n sin(2 dtheta)`` at every constant speed (2
   multiplications), and ``err = f / (2 I_p I_n)`` drives the PI observer
   (Fig. 4).

Hence the closed form of Table 3: zero error at standstill and at speed.
What distinguishes it from tt-dq in the bench is its cost (two
demodulation signals, two filters, ten multiplications against one) and
what the separation leaves: each LPF passes a tenth of the other sequence
at ``2 (w_h - w_e)``.

The PLL is designed as the other demodulators' (:mod:`controller._rotating`):
``theta_hat`` enters before the BPF (the rotation) and after it (the
demodulation signals); the direct parts cancel in ``P_p P_n`` and what is
left is tt-dq's in-loop response, the two sequences' envelopes through the
BPF, then the LPF (``"bpf+lpf"``).

Time stamps: the sample ``k`` is rotated with ``theta_hat`` at ``k T_s`` and
demodulated with ``w_h t`` at ``t = k T_s``; ``err`` and ``theta_hat`` refer to
``k T_s``.
"""

from __future__ import annotations

import math
from typing import Any

from controller._filters import Biquad2, FirstOrder2
from controller._params import MotorModel
from controller._rotating import RotatingHFEstimator, RotatingInjectionPars

_TWO_PI = 2.0 * math.pi


class EPFEstimator(RotatingHFEstimator):
    """Rotating injection with estimated-position-feedback demodulation ([25], reconstructed)."""

    IN_LOOP = "bpf+lpf"

    def __init__(self, motor: MotorModel, T_s: float, pars: RotatingInjectionPars) -> None:
        if pars.bpf_tracking:
            raise ValueError("bpf_tracking is a tt-dq option (epf keeps the BPF of eq. 11 fixed)")
        super().__init__(motor, T_s, pars)
        self._bpf = Biquad2(*self.bpf_z)
        self._lpf_p = FirstOrder2(*self.lpf_z)
        self._lpf_n = FirstOrder2(*self.lpf_z)
        self._lpf_m = FirstOrder2(*self.lpf_z)
        self._inv_norm = 1.0 / (2.0 * self.I_p * self.I_n)
        self._floor = 0.1 * self.I_p * self.I_n

    def _reset_filters(self) -> None:
        self._bpf.reset()
        self._lpf_p.reset()
        self._lpf_n.reset()
        self._lpf_m.reset()


def create(motor: MotorModel, T_s: float, **options: Any) -> EPFEstimator:
    """Build the ``epf`` estimator; ``options`` are fields of :class:`RotatingInjectionPars`."""
    return EPFEstimator(motor, T_s, RotatingInjectionPars(**options))
