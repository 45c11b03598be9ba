"""Conventional demodulation: synchronous-frame high-pass filter (SFHF), Wen Sec. 2.3.

1. BPF, eq. (11), extracts the HF current in alpha-beta, eq. (7).
2. Rotating it by ``exp(-j w_h t)`` makes the positive sequence DC; the HPF
   of eq. (12) removes it, leaving the negative sequence at
   ``-2 w_h + 2 w_e``; rotating back by ``exp(j w_h t)`` gives
   ``i_ab,h^n = I_n exp(j(-w_h t + 2 theta_e + pi/2))`` (Fig. 3).
3. Heterodyne, eq. (9), with the derived sign ``I_n > 0``
   (:mod:`controller._rotating`):

       f = Im{ i_ab,h^n exp(-j(2 theta_hat - w_h t + pi/2)) }
         = -[i_ah^n cos(2 theta_hat - w_h t) + i_bh^n sin(2 theta_hat - w_h t)]
         = I_n sin(2 dtheta).

   Eq. (9) as printed has no minus sign; it is consistent only with the
   printed eq. (6), whose ``I_n`` has the opposite sign.
4. LPF, eq. (13), removes the residual ripple; ``err = f / (2 I_n)`` drives
   the PI observer (Fig. 4).

The BPF and HPF phase shifts of the negative sequence are not compensated
(Table 3, "conventional method"): the error has an offset that grows with
speed.

Time stamps: ``t = k T_s`` (the sample instant) in every ``w_h t``; ``err``
and ``theta_hat`` refer to ``k T_s``.
"""

from __future__ import annotations

from typing import Any

from controller._filters import Biquad2, FirstOrder, FirstOrder2
from controller._params import MotorModel
from controller._rotating import RotatingHFEstimator, RotatingInjectionPars


class SFHFEstimator(RotatingHFEstimator):
    """Rotating injection with SFHF separation and heterodyne demodulation (Wen eq. 9)."""

    IN_LOOP = "lpf"

    def __init__(self, motor: MotorModel, T_s: float, pars: RotatingInjectionPars) -> None:
        super().__init__(motor, T_s, pars)
        self._bpf = Biquad2(*self.bpf_z)
        self._hpf = FirstOrder2(*self.hpf_z)
        self._lpf = FirstOrder(*self.lpf_z)
        self._lpf2 = FirstOrder2(*self.lpf_z)
        self._inv_norm = 1.0 / (2.0 * self.I_n)
        self._floor = 0.1 * self.I_n

    def _reset_filters(self) -> None:
        self._bpf.reset()
        self._hpf.reset()
        self._lpf.reset()
        self._lpf2.reset()


def create(motor: MotorModel, T_s: float, **options: Any) -> SFHFEstimator:
    """Build the ``sfhf`` estimator; ``options`` are fields of :class:`RotatingInjectionPars`."""
    return SFHFEstimator(motor, T_s, RotatingInjectionPars(**options))
