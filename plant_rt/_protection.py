"""Inverter protection: over-current, DC-link over-voltage and over-speed trips.

A real inverter compares the phase currents, the DC-link voltage and the
shaft speed with fixed limits every PWM period and, on a violation, opens
all switches and latches the reason until the operator resets it. This
module is that comparator and latch, as a pure class (values in, fault code
out); the plant node applies the safe state (``Plant.step(..., enable=False)``,
diode bridge) while :attr:`Protection.fault` is set.

Fault codes are those of the DBC's ``PlantStatus.fault_code`` value table.
"""

from __future__ import annotations

from dataclasses import dataclass

from plant_rt._engine import _cplant
from plant_rt._inverter import InverterPars
from plant_rt._machine import MotorPars

__all__ = [
    "FAULT_NAMES",
    "FAULT_NONE",
    "FAULT_OVER_CURRENT",
    "FAULT_OVER_SPEED",
    "FAULT_OVER_VOLTAGE",
    "FAULT_WATCHDOG",
    "Protection",
    "ProtectionPars",
]

# The codes are the core's (plant_rt/core/plant_protection.h).
#: Fault code (``PlantStatus.fault_code``): no fault.
FAULT_NONE: int = _cplant.FAULT_NONE
#: Fault code: the duty frames stopped (the plant's duty watchdog).
FAULT_WATCHDOG: int = _cplant.FAULT_WATCHDOG
#: Fault code: a phase current above the limit.
FAULT_OVER_CURRENT: int = _cplant.FAULT_OVER_CURRENT
#: Fault code: the DC-link voltage above the limit.
FAULT_OVER_VOLTAGE: int = _cplant.FAULT_OVER_VOLTAGE
#: Fault code: the mechanical speed above the limit.
FAULT_OVER_SPEED: int = _cplant.FAULT_OVER_SPEED
FAULT_NAMES: dict[int, str] = {
    FAULT_NONE: "none",
    FAULT_WATCHDOG: "watchdog",
    FAULT_OVER_CURRENT: "over_current",
    FAULT_OVER_VOLTAGE: "over_voltage",
    FAULT_OVER_SPEED: "over_speed",
}
"""Fault code to name, as in the DBC value table of ``PlantStatus.fault_code``."""


@dataclass(frozen=True, slots=True)
class ProtectionPars:
    """Trip thresholds.

    Parameters
    ----------
    i_trip : float
        Over-current trip: peak of any phase current (A), compared with
        ``|i_x|`` every period.
    u_dc_trip : float
        DC-link over-voltage trip (V).
    w_m_trip : float
        Over-speed trip: ``|w_m|`` (rad/s, mechanical).
    """

    i_trip: float
    u_dc_trip: float
    w_m_trip: float

    def __post_init__(self) -> None:
        for name in ("i_trip", "u_dc_trip", "w_m_trip"):
            v = getattr(self, name)
            if not v > 0.0:
                raise ValueError(f"ProtectionPars.{name} must be > 0, got {v}")

    @classmethod
    def from_preset(
        cls,
        motor: MotorPars,
        inverter: InverterPars,
        *,
        i_margin: float = 1.5,
        u_margin: float = 1.2,
        w_margin: float = 1.5,
    ) -> ProtectionPars:
        """Thresholds as margins over the machine's and inverter's ratings.

        ``i_trip = i_margin i_max`` (the controller limits the current to
        ``i_max``; the margin leaves room for the current ripple, HF injection
        and the overshoot of a load step), ``u_dc_trip = u_margin u_dc``
        (nominal DC link), ``w_m_trip = w_margin w_m_rated``.
        """
        if min(i_margin, u_margin, w_margin) <= 0.0:
            raise ValueError("protection margins must be > 0")
        return cls(
            i_trip=i_margin * motor.i_max,
            u_dc_trip=u_margin * inverter.u_dc,
            w_m_trip=w_margin * motor.w_m_rated,
        )


class Protection:
    """Comparators and fault latch of an inverter.

    Parameters
    ----------
    pars : ProtectionPars
        Trip thresholds.

    Attributes
    ----------
    fault : int
        Latched fault code (:data:`FAULT_NONE` while healthy). The first
        fault wins and stays until :meth:`reset`.
    trips : dict of int to int
        Trips per fault code since construction.
    """

    __slots__ = ("_i", "_u", "_w", "fault", "pars", "trips")

    def __init__(self, pars: ProtectionPars) -> None:
        self.pars = pars
        self._i = float(pars.i_trip)
        self._u = float(pars.u_dc_trip)
        self._w = float(pars.w_m_trip)
        self.fault = FAULT_NONE
        self.trips: dict[int, int] = {}

    @property
    def tripped(self) -> bool:
        """True while a fault is latched."""
        return self.fault != FAULT_NONE

    def check(self, i_a: float, i_b: float, i_c: float, u_dc: float, w_m: float) -> int:
        """Compare one period's values with the thresholds; return the latched fault.

        Parameters
        ----------
        i_a, i_b, i_c : float
            Phase currents (A).
        u_dc : float
            DC-link voltage (V).
        w_m : float
            Mechanical speed (rad/s).

        Returns
        -------
        int
            The latched fault code: a new trip is latched only when none is;
            checked in the order over-current, over-voltage, over-speed.
            NaN values trip (a comparator cannot be fooled by them).
        """
        if self.fault != FAULT_NONE:
            return self.fault
        code = _cplant.protection_check(self._i, self._u, self._w, i_a, i_b, i_c, u_dc, w_m)
        return FAULT_NONE if code == FAULT_NONE else self.trip(code)

    def trip(self, code: int) -> int:
        """Latch fault ``code`` (e.g. the watchdog, which is outside this class) unless one is."""
        if code not in FAULT_NAMES or code == FAULT_NONE:
            raise ValueError(f"unknown fault code {code}")
        if self.fault == FAULT_NONE:
            self.fault = code
            self.trips[code] = self.trips.get(code, 0) + 1
        return self.fault

    def reset(self) -> int:
        """Clear the latch (operator reset); return the fault that was latched.

        If the condition persists, the next :meth:`check` trips again.
        """
        old = self.fault
        self.fault = FAULT_NONE
        return old
