"""Rotating HF voltage injection (Wen Sec. 2), shared by the three demodulators.

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
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from controller._api import EstimatorInput
from controller._filters import BPF_WEN, HPF_WEN, LPF_WEN, discretize
from controller._params import MotorModel
from controller._pll import PositionObserver

_TWO_PI = 2.0 * math.pi


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
    w_o : float
        Position-observer (PLL) bandwidth (rad/s); 0 freezes the observer.
        The demodulation chain bounds it: the BPF passes the phase
        modulation of each sequence through its envelope, a pole at half its
        bandwidth (314 rad/s for eq. 11), and the LPF (eq. 13) adds one at
        628 rad/s. With ``k_p = 2 w_o``, ``k_i = w_o^2`` the default
        ``2 pi 20`` crosses over at about 210 rad/s with 21 degrees of phase
        margin; 30 Hz loses it (6 degrees), lower values track accelerations
        worse (steady error ``a / w_o^2`` for an angular acceleration ``a``).
    normalise : str
        ``"model"``: divide the demodulated signal by the model amplitudes
        (``2 I_p I_n`` or ``2 I_n`` from :func:`hf_amplitudes`);
        ``"measured"``: by the amplitudes measured from the same signals
        (the quadrature component is demodulated with the same LPF, and
        ``hypot`` of the two is ``I_p I_n`` or ``I_n``), floored at 10 % of
        the model value.
    bpf, hpf, lpf : tuple
        Continuous prototypes ``(b, a)``; defaults Wen eqs. (11)-(13). If
        ``f_h`` is not 500 Hz and ``bpf`` is the default, the BPF centre
        moves to ``2 pi f_h`` with the same bandwidth. The BPF and HPF are
        pre-warped at ``w_h`` (where Wen Fig. 5 states their phase), the LPF
        at its corner.
    """

    V_h: float = 50.0
    f_h: float = 500.0
    w_o: float = 2.0 * math.pi * 20.0
    normalise: str = "model"
    bpf: tuple[tuple[float, ...], tuple[float, ...]] = BPF_WEN
    hpf: tuple[tuple[float, ...], tuple[float, ...]] = HPF_WEN
    lpf: tuple[tuple[float, ...], tuple[float, ...]] = LPF_WEN


def hf_amplitudes(motor: MotorModel, V_h: float, w_h: float, T_s: float) -> tuple[float, float]:
    """Model amplitudes ``(I_p, I_n)`` (A) of the sampled HF current.

    Wen eqs. (5)-(6) with the derived sign ``I_n ~ (L_q - L_d) > 0`` and the
    zero-order-hold factor ``x/sin(x)``, ``x = w_h T_s / 2`` (module docstring).
    """
    x = 0.5 * w_h * T_s
    kappa = x / math.sin(x) if x > 0.0 else 1.0
    k = kappa * V_h / (2.0 * w_h * motor.L_d * motor.L_q)
    return k * (motor.L_d + motor.L_q), k * (motor.L_q - motor.L_d)


class RotatingHFEstimator:
    """Common part: injection, discrete filters, observer, estimator attributes.

    Subclasses implement :meth:`update` (demodulation) and use
    ``self.pll``, ``self._bpf_b/_bpf_a`` etc. What each quantity refers to
    in time: ``theta_hat`` and ``err`` belong to the sample instant
    ``k T_s`` of the last :meth:`update`; :meth:`injection` is the voltage
    averaged over period ``k + 1``.

    Parameters
    ----------
    motor : MotorModel
        The controller's motor model (for ``I_p``, ``I_n``).
    T_s : float
        Sampling period (s).
    pars : RotatingInjectionPars
        Injection, filter and observer settings.
    """

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
        self.bpf_z = discretize(b, a, T_s, self.w_h)
        self.hpf_z = discretize(*pars.hpf, T_s, self.w_h)
        a_l = pars.lpf[1]
        w_lpf = abs(a_l[-1] / a_l[0]) if len(a_l) == 2 else self.w_h / 5.0
        self.lpf_z = discretize(*pars.lpf, T_s, w_lpf)
        if pars.normalise not in ("model", "measured"):
            raise ValueError(f"normalise must be 'model' or 'measured', got {pars.normalise!r}")
        self.measured = pars.normalise == "measured"
        self.pll = PositionObserver(pars.w_o, T_s)
        self.theta_hat = 0.0
        self.w_hat = 0.0
        self.err = 0.0
        self.f = 0.0
        self.i_alpha_f = 0.0
        self.i_beta_f = 0.0
        self._k = 0

    def update(self, x: EstimatorInput) -> None:  # pragma: no cover - abstract
        """Take sample ``k`` and advance the estimate."""
        raise NotImplementedError

    def _publish(self, th: float, f: float, err: float, i_af: float, i_bf: float) -> None:
        """End of every demodulator's update: outputs of sample ``k``, then the observer step."""
        self.i_alpha_f = i_af
        self.i_beta_f = i_bf
        self.theta_hat = th
        self.f = f
        self.err = err
        self.pll.update(err)
        self.w_hat = self.pll.w_hat

    def injection(self) -> tuple[float, float]:
        """HF voltage (V) for period ``k + 1``: eq. (3) at ``t = (k + 1.5) T_s``."""
        ph = (self._k + 1.5) * self.wT
        return self.V_h * math.cos(ph), self.V_h * math.sin(ph)

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
