"""Luenberger position-speed observer with torque feed-forward, Xue et al. Sec. 3.3, eqs. (9)-(12).

The observer is a model of the mechanics (eq. 11) driven by the
electromagnetic torque the controller believes it produces and corrected by
the position error ``e`` (eq. 9)::

    d theta_hat / dt = w_hat + (K_3 / J) e
    d w_hat / dt     = (n_p tau_e + K_2 e + x) / J
    d x / dt         = K_1 e

with electrical angle and speed. The integral state ``x`` converges to
``-n_p tau_L`` (load torque, eq. 12). With ``e = theta_e - theta_hat`` the
loop's characteristic polynomial is ``J s^3 + K_3 s^2 + K_2 s + K_1``
(eq. 10); Xue's gains ``K_1 = a^3 J``, ``K_2 = 3 a^2 J``, ``K_3 = 3 a J``
put the three poles at ``s = -a``. The loop holds three integrators, so a
constant-speed ramp and a constant-acceleration parabola of the angle are
tracked with zero steady-state error, with or without the feed-forward;
with the feed-forward a load-torque step gives (eq. 12)::

    e(t) = -(n_p tau_L / J) (t^2 / 2) exp(-a t)

which decays to zero (peak ``-2 e^-2 n_p tau_L / (J a^2)`` at ``t = 2/a``).

Discretisation: forward Euler at the sampling period ``T_s``,
``X[k+1] = X[k] + T_s (A X[k] + L e[k] + B tau_e[k])``. Its closed-loop
matrix is ``I + T_s A_cl``, so the poles are at ``z = 1 - a T_s`` (triple),
exactly the Euler image of ``s = -a``. The update is explicit: it uses the
error of the present sample, which (in the square-wave estimator) does not
depend on the state being updated.

Transfer functions of the update (:func:`observer_response`), from the
error ``e(k)`` to the states after the step of sample ``k``::

    X     = g_1 E / (1 - z^-1)
    W     = (T z^-1 X + g_2 E) / (1 - z^-1)
    Theta = (T z^-1 W + g_3 E) / (1 - z^-1)

with ``g_i = T_s K_i / J`` (``3 a``, ``3 a^2``, ``a^3`` times ``T_s``): the
inertia cancels, so the loop from the error to the angle does not depend
on ``J`` at all. A wrong ``J`` enters only through the torque
feed-forward, as a disturbance the loop has to reject.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from controller._design import largest_with_margin

_TWO_PI = 2.0 * math.pi


class LuenbergerObserver:
    """Third-order position observer of Xue eqs. (9)-(12), forward Euler.

    Parameters
    ----------
    J : float
        Inertia assumed by the observer (kg m^2).
    n_p : int
        Pole pairs.
    a : float
        Triple closed-loop pole (rad/s), > 0.
    T_s : float
        Sampling period (s).
    b : float or None
        Load pole (rad/s): the poles are then ``-a`` (double) and ``-b``,
        ``K_3 / J = 2 a + b``, ``K_2 / J = a^2 + 2 a b``, ``K_1 / J = a^2 b``.
        None is Xue's triple pole (``b = a``). A ``b`` well below ``a``
        makes the observer a PI tracker of bandwidth ``a`` with a torque
        feed-forward and a slow load estimate: an unmodelled load step is
        then followed as the PI tracker follows any acceleration (steady
        error ``alpha / a^2`` until the load state learns it, at the rate
        ``b``), while the accelerations the torque commands are fed forward.

    Attributes
    ----------
    theta_hat : float
        Estimated electrical angle (rad, wrapped to [0, 2 pi)).
    w_hat : float
        Estimated electrical speed (rad/s), the integrator state of eq. (9)
        (without the proportional ``K_3 e / J`` term).
    x : float
        Integral state ``K_1 int e / J`` (rad/s^2): minus the load's
        electrical deceleration.
    """

    __slots__ = (
        "J",
        "K_1",
        "K_2",
        "K_3",
        "T_s",
        "_g1",
        "_g2",
        "_g3",
        "_gt",
        "a",
        "n_p",
        "theta_hat",
        "w_hat",
        "x",
    )

    def __init__(self, J: float, n_p: int, a: float, T_s: float, b: float | None = None) -> None:
        if not (J > 0.0 and a > 0.0 and T_s > 0.0 and (b is None or b > 0.0)):
            raise ValueError(f"observer needs J, a, b, T_s > 0; got J={J}, a={a}, b={b}, T_s={T_s}")
        self.J = J
        self.n_p = n_p
        self.a = a
        self.T_s = T_s
        if b is None:
            self.K_1 = a**3 * J
            self.K_2 = 3.0 * a**2 * J
            self.K_3 = 3.0 * a * J
        else:
            self.K_1 = a * a * b * J
            self.K_2 = (a * a + 2.0 * a * b) * J
            self.K_3 = (2.0 * a + b) * J
        # per-step gains (T_s K_i / J) and the feed-forward gain (T_s n_p / J)
        self._g1 = T_s * self.K_1 / J
        self._g2 = T_s * self.K_2 / J
        self._g3 = T_s * self.K_3 / J
        self._gt = T_s * n_p / J
        self.theta_hat = 0.0
        self.w_hat = 0.0
        self.x = 0.0

    @property
    def tau_L_hat(self) -> float:
        """Estimated load torque (N m), ``-J x / n_p``."""
        return -self.J * self.x / self.n_p

    def reset(self, theta0: float = 0.0, w0: float = 0.0, x0: float = 0.0) -> None:
        """Set angle ``theta0`` (rad), speed ``w0`` (rad/s) and integral ``x0`` (rad/s^2)."""
        self.theta_hat = theta0 % _TWO_PI
        self.w_hat = w0
        self.x = x0


def observer_response(
    a: float, T_s: float, z: np.ndarray, b: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``(Theta/E, W/E)`` of the observer's step (``controller/core/cc_luenberger.c``) at ``z`` (module docstring);
    ``b`` as in :class:`LuenbergerObserver`."""
    zi = 1.0 / np.asarray(z, complex)
    d = 1.0 - zi
    if b is None:
        l1, l2, l3 = a**3, 3.0 * a * a, 3.0 * a
    else:
        l1, l2, l3 = a * a * b, a * a + 2.0 * a * b, 2.0 * a + b
    x = T_s * l1 / d
    w = (T_s * zi * x + T_s * l2) / d
    th = (T_s * zi * w + T_s * l3) / d
    return th, w


