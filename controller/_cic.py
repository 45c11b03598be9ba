"""Single-order cascaded integrator-comb (CIC) interpolation, Xue et al. Sec. 3.2, eq. (8).

A slow signal (one sample every ``R`` fast steps) is raised to the fast rate
in two stages, both running at the fast rate:

1. sample-and-hold rate conversion (Xue Fig. 4): each slow sample is held
   for ``R`` fast steps;
2. the single-order CIC filter of eq. (8), a comb followed by an integrator::

       H(z) = H_1(z) H_2(z) = (1 - z^-M) / (1 - z^-1) = sum_{n=0}^{M-1} z^-n

   scaled by ``1 / M`` for unity DC gain.

Impulse responses (fast steps):

- eq. (8) alone (:class:`CicFilter`): ``1/M`` for ``n = 0 .. M-1``, zero after;
- hold + eq. (8) (:class:`CicInterpolator`): the convolution of a box of
  length ``R`` with a box of length ``M``, divided by ``M``; for ``M = R`` a
  triangle of base ``2 R - 1``, i.e. linear interpolation between
  successive slow samples.

The hold is kept in front of the comb on purpose: a single-order CIC fed
with zero-stuffed samples and ``M = R`` (the textbook interpolator) has the
box impulse response of a zero-order hold and would not smooth anything.

Group delays (fast steps, exact for these linear-phase boxes): hold
``(R - 1) / 2``, comb-integrator ``(M - 1) / 2``. For Xue's ``M = R = 2``
each adds half a PWM period.
"""

from __future__ import annotations


class CicFilter:
    """Comb ``1 - z^-M`` then integrator ``1 / (1 - z^-1)``, scaled by ``1/M`` (Xue eq. 8).

    Realised as written: ``c[n] = x[n] - x[n-M]``, ``y[n] = y[n-1] + c[n]``,
    output ``y[n] / M``.  Integer and binary-fraction inputs are summed
    exactly; for general floats the integrator's rounding is bounded by
    the recomputation in the step every ``4096`` steps (``controller/core/cc_cic.c``;
    its Python, the tests' oracle: ``tests/oracle/blocks.py``).

    Parameters
    ----------
    M : int
        Differential delay of the comb (fast steps), >= 1.
    """

    __slots__ = ("M", "_acc", "_buf", "_i", "_inv_M", "_n")

    def __init__(self, M: int = 2) -> None:
        if M < 1:
            raise ValueError(f"CIC order M must be >= 1, got {M}")
        self.M = M
        self._inv_M = 1.0 / M
        self._buf = [0.0] * M
        self._i = 0
        self._acc = 0.0
        self._n = 0

    def reset(self) -> None:
        """Clear the comb delay line and the integrator."""
        for j in range(self.M):
            self._buf[j] = 0.0
        self._i = 0
        self._acc = 0.0
        self._n = 0


class CicInterpolator:
    """Sample-and-hold rate conversion by ``R`` followed by :class:`CicFilter` (Xue Figs. 4, 7-9).

    The step (``controller/core/cc_cic.c``) runs once per fast step, with the new slow
    sample on the step it arrives and none on the other ``R - 1`` steps.

    Parameters
    ----------
    M : int
        CIC differential delay (fast steps). Xue uses ``M = R``.
    R : int
        Rate factor: fast steps per slow sample (Xue ``R = (T_h/2)/T_PWM``
        in Fig. 8 counts the other way; at 1 kHz PWM and 500 Hz injection
        it is 2).
    """

    __slots__ = ("R", "_cic", "_held")

    def __init__(self, M: int = 2, R: int = 2) -> None:
        if R < 1:
            raise ValueError(f"CIC rate factor R must be >= 1, got {R}")
        self.R = R
        self._cic = CicFilter(M)
        self._held = 0.0

    @property
    def M(self) -> int:
        """CIC differential delay (fast steps)."""
        return self._cic.M

    @property
    def group_delay(self) -> float:
        """Delay of hold plus comb-integrator (fast steps): ``(R - 1)/2 + (M - 1)/2``."""
        return 0.5 * (self.R - 1) + 0.5 * (self._cic.M - 1)

    def reset(self, x0: float = 0.0) -> None:
        """Empty the filter and hold ``x0``."""
        self._cic.reset()
        self._held = x0
