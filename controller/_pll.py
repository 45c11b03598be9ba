"""PI-type position observer (phase-locked loop), Wen Fig. 4."""

from __future__ import annotations

import math

import numpy as np

from controller._built import _cctl
from controller._design import LoopResponse, largest_with_margin


class PositionObserver(_cctl.Pll):
    """PI regulator driving the normalised position error to zero, then an integrator.

    A public block a user may call per period (a plug-in's estimator composes
    it): a binding of the core's ``controller/core/cc_pll.c``, the one
    implementation the controller's engine runs too. Its readable Python is
    the tests' oracle (``tests/oracle/blocks.py``, tolerance 0).

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

    Notes
    -----
    Its members, the core struct's fields (design values read-only, states
    writable):

    k_p, k_i, T_s : float
        The gains ``2 w_o``, ``w_o^2`` and the period, read-only.
    theta_hat, w_hat, w_i : float
        The angle (rad, [0, 2 pi)), the speed (rad/s) and the integral state (writable).
    """

    __slots__ = ()

    def __init__(self, w_o: float, T_s: float) -> None:
        super().__init__(2.0 * w_o, w_o * w_o, T_s)

    # update(err, accel=0.0) and reset(theta0, w0=0.0): the core's (_cctl.Pll)


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
