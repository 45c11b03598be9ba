"""Wen's demodulation filters, eqs. (11)-(13), and their discrete realisations.

The continuous prototypes are Wen et al., Sec. 3.2:

- BPF, eq. (11): ``H_1(s) = 628 s / (s^2 + 628 s + 9859600)``, centre
  ``sqrt(9859600) = 3140 rad/s`` (499.7 Hz), bandwidth 628 rad/s (100 Hz);
- HPF, eq. (12): ``H_2(s) = s / (s + 1256)``, corner 1256 rad/s (200 Hz);
- LPF, eq. (13): ``H_3(s) = 628 / (s + 628)``, corner 628 rad/s (100 Hz).

They are discretised at the control rate by the bilinear transform with
pre-warping at the frequency of interest ``w_p`` (the discrete response
equals the continuous one exactly at ``w_p``):
``s = w_p / tan(w_p T_s / 2) * (z - 1) / (z + 1)``.

The per-step classes filter a pair of signals (the two components of a
space vector) with the same real coefficients, so a component rotating at
``+w`` sees ``H(j w)`` and one rotating at ``-w`` sees its conjugate.
They run on Python floats (direct form II transposed).
"""

from __future__ import annotations

import math

import numpy as np

from controller._design import designed

#: Coefficients (numerator, denominator) of Wen eqs. (11)-(13), highest power first.
BPF_WEN: tuple[tuple[float, ...], tuple[float, ...]] = ((628.0, 0.0), (1.0, 628.0, 9859600.0))
#: The high-pass filter of Wen eqs. (11)-(13), as :data:`BPF_WEN`.
HPF_WEN: tuple[tuple[float, ...], tuple[float, ...]] = ((1.0, 0.0), (1.0, 1256.0))
#: The low-pass filter of Wen eqs. (11)-(13), as :data:`BPF_WEN`.
LPF_WEN: tuple[tuple[float, ...], tuple[float, ...]] = ((628.0,), (1.0, 628.0))


@designed
def discretize(
    b: tuple[float, ...] | list[float],
    a: tuple[float, ...] | list[float],
    T_s: float,
    w_p: float,
) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Bilinear transform of ``b(s)/a(s)`` with pre-warping at ``w_p`` (rad/s).

    Returns ``(b_z, a_z)`` with ``a_z[0] = 1`` (coefficients of ``z^-n``).
    """
    # imported here: scipy.signal takes most of a process's start-up (1.2 of
    # 1.6 s here, ten times that in User-Mode Linux), and a plant node never
    # designs a filter
    from scipy import signal

    if w_p <= 0.0 or w_p * T_s >= math.pi:
        raise ValueError(f"pre-warping frequency {w_p} rad/s outside (0, pi/T_s)")
    fs_equiv = w_p / (2.0 * math.tan(0.5 * w_p * T_s))
    b_z, a_z = signal.bilinear(np.asarray(b, float), np.asarray(a, float), fs=fs_equiv)
    b_z = np.atleast_1d(b_z) / a_z[0]
    a_z = np.atleast_1d(a_z) / a_z[0]
    return tuple(float(x) for x in b_z), tuple(float(x) for x in a_z)


class FirstOrder2:
    """First-order discrete filter applied to a pair of signals.

    ``y[k] = b_0 x[k] + b_1 x[k-1] - a_1 y[k-1]``.

    Parameters
    ----------
    b, a : sequence of float
        Discrete coefficients from :func:`discretize` (length 2, ``a[0] = 1``).
    """

    __slots__ = ("_s1", "_s2", "a1", "b0", "b1")

    def __init__(self, b: tuple[float, ...], a: tuple[float, ...]) -> None:
        b = tuple(b) + (0.0,) * (2 - len(b))
        self.b0, self.b1 = float(b[0]), float(b[1])
        self.a1 = float(a[1])
        self._s1 = 0.0
        self._s2 = 0.0

    def reset(self) -> None:
        """Zero the states."""
        self._s1 = self._s2 = 0.0


class FirstOrder:
    """First-order discrete filter of one signal (see :class:`FirstOrder2`)."""

    __slots__ = ("_s", "a1", "b0", "b1")

    def __init__(self, b: tuple[float, ...], a: tuple[float, ...]) -> None:
        b = tuple(b) + (0.0,) * (2 - len(b))
        self.b0, self.b1 = float(b[0]), float(b[1])
        self.a1 = float(a[1])
        self._s = 0.0

    def reset(self) -> None:
        """Zero the state."""
        self._s = 0.0


class Biquad2:
    """Second-order discrete filter applied to a pair of signals (DF2T).

    ``y[k] = b_0 x[k] + b_1 x[k-1] + b_2 x[k-2] - a_1 y[k-1] - a_2 y[k-2]``.
    """

    __slots__ = ("_p1", "_p2", "_q1", "_q2", "a1", "a2", "b0", "b1", "b2")

    def __init__(self, b: tuple[float, ...], a: tuple[float, ...]) -> None:
        b = tuple(b) + (0.0,) * (3 - len(b))
        self.b0, self.b1, self.b2 = (float(x) for x in b[:3])
        self.a1, self.a2 = float(a[1]), float(a[2])
        self._p1 = self._p2 = self._q1 = self._q2 = 0.0

    def reset(self) -> None:
        """Zero the states."""
        self._p1 = self._p2 = self._q1 = self._q2 = 0.0


def bandpass_coefficients(w_0: float, B: float, T_s: float) -> tuple[float, float, float]:
    """``(b_0, a_1, a_2)`` of ``B s / (s^2 + B s + w_0^2)``, bilinear, pre-warped at ``w_0``.

    The centre ``w_0`` (rad/s) and bandwidth ``B`` (rad/s) of Wen's eq. (11)
    form; ``b_1 = 0`` and ``b_2 = -b_0``. With ``c = w_0 / tan(w_0 T_s / 2)``
    the substitution ``s = c (1 - z^-1) / (1 + z^-1)`` gives the numerator
    ``B c (1 - z^-2)`` and the denominator ``(c^2 + B c + w_0^2) + 2 (w_0^2 -
    c^2) z^-1 + (c^2 - B c + w_0^2) z^-2``, normalised. The same as
    :func:`discretize` of the prototype centred on ``w_0`` at ``w_p = w_0``
    (to rounding),
    without scipy, cheap enough to run every period
    (:class:`controller._tt_dq.TTDQEstimator` with ``bpf_tracking``).
    """
    c = w_0 / math.tan(0.5 * w_0 * T_s)
    cc = c * c
    ww = w_0 * w_0
    bc = B * c
    inv = 1.0 / (cc + bc + ww)
    return bc * inv, 2.0 * (ww - cc) * inv, (cc - bc + ww) * inv


def lpf_first_order(w_c: float, T_s: float) -> FirstOrder:
    """First-order low-pass ``w_c/(s + w_c)`` (unity DC gain), bilinear, pre-warped at ``w_c``."""
    b, a = discretize((w_c,), (1.0, w_c), T_s, min(w_c, 0.9 * math.pi / T_s))
    return FirstOrder(b, a)
