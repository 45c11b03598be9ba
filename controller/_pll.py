"""PI-type position observer (phase-locked loop), Wen Fig. 4."""

from __future__ import annotations

import math

import numpy as np

from controller._design import LoopResponse, largest_with_margin

_TWO_PI = 2.0 * math.pi


class PositionObserver:
    """PI regulator driving the normalised position error to zero, then an integrator.

    Kept in Python as a public block a user may call per period (a plug-in's
    estimator composes it; the core calls a plug-in's Python each period), and
    as the tests' oracle of ``controller/core/cc_pll.c``, which the controller's
    one engine runs with the same operations (``tests/oracle/``, tolerance 0).

    Wen Fig. 4 (and below eqs. (9), (28), (34)): ``w_hat = k_p err + k_i int(err)``,
    ``theta_hat = int(w_hat)``. With the error normalised to ``err ~ theta -
    theta_hat`` the loop is ``s^2 + k_p s + k_i`` (ignoring the demodulation
    filters); the gains put both poles at ``-w_o``: ``k_p = 2 w_o``, ``k_i = w_o^2``.
    Because the demodulated error is normalised by the HF current amplitudes,
    the bandwidth does not depend on ``V_h`` or on the motor. How ``w_o`` is
    chosen for each demodulator, with its filters in the loop:
    :func:`design_bandwidth`.

    Timing: :attr:`theta_hat` is the estimate at the sample instant ``k T_s``;
    :meth:`update` with the error of sample ``k`` moves it to ``(k+1) T_s``
    (forward Euler with the updated speed). Its transfer function from the
    error to the angle is :func:`open_loop`.

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

    def update(self, err: float, accel: float = 0.0) -> None:
        """Take the error of sample ``k``; advance ``theta_hat`` to ``(k+1) T_s``.

        ``accel`` (rad/s^2): a known acceleration fed forward into the integral, so
        that the speed follows it without the error ``accel / w_o^2`` the loop
        needs otherwise. It is an input beside the loop, not in it: the transfer
        function from ``err`` to the angle (:func:`open_loop`) stays what it is.
        """
        self.w_i += self.T_s * self.k_i * err
        if accel != 0.0:
            self.w_i += self.T_s * accel
        self.w_hat = self.k_p * err + self.w_i
        self.theta_hat = (self.theta_hat + self.T_s * self.w_hat) % _TWO_PI

    def reset(self, theta0: float, w0: float = 0.0) -> None:
        """Restart at angle ``theta0`` (rad) and speed ``w0`` (rad/s)."""
        self.theta_hat = theta0 % _TWO_PI
        self.w_hat = w0
        self.w_i = w0


def open_loop(w_o: float, T_s: float, w: np.ndarray) -> np.ndarray:
    """Transfer function of :class:`PositionObserver` from ``err(k)`` to ``theta_hat(k)``.

    From :meth:`PositionObserver.update`: ``W_i = T k_i E / (1 - z^-1)``,
    ``W = k_p E + W_i`` and ``(z - 1) Theta = T W``, so::

        O(z) = T (k_p + T k_i z / (z - 1)) / (z - 1)

    with its one period of delay (the error of sample ``k`` moves the angle
    of sample ``k + 1``), evaluated at ``z = e^{j w T_s}``.
    """
    z = np.exp(1j * np.asarray(w, float) * T_s)
    return T_s * (2.0 * w_o + T_s * w_o * w_o * z / (z - 1.0)) / (z - 1.0)


def design_bandwidth(
    chain: LoopResponse, T_s: float, pm_deg: float, w_c_max: float
) -> tuple[float, float, float]:
    """PLL bandwidth ``w_o`` from a phase-margin target with the demodulator's filters in the loop.

    The loop is ``L = O(z) G(z)``: :func:`open_loop` and ``chain``, the
    demodulator's response from ``theta_hat`` to ``err`` (its in-loop
    filters). ``w_o`` is the largest bandwidth that keeps

    1. the phase margin at ``pm_deg`` or more, and
    2. the gain crossover at or below ``w_c_max``, the corner of the
       demodulation low-pass filter: above it the error signal is, by that
       filter's design (Wen Sec. 3.2), ripple at twice the injection
       frequency and not position, so a faster loop would only pass that
       ripple to the angle. This bound matters only for a demodulator with
       no filter in its loop (tt-ab).

    With ``k_p = 2 w_o``, ``k_i = w_o^2`` and nothing else in the loop the
    margin is 76 degrees whatever ``w_o``, so the filters and the delays
    alone take the margin down to the target.

    Returns
    -------
    w_o, pm, w_c : float
        Bandwidth (rad/s), achieved phase margin (deg) and crossover (rad/s).
    """
    return largest_with_margin(
        lambda w_o: lambda w: open_loop(w_o, T_s, w) * chain(w),
        1e-3 / T_s * 1e-2,
        0.3 / T_s,
        0.999 * math.pi / T_s,
        2,
        pm_deg,
        w_c_max,
    )
