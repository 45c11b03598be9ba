"""Three-phase two-level inverter: parameters and the average model.

Average model over one PWM period: phase leg ``x`` connects its output to
the positive rail for the fraction ``d_x`` of the period, so its mean pole
voltage (referred to the negative rail) is ``d_x u_dc``. The machine's star
point floats, so only the differential part reaches the windings::

    u_alpha = (2/3) (v_a - (v_b + v_c) / 2)
    u_beta  = (v_b - v_c) / sqrt(3)

(amplitude-invariant Clarke transformation; the zero-sequence part drops).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

SQRT3 = math.sqrt(3.0)
INV_SQRT3 = 1.0 / SQRT3


@dataclass(frozen=True, slots=True)
class InverterPars:
    """Inverter and DC link.

    Parameters
    ----------
    u_dc : float
        DC-link voltage (V), held constant (stiff DC source).
    t_dead : float
        Dead time per switching transition (s). Zero disables the dead-time
        voltage error.
    """

    u_dc: float
    t_dead: float = 0.0

    def __post_init__(self) -> None:
        if not self.u_dc > 0.0:
            raise ValueError(f"InverterPars.u_dc must be > 0, got {self.u_dc}")
        if self.t_dead < 0.0:
            raise ValueError(f"InverterPars.t_dead must be >= 0, got {self.t_dead}")


def clamp_duty(d: float) -> float:
    """Clamp a duty cycle to [0, 1]; NaN becomes 0."""
    if d > 1.0:
        return 1.0
    if d >= 0.0:
        return d
    return 0.0


def pole_to_ab(v_a: float, v_b: float, v_c: float) -> tuple[float, float]:
    """Pole voltages (V, referred to the negative rail) to the stator voltage in alpha-beta (V)."""
    return (2.0 * v_a - v_b - v_c) / 3.0, (v_b - v_c) * INV_SQRT3


def dead_time_error(i_x: float, u_dc: float, t_dead: float, T_s: float) -> float:
    """Mean pole-voltage error of one leg caused by dead time (V).

    During the dead time both switches of the leg are off and the phase
    current flows through a diode: the lower one if the current flows into
    the machine (``i_x > 0``), the upper one otherwise. Of the two edges of
    a period only the one that turns on the switch opposite to the
    conducting diode is delayed, so the mean pole voltage loses
    ``t_dead / T_s * u_dc`` against the current's direction. A leg held at
    a rail (duty 0 or 1) does not switch and has no such error: the plant
    applies this only to switching legs.

    Parameters
    ----------
    i_x : float
        Phase current (A), positive into the machine.
    u_dc : float
        DC-link voltage (V).
    t_dead : float
        Dead time (s).
    T_s : float
        PWM period (s).
    """
    if i_x > 0.0:
        return -u_dc * t_dead / T_s
    if i_x < 0.0:
        return u_dc * t_dead / T_s
    return 0.0
