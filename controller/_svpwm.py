"""Voltage limiting and space-vector PWM by min-max zero-sequence injection.

Public functions a user may call per period: bindings of the core's
``controller/core/cc_svpwm.c``, the one implementation the controller's
engine runs too. Their readable Python is the tests' oracle
(``tests/oracle/blocks.py``, tolerance 0).
"""

from __future__ import annotations

import math

from controller._built import _cctl

_SQRT3 = math.sqrt(3.0)


def limit_magnitude(x_1: float, x_2: float, x_max: float) -> tuple[float, float]:
    """Scale the vector ``(x_1, x_2)`` down to magnitude ``x_max`` if it is longer
    (``cc_limit_magnitude``: ``x <- x x_max / |x|`` when ``|x|^2 > x_max^2``)."""
    return _cctl.limit_magnitude(x_1, x_2, x_max)


def u_max_linear(u_dc: float) -> float:
    """Largest voltage-vector magnitude (V) SVPWM makes without overmodulation: ``u_dc/sqrt(3)``."""
    return u_dc / _SQRT3


def svpwm(u_alpha: float, u_beta: float, u_dc: float) -> tuple[float, float, float]:
    """Phase duty cycles for the stator-voltage reference ``u_ab`` (``cc_svpwm``).

    Phase references of the amplitude-invariant inverse Clarke transform get
    the min-max zero sequence ``-(max + min)/2``, which centres them in
    ``[-u_dc/2, u_dc/2]`` and gives the same switching times as
    conventional space-vector modulation. The duty of phase ``x`` is
    ``d_x = 1/2 + u_x/u_dc`` (pole voltage ``d_x u_dc`` with respect to the
    negative rail), so the line voltage is ``(d_a - d_b) u_dc = u_a - u_b``.
    Beyond the linear range (``|u_ab| > u_dc/sqrt(3)``) the duties are
    clipped to [0, 1].

    Parameters
    ----------
    u_alpha, u_beta : float
        Voltage reference, stationary frame (V), averaged over the period.
    u_dc : float
        DC-link voltage (V), positive (a ValueError otherwise).

    Returns
    -------
    d_a, d_b, d_c : float
        Duty cycles in [0, 1].
    """
    if not u_dc > 0.0:
        raise ValueError(f"svpwm: u_dc must be positive (got {u_dc} V)")
    d: tuple[float, float, float] = _cctl.svpwm(u_alpha, u_beta, u_dc)
    return d