def design_pole(
    chain: Callable[[np.ndarray], np.ndarray],
    T_s: float,
    pm_deg: float,
    w_c_max: float,
    load_ratio: float | None = None,
) -> tuple[float, float, float]:
    """Triple pole ``a`` from a phase-margin target with a demodulator's filters in the loop.

    ``load_ratio``: the load pole as a fraction of ``a`` (``b = load_ratio
    a``; None: triple pole). The loop, broken at the error, is ``L =
    Theta/E(z) G(z)``: the
    observer's angle response (:func:`observer_response`) and ``chain``,
    the demodulator's response from ``theta_hat`` to its error (its in-loop
    filters; :func:`controller._rotating.in_loop_response`). The torque
    feed-forward is outside this loop. ``a`` is the largest pole that keeps

    1. the phase margin at ``pm_deg`` or more, and
    2. the gain crossover at or below ``w_c_max`` (the demodulation
       low-pass corner, as for the PI observer:
       :func:`controller._pll.design_bandwidth`).

    With nothing in the loop (``G = 1``) the triple-pole loop crosses over
    at about ``3.0 a`` with 72 degrees of margin whatever ``a`` (for ``a
    T_s`` small), so the filters and the one-period update take the margin
    down to the target.

    Returns
    -------
    a, pm, w_c : float
        Pole (rad/s), achieved phase margin (deg) and crossover (rad/s).
    """

    def loop(a: float) -> Callable[[np.ndarray], np.ndarray]:
        def f(w: np.ndarray) -> np.ndarray:
            z = np.exp(1j * np.asarray(w, float) * T_s)
            b = None if load_ratio is None else load_ratio * a
            return observer_response(a, T_s, z, b)[0] * chain(w)

        return f

    return largest_with_margin(
        loop, 1e-5 / T_s, 0.1 / T_s, 0.999 * math.pi / T_s, 3, pm_deg, w_c_max
    )
