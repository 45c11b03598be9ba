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

from controller._built import _cctl


class PolarityTest(_cctl.Polarity):
    """State machine of the magnet-polarity test (see module docstring).

    A public block a user may call per period (a plug-in's estimator composes
    it): a binding of the core's ``controller/core/cc_startup.c``, the one
    implementation the controller's engine runs too. Its readable Python is
    the tests' oracle (``tests/oracle/blocks.py``, tolerance 0).

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

    Notes
    -----
    Its members, the core struct's fields (design values read-only, states
    writable):

    L_d, T_s, i_pulse, u_frac : float
        The design values, read-only.
    U, N : float, int
        The pulse voltage (V) and length (periods) of the test :meth:`start` began.
    d_i_pos, d_i_neg : float
        The peaks of the two halves (A).
    done, flip : bool
        Whether the test has ended, and whether its result is a flip by pi.
    """

    __slots__ = ()

    def __init__(self, L_d: float, T_s: float, i_pulse: float, u_frac: float = 0.5) -> None:
        super().__init__(L_d, T_s, i_pulse, u_frac)

    def start(self, u_dc: float, i_d0: float) -> None:
        """Begin a test at DC-link voltage ``u_dc`` (V) and d current ``i_d0`` (A).

        The pulse needs a positive ``u_dc``, ``L_d``, ``T_s``, ``i_pulse`` and ``u_frac``
        (``U`` and ``N`` are undefined otherwise): a ValueError names the first that is not.
        """
        for name, v in (
            ("u_dc", u_dc),
            ("L_d", self.L_d),
            ("T_s", self.T_s),
            ("i_pulse", self.i_pulse),
            ("u_frac", self.u_frac),
        ):
            if not v > 0.0:
                raise ValueError(f"PolarityTest.start: {name} must be positive (got {v})")
        super().start(u_dc, i_d0)

    @property
    def n_steps(self) -> int:
        """Length of the whole test (periods)."""
        return 6 * self.N

    # step(i_d): the core's (_cctl.Polarity)
