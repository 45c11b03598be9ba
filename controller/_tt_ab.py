"""TT current self-demodulation in the alpha-beta axes (Wen Sec. 4.2).

The BPF of eq. (11) extracts the HF current in alpha-beta; with eq. (23)-(24)
(``A = w_h t - pi/2``, ``B = -w_h t + 2 theta_e + pi/2``, ``I_n > 0`` as derived
in :mod:`controller._rotating`) the triangular transform gives

    LPF(i_ah i_bh)              = I_p I_n sin(2 theta_e)            (25)-(26)
    LPF((i_ah^2 - i_bh^2) / 2)  = I_p I_n cos(2 theta_e)            (27)

and the heterodyne error

    f = I_p I_n [sin 2theta_e cos 2theta_hat - cos 2theta_e sin 2theta_hat]
      = I_p I_n sin(2 dtheta)                                       (28)

(eq. (28) as printed has ``+`` between the two products; the identity needs
``-``). The normalised error ``err = f / (2 I_p I_n)`` drives the PI
observer (Fig. 4). Here the negative sequence sits at ``-(w_h - 2 w_e)``
and the two products vary at ``2 w_e``, so the BPF and LPF phase shifts do
not cancel when the rotor turns (eqs. 29-30): the error depends on speed.

Time stamps: ``err`` and ``theta_hat`` refer to the sample instant ``k T_s``.
"""

from __future__ import annotations

from typing import Any

from controller._filters import Biquad2, FirstOrder2
from controller._params import MotorModel
from controller._rotating import RotatingHFEstimator, RotatingInjectionPars


class TTABEstimator(RotatingHFEstimator):
    """Rotating injection with TT demodulation in alpha-beta (Wen eqs. 23-28)."""

    IN_LOOP = "none"

    def __init__(self, motor: MotorModel, T_s: float, pars: RotatingInjectionPars) -> None:
        super().__init__(motor, T_s, pars)
        self._bpf = Biquad2(*self.bpf_z)
        self._lpf = FirstOrder2(*self.lpf_z)
        self._inv_norm = 1.0 / (2.0 * self.I_p * self.I_n)
        self._floor = 0.1 * self.I_p * self.I_n

    def _reset_filters(self) -> None:
        self._bpf.reset()
        self._lpf.reset()


def create(motor: MotorModel, T_s: float, **options: Any) -> TTABEstimator:
    """Build the ``tt-ab`` estimator; ``options`` are fields of :class:`RotatingInjectionPars`."""
    return TTABEstimator(motor, T_s, RotatingInjectionPars(**options))
