"""Plant and sensor faults on the exact PWM period (pure: values in, values out).

A scenario's fault timeline (``[[faults]]``, ``bench/scenarios/_faults.py``)
reaches the plant as :class:`FaultWindow` values: a kind, the periods
``[k0, k1)`` it covers and its parameters.  :class:`PlantFaults` applies the
ones of the machine and the power stage through the plant's public API
(:meth:`plant_rt.Plant.set_parameters`) before each period, and those of the
sensors to each :class:`plant_rt.Sample`:

- ``open_phase``: the leg of ``phase`` is open (:meth:`plant_rt.Plant.set_leg_faults`
  ``"open_phase"``: its current freewheels to zero through the leg's diodes and is
  then held at zero; the equations in ``plant_rt/core/plant_leg.h``);
- ``open_switch``: the ``device`` (``upper`` or ``lower``) of the leg of ``phase``
  never conducts, its antiparallel diode does (``"open_upper"``, ``"open_lower"``);
- ``dc_link_step``: the DC-link source voltage is ``u_dc_v`` in ``[k0, k1)``;
- ``demagnetisation``: ``psi_f`` is ``psi_f_factor`` times the nominal;
- ``resistance_drift``: ``R_s`` is ``R_s_factor`` times the nominal;
- ``current_offset``: the phase's measured current plus ``a``;
- ``current_gain``: the phase's measured current times ``factor``;
- ``current_stuck``: the phase's measured current of sample ``k0 - 1`` (the
  last before the fault; at ``k0 = 0`` the first sample's own value);
- ``current_lost``: the phase's measured current reads 0;
- ``dc_voltage_offset``: the measured DC-link voltage plus ``v``;
- ``position_sensor_lost``: :meth:`PlantFaults.position_lost` is true (the
  node sends no ``PositionSensor`` frame).

Sensor faults act on the sample as the plant's sensor model measured it
(gain, offset, noise and ADC applied): a fault of the signal chain after the
converter, so an offset or a gain is exact to the last bit.  Two factors of
one kind active together multiply, two offsets add, and a window of the
machine restores the nominal value when it ends (the nominal is the plant's
at construction of :class:`PlantFaults`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

from plant_rt._plant import Plant, Sample

#: Kinds applied by :class:`PlantFaults` to the plant between periods.
MACHINE_KINDS = ("dc_link_step", "demagnetisation", "resistance_drift")
#: Kinds that open a leg (:meth:`plant_rt.Plant.set_leg_faults`) between periods.
LEG_KINDS = ("open_phase", "open_switch")
#: Kinds applied to the measured sample (and the position sensor).
SENSOR_KINDS = (
    "current_offset",
    "current_gain",
    "current_stuck",
    "current_lost",
    "dc_voltage_offset",
    "position_sensor_lost",
)
_PHASE_INDEX = {"a": 0, "b": 1, "c": 2}


@dataclass(frozen=True, slots=True)
class FaultWindow:
    """One fault: ``kind`` over the periods ``[k0, k1)`` (``k1`` None: to the end)."""

    kind: str
    k0: int
    k1: int | None
    params: Mapping[str, Any]

    def active(self, k: int) -> bool:
        """Whether period (or sample instant) ``k`` lies in the window."""
        return self.k0 <= k and (self.k1 is None or k < self.k1)


class PlantFaults:
    """Applies the machine and sensor faults of a timeline to one plant.

    Parameters
    ----------
    plant : Plant
        The plant; its parameters at construction are the nominal ones.
    windows : sequence of FaultWindow
        The timeline; kinds other than :data:`MACHINE_KINDS`, :data:`LEG_KINDS`
        and :data:`SENSOR_KINDS` (the bus's) are ignored here.  Two leg faults
        on one leg: an open phase wins over an open switch, and both switches
        open are an open phase.
    """

    def __init__(self, plant: Plant, windows: Sequence[FaultWindow]) -> None:
        self.R_s = float(plant.motor.R_s)
        self.psi_f = float(plant.motor.psi_f)
        self.u_dc = float(plant.inverter.u_dc)
        self.machine = [w for w in windows if w.kind in MACHINE_KINDS]
        self.sensor = [w for w in windows if w.kind in SENSOR_KINDS]
        self.legs = [w for w in windows if w.kind in LEG_KINDS]
        self.windows = [*self.machine, *self.legs, *self.sensor]
        self._leg_state = ("none", "none", "none")
        self._state = (self.R_s, self.psi_f, self.u_dc)
        #: current_stuck: the held value per window (index in ``sensor``).
        self._held: dict[int, float] = {}
        self._last: Sample | None = None

    def parameters(self, k: int) -> tuple[float, float, float]:
        """``(R_s, psi_f, u_dc source)`` in force in period ``k``."""
        R, psi, u = self.R_s, self.psi_f, self.u_dc
        for w in self.machine:
            if not w.active(k):
                continue
            if w.kind == "resistance_drift":
                R *= float(w.params["R_s_factor"])
            elif w.kind == "demagnetisation":
                psi *= float(w.params["psi_f_factor"])
            else:
                u = float(w.params["u_dc_v"])
        return R, psi, u

    def leg_faults(self, k: int) -> tuple[str, str, str]:
        """The open-leg fault of each leg in period ``k`` (:data:`plant_rt._plant.LEG_FAULTS`)."""
        legs = ["none", "none", "none"]
        for w in self.legs:
            if not w.active(k):
                continue
            x = _PHASE_INDEX[str(w.params["phase"])]
            if w.kind == "open_phase":
                legs[x] = "open_phase"
            elif legs[x] != "open_phase":
                mine = "open_upper" if w.params["device"] == "upper" else "open_lower"
                legs[x] = mine if legs[x] in ("none", mine) else "open_phase"
        return legs[0], legs[1], legs[2]

    def before_period(self, plant: Plant) -> None:
        """Set the plant's parameters for period ``plant.k`` (call before its step and
        before its sample: a DC-link step is measured from its first instant)."""
        if self.legs:
            legs = self.leg_faults(plant.k)
            if legs != self._leg_state:
                plant.set_leg_faults(*legs)
                self._leg_state = legs
        if not self.machine:
            return
        now = self.parameters(plant.k)
        if now != self._state:
            R, psi, u = now
            plant.set_parameters(
                motor=replace(plant.motor, R_s=R, psi_f=psi),
                inverter=replace(plant.inverter, u_dc=u),
            )
            self._state = now

    def sample(self, s: Sample) -> Sample:
        """The sample ``s`` (measured at ``s.k``) with the active sensor faults applied."""
        last = self._last
        self._last = s
        if not self.sensor:
            return s
        i = [s.i_a, s.i_b, s.i_c]
        u = s.u_dc
        for n, w in enumerate(self.sensor):
            if not w.active(s.k):
                continue
            if w.kind == "dc_voltage_offset":
                u += float(w.params["v"])
                continue
            if w.kind == "position_sensor_lost":
                continue
            x = _PHASE_INDEX[str(w.params["phase"])]
            if w.kind == "current_offset":
                i[x] += float(w.params["a"])
            elif w.kind == "current_gain":
                i[x] *= float(w.params["factor"])
            elif w.kind == "current_lost":
                i[x] = 0.0
            else:  # current_stuck: the last sample before the window
                if n not in self._held:
                    src = last if last is not None and last.k == s.k - 1 else s
                    self._held[n] = (src.i_a, src.i_b, src.i_c)[x]
                i[x] = self._held[n]
        return replace(s, i_a=i[0], i_b=i[1], i_c=i[2], u_dc=u)

    def position_lost(self, k: int) -> bool:
        """Whether the position sensor is lost at instant ``k``."""
        return any(w.kind == "position_sensor_lost" and w.active(k) for w in self.sensor)

    def active(self, k: int) -> bool:
        """Whether any machine or sensor fault is active at ``k``."""
        return any(w.active(k) for w in self.windows)
