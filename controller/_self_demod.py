"""HF response current self-demodulation: Wen's reference [27] (Li et al. 2021), reconstructed.

A reconstruction, not Li et al.'s code: the bench has only what Wen et al.
say of [27], and builds the simplest demodulator that does all of it.

What Wen says (Secs. 1, 4.2 with Fig. 7, 4.4 with Fig. 11, Table 3):

- it needs no auxiliary demodulation signal, yet still separates the
  positive and negative sequences (Sec. 1, Fig. 7);
- four multiplications and four additions (Sec. 4.4);
- its error is 0 at standstill and ``(phi_p^sum + phi_n^sum) / 2`` at speed,
  correlated with speed (Table 3; Table 6's error grows with speed).

What is built, on the BPF of eq. (11) and the LPF of eq. (13) and nothing
else (the HPF of eq. (12) is not used):

1. The BPF extracts the HF current ``d`` in alpha-beta (eq. 7/18), as
   tt-ab does; ``i - d`` is the fundamental current for the current loops.
2. Separation without a demodulation signal (assumed: a quadrature twin of
   the BPF, as the positive/negative sequence calculators of grid
   synchronisation build from a second-order generalised integrator):
   ``q = (s / w_h) d``, the BPF times ``s / w_h``, discretised with the same
   bilinear map pre-warped at ``w_h``. At ``+w_h``, ``q = +j d``; at ``-w_h``,
   ``q = -j d``; so ``i_p = (d - j q) / 2`` and ``i_n = (d + j q) / 2`` are the
   two sequences, exactly at standstill, and with a real gain (no phase) at
   any frequency (:func:`controller._rotating.separation_gains`). The
   derivative form, not ``w_h / s`` (the generalised integrator's
   quadrature output), because it keeps the BPF's zero at DC: the
   fundamental current, amperes against ``I_n``'s tens of milliamperes,
   does not leak into the separation. Four additions.
3. Self-demodulation (assumed): the positive sequence is the negative's
   demodulation signal. With eq. (18),
   ``i_p i_n = I_p I_n exp(j(2 theta_e + phi_p + phi_n))``: the carrier
   ``w_h t`` and the ``+-pi/2`` cancel, and what is left is the rotor angle
   with the sum of the two sequences' phase shifts. Four multiplications
   (the complex product), as Sec. 4.4 counts.
4. The heterodyne with ``2 theta_hat`` that every method's position observer
   has (eqs. 9, 28): ``f = Im{i_p i_n exp(-j 2 theta_hat)} = I_p I_n sin(2 dtheta
   + phi_p + phi_n)``, before the LPF (assumed), so that at constant speed
   the LPF sees a constant and adds no phase (Table 3 gives [27] no LPF
   term, unlike the alpha-beta TT). ``err = LPF(f) / (2 I_p I_n)`` drives the
   PI observer (Fig. 4).

Hence the closed form of Table 3: the observer settles at ``theta_hat =
theta_e + (phi_p + phi_n) / 2`` (eq. 30's form). In alpha-beta the positive
sequence sits at ``+w_h`` and the negative at ``-w_h + 2 w_e`` (Table 2): at
standstill the BPF's phases (odd in frequency) and any pure delay cancel;
at speed they do not, and the error follows the speed.

The PLL is designed as the other demodulators' (:mod:`controller._rotating`):
``theta_hat`` enters after the BPF and the separation and before the LPF,
so its in-loop response is ``|H_B(w_h) H_B(-w_h)| LPF(z)`` (``"pn+lpf"``).

Time stamps: ``err`` and ``theta_hat`` refer to the sample instant ``k T_s``.
"""

from __future__ import annotations

from typing import Any

from controller._filters import Biquad2, FirstOrder, FirstOrder2, discretize
from controller._params import MotorModel
from controller._rotating import RotatingHFEstimator, RotatingInjectionPars


class SelfDemodEstimator(RotatingHFEstimator):
    """Rotating injection with sequence separation and self-demodulation ([27], reconstructed)."""

    IN_LOOP = "pn+lpf"

    def __init__(self, motor: MotorModel, T_s: float, pars: RotatingInjectionPars) -> None:
        super().__init__(motor, T_s, pars)
        b, a = self.bpf_s
        #: The BPF's quadrature twin ``(s / w_h) H_B(s)``, discrete.
        self.quad_z = discretize((*(c / self.w_h for c in b), 0.0), a, T_s, self.w_h)
        self._bpf = Biquad2(*self.bpf_z)
        self._quad = Biquad2(*self.quad_z)
        self._lpf = FirstOrder(*self.lpf_z)
        self._lpf2 = FirstOrder2(*self.lpf_z)
        self._inv_norm = 1.0 / (2.0 * self.I_p * self.I_n)
        self._floor = 0.1 * self.I_p * self.I_n

    def _reset_filters(self) -> None:
        self._bpf.reset()
        self._quad.reset()
        self._lpf.reset()
        self._lpf2.reset()


def create(motor: MotorModel, T_s: float, **options: Any) -> SelfDemodEstimator:
    """Build the ``self-demod`` estimator; ``options`` are fields of :class:`RotatingInjectionPars`."""
    return SelfDemodEstimator(motor, T_s, RotatingInjectionPars(**options))
