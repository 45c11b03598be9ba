"""Start-up from an unknown rotor angle: magnet-polarity test by d-axis voltage pulses.

The HF estimators (rotating or square-wave) see the saliency, which repeats
every pi electrical: at standstill they converge to ``theta_e`` or
``theta_e + pi``. The polarity test resolves the ambiguity with the
magnet's saturation: current along the magnet's north (``i_d > 0``) adds to
the magnet flux and saturates the d-axis iron, so its incremental
inductance is lower and the same volt-seconds give a larger current than
along the south.

Sequence (estimator frozen, no injection; ``u`` along the estimated d axis)::

    +U for N periods, -U for N (back to the start flux), 0 for N
    -U for N periods, +U for N, 0 for N

``U = min(u_frac u_dc / sqrt(3), L_d i_pulse / (2 T_s))`` and
``N = ceil(L_d i_pulse / (U T_s))`` (at least 2), so the peak is about
``i_pulse`` in the linear model also at a low switching frequency. The
peaks ``dI_+ = max(i_d - i_d0)`` over the first half and
``dI_- = max(i_d1 - i_d)`` over the second, each from its own half's start
current (``i_d1``: what the resistance left of the first half's pulse pair,
which would otherwise bias ``dI_-`` by about ``i_pulse R N T_s / L_d``),
decide: ``dI_+ < dI_-`` means the
estimated d axis points south and the angle is flipped by pi. Volt-second
balanced pulses return the flux (and the current) to its start value, so
the rotor gets no net torque.

Time stamps: the voltage decided at sample ``k`` acts in period ``k + 1``;
the peaks are taken over all samples of each half, which covers the
one-period delay.
"""

from __future__ import annotations

import math


class PolarityTest:
    """State machine of the magnet-polarity test (see module docstring).

    Kept in Python as a public block a user may call per period (a plug-in's
    estimator composes it; the core calls a plug-in's Python each period), and
    as the tests' oracle of ``controller/core/cc_startup.c``, which the controller's
    one engine runs with the same operations (``tests/oracle/``, tolerance 0).

    Parameters
    ----------
    L_d : float
        Model d-axis inductance (H).
    T_s : float
        Sampling period (s).
    i_pulse : float
        Peak pulse current in the linear model (A).
    u_frac : float
        Pulse voltage as a fraction of ``u_dc / sqrt(3)``.
    """

    __slots__ = (
        "L_d",
        "N",
        "T_s",
        "U",
        "_i0",
        "_i1",
        "_n",
        "d_i_neg",
        "d_i_pos",
        "done",
        "flip",
        "i_pulse",
        "u_frac",
    )

    def __init__(self, L_d: float, T_s: float, i_pulse: float, u_frac: float = 0.5) -> None:
        self.L_d = L_d
        self.T_s = T_s
        self.i_pulse = i_pulse
        self.u_frac = u_frac
        self.U = 0.0
        self.N = 1
        self._n = 0
        self._i0 = 0.0
        self._i1 = 0.0
        self.d_i_pos = 0.0
        self.d_i_neg = 0.0
        self.done = False
        self.flip = False

    def start(self, u_dc: float, i_d0: float) -> None:
        """Begin a test at DC-link voltage ``u_dc`` (V) and d current ``i_d0`` (A)."""
        flux = self.L_d * self.i_pulse
        self.U = min(self.u_frac * u_dc / math.sqrt(3.0), flux / (2.0 * self.T_s))
        self.N = max(2, math.ceil(flux / (self.U * self.T_s) - 1e-9))
        self._n = 0
        self._i0 = i_d0
        self._i1 = i_d0
        self.d_i_pos = 0.0
        self.d_i_neg = 0.0
        self.done = False
        self.flip = False

    @property
    def n_steps(self) -> int:
        """Length of the whole test (periods)."""
        return 6 * self.N

    def step(self, i_d: float) -> float:
        """Take the d current of sample ``k`` (A); return ``u_d`` (V) for period ``k + 1``."""
        n = self._n
        N = self.N
        if n < 3 * N:
            d = i_d - self._i0
            if d > self.d_i_pos:
                self.d_i_pos = d
        else:
            if n == 3 * N:  # start of the second half: its own reference
                self._i1 = i_d
            d = self._i1 - i_d
            if d > self.d_i_neg:
                self.d_i_neg = d
        self._n = n + 1
        if n >= 6 * N:
            self.done = True
            self.flip = self.d_i_pos < self.d_i_neg
            return 0.0
        phase = n // N
        if phase in (0, 4):
            return self.U
        if phase in (1, 3):
            return -self.U
        return 0.0
