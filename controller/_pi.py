"""Discrete two-degree-of-freedom PI controller with anti-windup."""

from __future__ import annotations


class PIController:
    """2DOF PI controller, the motulator template.

    Kept in Python as a public block a user may call per period (a plug-in's
    estimator composes it; the core calls a plug-in's Python each period), and
    as the tests' oracle of ``controller/core/cc_pi.c``, which the controller's
    one engine runs with the same operations (``tests/oracle/``, tolerance 0).

    Control law (sample ``k``)::

        u   = k_t r - k_p y + u_i + u_ff        (output, before limiting)
        u_i <- u_i + T_s k_i [ (r - y) + (u_lim - u) / k_t ]

    where ``u_lim`` is the *realised* (limited) output. Feeding the realised
    output back into the integrator is the anti-windup: once the output
    saturates, the integral stops growing. With ``k_t = k_p`` this is the
    ordinary PI ``u = k_p (r - y) + u_i``.

    Call :meth:`output` first (it stores the unlimited output), limit it,
    then call :meth:`update` with the realised value: measure, compute
    output, update states, so that the output leaves with minimum latency.

    Parameters
    ----------
    k_p : float
        Proportional gain on the measurement.
    k_i : float
        Integral gain.
    T_s : float
        Sampling period (s).
    k_t : float, optional
        Reference gain; defaults to ``k_p``.
    """

    __slots__ = ("T_s", "_e", "_u", "k_i", "k_p", "k_t", "u_i")

    def __init__(self, k_p: float, k_i: float, T_s: float, k_t: float | None = None) -> None:
        self.k_p = float(k_p)
        self.k_i = float(k_i)
        self.k_t = float(k_p if k_t is None else k_t)
        self.T_s = float(T_s)
        self.u_i = 0.0
        self._e = 0.0
        self._u = 0.0

    def output(self, r: float, y: float, u_ff: float = 0.0) -> float:
        """Unlimited controller output for reference ``r`` and measurement ``y``."""
        self._e = r - y
        self._u = self.k_t * r - self.k_p * y + self.u_i + u_ff
        return self._u

    def update(self, u_lim: float) -> None:
        """Advance the integrator with the realised (limited) output ``u_lim``."""
        self.u_i += self.T_s * self.k_i * (self._e + (u_lim - self._u) / self.k_t)

    def reset(self, u_i: float = 0.0) -> None:
        """Set the integral state."""
        self.u_i = float(u_i)
        self._e = 0.0
        self._u = 0.0
