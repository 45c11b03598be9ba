"""PI-type position observer (phase-locked loop), Wen Fig. 4."""

from __future__ import annotations

import math

_TWO_PI = 2.0 * math.pi


class PositionObserver:
    """PI regulator driving the normalised position error to zero, then an integrator.

    Wen Fig. 4 (and below eqs. (9), (28), (34)): ``w_hat = k_p err + k_i int(err)``,
    ``theta_hat = int(w_hat)``. With the error normalised to ``err ~ theta -
    theta_hat`` the loop is ``s^2 + k_p s + k_i`` (ignoring the demodulation
    LPF); the gains put both poles at ``-w_o``: ``k_p = 2 w_o``, ``k_i = w_o^2``.
    Because the demodulated error is normalised by the HF current amplitudes,
    the bandwidth does not depend on ``V_h`` or on the motor.

    Timing: :attr:`theta_hat` is the estimate at the sample instant ``k T_s``;
    :meth:`update` with the error of sample ``k`` moves it to ``(k+1) T_s``
    (forward Euler with the updated speed).

    Parameters
    ----------
    w_o : float
        Observer bandwidth (rad/s); 0 freezes the observer.
    T_s : float
        Sampling period (s).
    """

    __slots__ = ("T_s", "k_i", "k_p", "theta_hat", "w_hat", "w_i")

    def __init__(self, w_o: float, T_s: float) -> None:
        self.k_p = 2.0 * w_o
        self.k_i = w_o * w_o
        self.T_s = T_s
        self.theta_hat = 0.0
        self.w_hat = 0.0
        self.w_i = 0.0

    def update(self, err: float) -> None:
        """Take the error of sample ``k``; advance ``theta_hat`` to ``(k+1) T_s``."""
        self.w_i += self.T_s * self.k_i * err
        self.w_hat = self.k_p * err + self.w_i
        self.theta_hat = (self.theta_hat + self.T_s * self.w_hat) % _TWO_PI

    def reset(self, theta0: float, w0: float = 0.0) -> None:
        """Restart at angle ``theta0`` (rad) and speed ``w0`` (rad/s)."""
        self.theta_hat = theta0 % _TWO_PI
        self.w_hat = w0
        self.w_i = w0
