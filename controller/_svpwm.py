"""Voltage limiting and space-vector PWM by min-max zero-sequence injection.

Kept in Python as public functions a user may call per period, and as the
tests' oracle of ``controller/core/cc_svpwm.c``, which the controller's one
engine runs with the same operations (``tests/oracle/``, tolerance 0).
"""

from __future__ import annotations

import math

_SQRT3 = math.sqrt(3.0)
_SQRT3_HALF = 0.5 * math.sqrt(3.0)


def limit_magnitude(x_1: float, x_2: float, x_max: float) -> tuple[float, float]:
    """Scale the vector ``(x_1, x_2)`` down to magnitude ``x_max`` if it is longer."""
    m2 = x_1 * x_1 + x_2 * x_2
    if m2 > x_max * x_max:
        s = x_max / math.sqrt(m2)
        return x_1 * s, x_2 * s
    return x_1, x_2


def u_max_linear(u_dc: float) -> float:
    """Largest voltage-vector magnitude (V) SVPWM makes without overmodulation: ``u_dc/sqrt(3)``."""
    return u_dc / _SQRT3


def svpwm(u_alpha: float, u_beta: float, u_dc: float) -> tuple[float, float, float]:
    """Phase duty cycles for the stator-voltage reference ``u_ab``.

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
        DC-link voltage (V).

    Returns
    -------
    d_a, d_b, d_c : float
        Duty cycles in [0, 1].
    """
    u_a = u_alpha
    u_b = -0.5 * u_alpha + _SQRT3_HALF * u_beta
    u_c = -0.5 * u_alpha - _SQRT3_HALF * u_beta
    if u_a > u_b:
        hi = u_a
        lo = u_b
    else:
        hi = u_b
        lo = u_a
    if u_c > hi:
        hi = u_c
    elif u_c < lo:
        lo = u_c
    k = 1.0 / u_dc
    off = 0.5 - 0.5 * (hi + lo) * k
    d_a = off + u_a * k
    d_b = off + u_b * k
    d_c = off + u_c * k
    if (hi - lo) * k > 1.0 - 1e-12:  # at or beyond the linear range: clip
        return _clip(d_a), _clip(d_b), _clip(d_c)
    return d_a, d_b, d_c


def _clip(d: float) -> float:
    return 0.0 if d < 0.0 else (1.0 if d > 1.0 else d)
