"""Space-vector transforms (amplitude-invariant Clarke and Park) and angle wrapping.

All functions work on Python floats; they are called every PWM period. Kept
in Python as public functions a user may call per period (a plug-in's
estimator composes them) and for the closed-form tests of each block; the
controller's core writes the same operations inline in its step
(``controller/core/cc_foc.c``; the angle wrap is ``cc_math.h``'s).
"""

from __future__ import annotations

import math

_SQRT3_INV = 1.0 / math.sqrt(3.0)
_SQRT3_HALF = 0.5 * math.sqrt(3.0)
_TWO_PI = 2.0 * math.pi


def clarke(x_a: float, x_b: float, x_c: float) -> tuple[float, float]:
    """Amplitude-invariant Clarke transform.

    ``x_alpha = (2 x_a - x_b - x_c) / 3`` and ``x_beta = (x_b - x_c) / sqrt(3)``; a
    zero-sequence component is discarded.

    Parameters
    ----------
    x_a, x_b, x_c : float
        Phase quantities.

    Returns
    -------
    x_alpha, x_beta : float
        Stationary-frame components (same unit as the input).
    """
    return (2.0 * x_a - x_b - x_c) / 3.0, (x_b - x_c) * _SQRT3_INV


def inv_clarke(x_alpha: float, x_beta: float) -> tuple[float, float, float]:
    """Inverse amplitude-invariant Clarke transform (no zero sequence)."""
    return (
        x_alpha,
        -0.5 * x_alpha + _SQRT3_HALF * x_beta,
        -0.5 * x_alpha - _SQRT3_HALF * x_beta,
    )


def park(x_alpha: float, x_beta: float, cos_t: float, sin_t: float) -> tuple[float, float]:
    """Park transform ``x_dq = exp(-j theta) x_ab`` given ``cos(theta)``, ``sin(theta)``."""
    return cos_t * x_alpha + sin_t * x_beta, -sin_t * x_alpha + cos_t * x_beta


def inv_park(x_d: float, x_q: float, cos_t: float, sin_t: float) -> tuple[float, float]:
    """Inverse Park transform ``x_ab = exp(j theta) x_dq`` given ``cos(theta)``, ``sin(theta)``."""
    return cos_t * x_d - sin_t * x_q, sin_t * x_d + cos_t * x_q


def wrap_pi(theta: float) -> float:
    """Wrap an angle (rad) to [-pi, pi)."""
    return (theta + math.pi) % _TWO_PI - math.pi


def wrap_2pi(theta: float) -> float:
    """Wrap an angle (rad) to [0, 2 pi)."""
    return theta % _TWO_PI
