"""Discrete two-degree-of-freedom PI controller with anti-windup."""

from __future__ import annotations

from controller._built import _cctl


class PIController(_cctl.Pi):
    """2DOF PI controller, the motulator template.

    A public block a user may call per period (a plug-in's estimator composes
    it): a binding of the core's ``controller/core/cc_pi.c``, the one
    implementation the controller's engine runs too. Its readable Python is
    the tests' oracle (``tests/oracle/blocks.py``, tolerance 0).

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
        Reference gain; defaults to ``k_p``. Not zero (the anti-windup divides by it).

    Notes
    -----
    Its members, the core struct's fields (design values read-only, states
    writable):

    k_p, k_i, k_t, T_s : float
        The design values, read-only.
    u_i : float
        The integral state (writable).
    """

    __slots__ = ()

    def __init__(self, k_p: float, k_i: float, T_s: float, k_t: float | None = None) -> None:
        k_t = k_p if k_t is None else k_t
        if k_t == 0.0:
            raise ValueError(f"PIController: k_t must not be zero (got k_p={k_p}, k_t={k_t})")
        super().__init__(float(k_p), float(k_i), float(T_s), float(k_t))

    # output(r, y, u_ff=0.0), update(u_lim), reset(u_i=0.0): the core's (_cctl.Pi)
