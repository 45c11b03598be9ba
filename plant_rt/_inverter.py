"""Three-phase two-level inverter: parameters and the average model.

Average model over one PWM period: phase leg ``x`` connects its output to
the positive rail for the fraction ``d_x`` of the period, so its mean pole
voltage (referred to the negative rail) is ``d_x u_dc``. The machine's star
point floats, so only the differential part reaches the windings::

    u_alpha = (2/3) (v_a - (v_b + v_c) / 2)
    u_beta  = (v_b - v_c) / sqrt(3)

(amplitude-invariant Clarke transformation; the zero-sequence part drops).

The switching model (``InverterPars.model = "switching"``) resolves the
carrier, the dead time and the device drops edge by edge; its timeline is
``plant_rt/core/plant_pwm.c``, its integration ``plant_rt/core/plant.c``.
:func:`dead_time_error` and :func:`device_drop_error` are the core's
(``plant_pwm.c``), called through its binding.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from plant_rt._engine import _cplant

InverterModel = Literal["average", "switching"]
SampleAt = Literal["peak", "valley"]


@dataclass(frozen=True, slots=True)
class InverterPars:
    """Inverter and DC link.

    The field names are the keys of a scenario's ``[inverter]`` table.

    Parameters
    ----------
    u_dc : float
        DC-link voltage (V): the source voltage behind ``r_dc``; with
        ``r_dc = 0`` the DC link is stiff at this value.
    t_dead : float
        Dead time per switching transition (s). Zero disables the dead-time
        voltage error.
    model : {"average", "switching"}
        ``"average"``: one mean voltage per period (the fast reference,
        :func:`dead_time_error` and :func:`device_drop_error` as period
        means, each phase current's direction taken at the start of the
        period). That direction is the period's only while the current
        does not reverse within it: where a ripple larger than the current
        does (the 1 kHz square-wave injection's +-2.8 A at light load), the
        error it gives alternates with the ripple instead, and with dead time
        the square wave loses the rotor at start-up on this model
        (``wide-speed-xue``) where it keeps it on the switching one; use
        ``"switching"`` to study dead time with such a ripple.
        ``"switching"``: centre-aligned carrier, each edge, dead
        interval and diode clamp resolved in time (:mod:`plant_rt._pwm`).
    v_ce : float
        On-state voltage of a conducting transistor (IGBT ``V_CE(sat)`` or
        MOSFET ``R_DS(on) i`` at the working current) (V), >= 0.
    v_f : float
        Forward voltage of a conducting freewheeling diode (V), >= 0.
    r_dc : float
        Source resistance of the DC link (Ohm), >= 0. Zero: stiff DC link.
    c_dc : float
        DC-link capacitance (F), >= 0. With ``r_dc > 0`` the capacitor
        voltage is a state (time constant ``r_dc c_dc``); with ``c_dc = 0``
        the link droops algebraically, ``u_dc - r_dc i_dc``.
    sample_at : {"peak", "valley"}
        Which carrier extremum falls on the period boundary ``t = k T_s``,
        where the ADC samples (switching model). ``"peak"``: the centre of
        the zero vector with all lower switches on; ``"valley"``: all upper
        switches on.
    """

    u_dc: float
    t_dead: float = 0.0
    model: InverterModel = "average"
    v_ce: float = 0.0
    v_f: float = 0.0
    r_dc: float = 0.0
    c_dc: float = 0.0
    sample_at: SampleAt = "peak"

    def __post_init__(self) -> None:
        if not self.u_dc > 0.0:
            raise ValueError(f"InverterPars.u_dc must be > 0, got {self.u_dc}")
        if not self.t_dead >= 0.0:
            raise ValueError(f"InverterPars.t_dead must be >= 0, got {self.t_dead}")
        if self.model not in ("average", "switching"):
            raise ValueError(
                f"InverterPars.model must be 'average' or 'switching', got {self.model!r}"
            )
        if self.sample_at not in ("peak", "valley"):
            raise ValueError(
                f"InverterPars.sample_at must be 'peak' or 'valley', got {self.sample_at!r}"
            )
        for name in ("v_ce", "v_f", "r_dc", "c_dc"):
            v = getattr(self, name)
            if not (v >= 0.0 and math.isfinite(v)):
                raise ValueError(f"InverterPars.{name} must be finite and >= 0, got {v}")

    @property
    def dc_link_dynamic(self) -> bool:
        """True when the DC-link voltage depends on the load (``r_dc > 0``)."""
        return self.r_dc > 0.0


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
    return _cplant.dead_time_error(i_x, u_dc, t_dead, T_s)


def device_drop_error(i_x: float, d_x: float, v_ce: float, v_f: float) -> float:
    """Mean pole-voltage error of one leg caused by the device drops (V).

    The current flows through the upper transistor or the lower diode when
    it flows into the machine (``i_x > 0``), through the upper diode or the
    lower transistor otherwise. With the pole on the positive rail for the
    fraction ``d_x`` of the period::

        i_x > 0:  -(d_x v_ce + (1 - d_x) v_f)
        i_x < 0:  +(d_x v_f + (1 - d_x) v_ce)

    and zero at zero current.

    Parameters
    ----------
    i_x : float
        Phase current (A), positive into the machine.
    d_x : float
        Fraction of the period the pole sits on the positive rail (-).
    v_ce, v_f : float
        Transistor on-state and diode forward voltages (V).
    """
    return _cplant.device_drop_error(i_x, d_x, v_ce, v_f)
