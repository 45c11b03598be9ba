"""The plant: IPMSM, inverter, mechanics, load and sensing, one PWM period per step.

Timing (DESIGN.md, "Timing model"): step ``k`` is the PWM period
``[k T_s, (k + 1) T_s)``. :meth:`Plant.sample` returns the measurement taken
at ``t = k T_s`` (symmetric PWM: the carrier peak falls on the period
boundary of the average model), :meth:`Plant.step` applies duties for period
``k`` and advances to ``k + 1``.

The arithmetic of every period is the portable C core's
(``plant_rt/core/``, one file per block: machine and flux map, RK4, PWM
timeline and dead time, DC link, sensors, protection, the period step);
this class holds the parameters, the states between periods and the
public API, and hands them to the core through ``plant_rt/_cplant.c``.

Integration: classic RK4 with ``substeps`` fixed steps per period on the
states ``(i_d, i_q, w_m, theta_m)``. The average inverter voltage is constant
over the period in the stationary alpha-beta frame, not in d-q, so every RK4
stage rotates it into d-q with the stage's own rotor angle (at 1 kHz and
300 rpm the rotor turns 0.126 rad electrical per period). The load torque is
evaluated once per substep, at its start. At high speed each step is cut
further, into ``ceil(|w_e| h)`` equal RK4 steps: the rotor-frame pole pair
at ``+-j w_e`` leaves RK4's stability region at ``|w_e| h = 2 sqrt(2)``
(derived in ``plant_rt/core/plant_rk4.h``). Below ``|w_e| h = 1``, every
paper scenario, the step is one.

Switching inverter (``InverterPars.model = "switching"``): the period is cut
at every switching edge, every end of a dead interval (``plant_rt/core/plant_pwm.h``),
the substep grid ``j T_s / substeps`` and the sensor instant, and each
sub-interval, over which every pole voltage is constant, is one RK4 step with
the rotor angle moving inside it. Exact sub-interval solutions (matrix
exponentials) would need a constant rotor angle and a linear machine; RK4
keeps the rotation, the saturation and the cross-saturation, and its error
on a sub-interval no longer than ``T_s / substeps`` is the average model's
(about ``(h / tau)^5 / 120`` with ``tau = L / R`` >= 18 ms for both presets).
A period has at most 3 legs x 5 instants (2 edges, 2 dead-interval ends, one
dead interval carried from the previous period) plus the grid and the
sensor instant, 18 sub-intervals; 14 is typical (three switching legs with
dead time, substeps = 2). A diode that stops conducting inside a dead
interval adds one (class notes).
"""

from __future__ import annotations

import math
import random
from array import array
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from plant_rt._engine import _cplant, resolve_engine
from plant_rt._inverter import InverterPars
from plant_rt._load import ConstantLoad, LoadProfile
from plant_rt._machine import FLUX_RANGE, MotorPars, cross_saturation_check, magnetic_energy
from plant_rt._sensors import SensorPars, Sensors

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True, slots=True)
class Sample:
    """Measurement taken at ``t = k T_s`` (sensor errors applied).

    Parameters
    ----------
    k : int
        Step counter.
    i_a, i_b, i_c : float
        Measured phase currents (A).
    u_dc : float
        Measured DC-link voltage (V).
    """

    k: int
    i_a: float
    i_b: float
    i_c: float
    u_dc: float


@dataclass(frozen=True, slots=True)
class Truth:
    """Plant truth at ``t = k T_s``, for the recorder only.

    Parameters
    ----------
    k : int
        Step counter.
    t : float
        Time (s).
    theta_e : float
        Electrical rotor angle, d axis on the magnet's north (rad, [0, 2 pi)).
    w_e : float
        Electrical speed (rad/s).
    theta_m : float
        Mechanical rotor angle (rad, [0, 2 pi)).
    w_m : float
        Mechanical speed (rad/s).
    tau_e : float
        Electromagnetic torque (N m).
    tau_L : float
        Load torque (N m); with an imposed speed, the torque the dynamometer
        applies to hold it (``tau_e - b w_m``).
    i_d, i_q : float
        True d-q currents (A).
    u_dc : float
        True DC-link voltage (V).
    """

    k: int
    t: float
    theta_e: float
    w_e: float
    theta_m: float
    w_m: float
    tau_e: float
    tau_L: float
    i_d: float
    i_q: float
    u_dc: float


@dataclass(slots=True)
class EnergyMeter:
    """Energy integrals since the plant was built (J), integrated with the states.

    Attributes
    ----------
    e_in : float
        Electrical input at the machine terminals, ``int sum_x v_x i_x dt``
        from the pole voltages and phase currents.
    e_cu : float
        Copper loss, ``int R_s (i_a^2 + i_b^2 + i_c^2) dt``.
    e_em : float
        Air-gap (electromagnetic) work, ``int tau_e w_m dt``.
    e_fric : float
        Friction loss, ``int b w_m^2 dt``.
    e_load : float
        Work done on the load (or dynamometer), ``int tau_L w_m dt``.
    q_a, q_b, q_c : float
        Charge through each phase during the last period (A s); divided by
        ``T_s`` it is the period-mean phase current.
    """

    e_in: float = 0.0
    e_cu: float = 0.0
    e_em: float = 0.0
    e_fric: float = 0.0
    e_load: float = 0.0
    q_a: float = 0.0
    q_b: float = 0.0
    q_c: float = 0.0


#: The open-leg faults of a leg (:meth:`Plant.set_leg_faults`), in the order of the
#: core's ``PLANT_LEG_*`` (``plant_rt/core/plant_leg.h``, where their equations are):
#: healthy, the phase's connection open, the upper switch open, the lower switch open.
LEG_FAULTS = ("none", "open_phase", "open_upper", "open_lower")


def _constant_tau(load: LoadProfile) -> float | None:
    """The torque of a :class:`ConstantLoad` (the compiled core then needs no call), else None."""
    return float(load.tau_L) if type(load) is ConstantLoad else None


class Plant:
    """IPMSM drive plant advanced one PWM period at a time.

    Parameters
    ----------
    motor : MotorPars
        Machine and mechanical parameters.
    inverter : InverterPars
        Inverter model, DC link, dead time and device drops.
    T_s : float
        PWM period (s).
    sensors : SensorPars, optional
        Sensor errors; ideal by default.
    load : LoadProfile, optional
        Load-torque profile; no load by default.
    substeps : int, optional
        RK4 steps per PWM period (average model), 1 to 64 (the core's
        ``PLANT_MAX_SUBSTEPS``, its fixed-size grid); the switching model cuts
        its sub-intervals at the same grid, so none is longer than
        ``T_s / substeps``, and evaluates the load torque at each grid point.
        A step of length ``h`` with ``|w_e| h > 1`` is taken in
        ``ceil(|w_e| h)`` equal RK4 steps (stability at high speed).
    saturation : bool, optional
        Use the saturated d-axis flux model (:class:`SaturationPars`).
    theta_m0, w_m0 : float, optional
        Initial mechanical angle (rad) and speed (rad/s).
    meter : bool, optional
        Integrate the energy flows (:class:`EnergyMeter`); slower.
    cross_saturation : bool, optional
        Use the cross-saturation flux map (:class:`CrossSaturationPars`,
        on top of the d-axis model when ``saturation`` is set).
    i_d0, i_q0 : float, optional
        Initial d- and q-axis currents (A).
    engine : {"auto", "compiled", "python"}, optional
        Kept for compatibility (``bench run --engine`` chooses the
        controller's engine): the plant runs its C core for every choice
        (:mod:`plant_rt._engine`); :attr:`engine` is ``"compiled"``.

    Notes
    -----
    Switching inverter. Each leg's pole voltage over a sub-interval follows
    its gate state (``plant_rt/core/plant_pwm.h``) and the direction of its phase
    current at the start of the sub-interval (a conducting device's drop
    does not change sign inside one)::

        upper on:  u_dc - v_ce (i > 0, transistor)  or  u_dc + v_f (i < 0, diode)
        lower on:  -v_f       (i > 0, diode)       or  +v_ce      (i < 0, transistor)
        dead:      -v_f       (i > 0, lower diode) or  u_dc + v_f (i < 0, upper diode)

    Zero-current clamp. In a dead interval the current can only flow
    through a diode, which blocks it from reversing. When the voltage
    drives a diode's current through zero before the dead interval ends,
    the diode stops conducting there and the phase floats with zero current
    until the incoming switch turns on: the sub-interval is integrated
    once, the zero crossing located by linear interpolation of that phase's
    current, the step redone up to it, the phase current projected to zero
    and the rest integrated with the phase floating (pole voltage solved
    from ``d i_x / dt = 0``, the same floating-phase model as the disabled
    bridge below). A dead leg whose current is zero at the start floats at
    once; if its floating voltage lies beyond a diode's threshold
    (``u_dc + v_f`` or ``-v_f``) that diode conducts instead. Two floating
    legs leave no current path: the currents stay zero for the rest of that
    dead interval. A gated leg whose current is zero (within 1e-9 i_max) has
    no drop.

    DC link. With ``r_dc > 0`` the DC-link voltage is the capacitor voltage,
    ``c_dc d u_dc / dt = (u_src - u_dc) / r_dc - i_dc`` (``u_src`` =
    ``InverterPars.u_dc``), or ``u_dc = u_src - r_dc i_dc`` without a
    capacitor. ``i_dc`` is the current of the legs on the positive rail
    (upper switch or upper diode); the average model takes its period mean
    ``sum_x d_x i_x``. Each sub-interval (substep) uses the voltage at its
    start and then advances the capacitor exactly (exponential with
    ``r_dc c_dc``) for the mean of ``i_dc`` at its start and end, so the
    switching model resolves the ripple edge to edge. Without a capacitor
    the link voltage is set from ``i_dc`` at the start of each
    sub-interval: in the switching model it droops only while a pulse
    draws current, whereas the average model applies the mean droop to the
    whole period (the limit of a large capacitor).

    Disabled inverter (``enable=False``, all switches open): the legs become
    a diode bridge. A conducting phase sits on the negative rail when its
    current flows into the machine and on the positive rail otherwise, so
    the currents freewheel against the DC link. A phase whose current is
    zero floats: its pole voltage is solved from ``d i_x / dt = 0`` and,
    if it leaves [0, u_dc], that phase's diode starts to conduct. With all
    currents zero the bridge starts to rectify when the line back-EMF
    exceeds ``u_dc``. Simplifications: diodes are ideal (no forward
    voltage), and the conduction state is decided at the start of each
    substep; a phase whose current changes sign within a substep is set to
    zero at its end (projection), so the current-zero instant is resolved
    to one substep.

    Open legs (:meth:`set_leg_faults`, ``plant_rt/core/plant_leg.h``): an
    open phase's leg is a dead leg whose diodes carry its current to zero
    (the zero-current clamp above) and which then floats for good, its
    voltage never clamped to a rail; an open switch turns the gate's
    on-intervals of that device into dead intervals. The average model
    takes the period means of the same rules: a leg whose current the open
    device would carry sits on the diode's rail, one at zero current floats
    between the diode's rail and its PWM mean.
    """

    def __init__(
        self,
        motor: MotorPars,
        inverter: InverterPars,
        T_s: float,
        sensors: SensorPars | None = None,
        load: LoadProfile | None = None,
        substeps: int = 2,
        saturation: bool = False,
        theta_m0: float = 0.0,
        w_m0: float = 0.0,
        meter: bool = False,
        cross_saturation: bool = False,
        i_d0: float = 0.0,
        i_q0: float = 0.0,
        engine: str = "auto",
    ) -> None:
        if not T_s > 0.0:
            raise ValueError(f"T_s must be > 0, got {T_s}")
        if int(substeps) != substeps or not 1 <= substeps <= _cplant.MAX_SUBSTEPS:
            raise ValueError(
                f"substeps must be an integer in 1..{_cplant.MAX_SUBSTEPS}, got {substeps}"
            )
        sens = sensors if sensors is not None else SensorPars()
        if not sens.t_delay < T_s:
            raise ValueError(f"SensorPars.t_delay must be below T_s = {T_s} s, got {sens.t_delay}")
        if cross_saturation:
            cross_saturation_check(motor, bool(saturation), FLUX_RANGE * motor.i_max)
        self.motor = motor
        self.inverter = inverter
        self.T_s = float(T_s)
        self.substeps = int(substeps)
        self.saturation = bool(saturation)
        self.cross_saturation = bool(cross_saturation)
        self.sensor_pars = sens
        self._sensors = Sensors(self.sensor_pars)
        self._load: LoadProfile = load if load is not None else ConstantLoad(0.0)
        self.k = 0
        # States.
        self._i_d = float(i_d0)
        self._i_q = float(i_q0)
        self._w_m = float(w_m0)
        self._th_m = float(theta_m0) % TWO_PI
        self._w_imp: float | None = None
        self._u_dc = float(inverter.u_dc)
        self.meter: EnergyMeter | None = EnergyMeter() if meter else None
        self._sample: Sample | None = None
        # Mean stator voltage in alpha-beta over the last period (V).
        self.u_s_ab = (0.0, 0.0)
        self._switching = inverter.model == "switching"
        self._pwm_peak = inverter.sample_at == "peak"
        # Sensor delay: the state at T_s - t_delay of each period, sampled at the next.
        self._t_meas = self.T_s - sens.t_delay if sens.t_delay > 0.0 else 0.0
        self._meas: tuple[int, float, float, float, float] | None = None
        self.engine = resolve_engine(engine, meter)
        if not 0.0 <= inverter.t_dead < 0.5 * self.T_s:
            raise ValueError(
                f"dead time must be in [0, T_s / 2), got {inverter.t_dead} s at T_s = {self.T_s} s"
            )
        self.motor = motor
        self.inverter = inverter
        # The core (plant_rt/core) makes its constants from the design
        # parameters and keeps the states; step() copies them back each period.
        self._core = _cplant.Core(*self._core_pars())
        self._core.set_sensors(*self._sensors.constants())
        self._core.set_load(self._load.tau, _constant_tau(self._load))
        self._core.set_metering(meter)
        self._legs: tuple[str, str, str] = ("none", "none", "none")
        self._state_to_core()

    def set_parameters(
        self, motor: MotorPars | None = None, inverter: InverterPars | None = None
    ) -> None:
        """Change the motor's or the inverter's parameters between two periods.

        The states (currents, speed, angle, DC-link capacitor voltage, the
        PWM timeline's dead intervals) are kept; the next :meth:`step` runs
        on the new parameters. This is how a fault or a drift is inserted
        (e.g. ``plant.set_parameters(motor=replace(plant.motor, R_s=1.2 *
        plant.motor.R_s))``, a weaker magnet through ``psi_f``, a sagging
        supply through ``InverterPars.u_dc``). Without a dynamic DC link
        (``r_dc = 0``) the link voltage follows the new ``u_dc`` at once.

        Parameters
        ----------
        motor : MotorPars, optional
            New machine parameters; None keeps the present ones.
        inverter : InverterPars, optional
            New inverter parameters; None keeps the present ones. Its
            ``model`` and ``sample_at`` cannot change.

        Raises
        ------
        ValueError
            For an inverter of another model or carrier alignment, a dead
            time of ``T_s / 2`` or more, or a cross-saturation map the new
            motor makes non-physical (:func:`cross_saturation_check`).
        """
        m = motor if motor is not None else self.motor
        inv = inverter if inverter is not None else self.inverter
        if inv.model != self.inverter.model or inv.sample_at != self.inverter.sample_at:
            raise ValueError(
                "set_parameters: the inverter's model and sample_at cannot change "
                f"({self.inverter.model}/{self.inverter.sample_at} -> {inv.model}/{inv.sample_at})"
            )
        if not 0.0 <= inv.t_dead < 0.5 * self.T_s:
            raise ValueError(
                f"set_parameters: dead time must be in [0, T_s / 2), got {inv.t_dead} s"
            )
        if self.cross_saturation:
            cross_saturation_check(m, self.saturation, FLUX_RANGE * m.i_max)
        self.motor = m
        self.inverter = inv
        if not inv.r_dc > 0.0:
            self._u_dc = float(inv.u_dc)
        self._core.set_pars(*self._core_pars())
        self._state_to_core()
        self._sample = None  # a measurement of this instant taken before reads the new u_dc

    def set_leg_faults(self, a: str = "none", b: str = "none", c: str = "none") -> None:
        """Open a phase or one switch of a leg from the next period on (a fault).

        Each leg is one of :data:`LEG_FAULTS`: ``"none"``; ``"open_phase"``
        (both switches off and the phase's connection open once its current,
        freewheeling through the leg's diodes, reaches zero; then held at
        zero); ``"open_upper"`` or ``"open_lower"`` (that switch never
        conducts, its antiparallel diode does). The equations, and the
        textbook they follow, are in ``plant_rt/core/plant_leg.h``; with
        every leg ``"none"`` the plant is the healthy one, bit for bit.

        Raises
        ------
        ValueError
            For a name not in :data:`LEG_FAULTS`.
        """
        legs = (a, b, c)
        for x, f in zip("abc", legs, strict=True):
            if f not in LEG_FAULTS:
                raise ValueError(f"set_leg_faults: leg {x}: {f!r} is not one of {LEG_FAULTS}")
        self._core.set_legs(*(LEG_FAULTS.index(f) for f in legs))
        self._legs = legs

    @property
    def leg_faults(self) -> tuple[str, str, str]:
        """The open-leg fault of each leg (:meth:`set_leg_faults`)."""
        return self._legs

    # ------------------------------------------------------------------ API
    @property
    def t(self) -> float:
        """Time of the present sample instant, ``k T_s`` (s)."""
        return self.k * self.T_s

    @property
    def out_of_range_periods(self) -> int:
        """Periods that ended with ``|i_s|`` beyond the flux map's checked range.

        The range is ``FLUX_RANGE i_max`` (:data:`plant_rt._machine.FLUX_RANGE`), where
        :func:`cross_saturation_check` proves the cross-saturated map physical; beyond
        it the core continues the map so that it stays positive definite, but that
        continuation was not identified on any machine (nor were the linear and the
        d-axis saturated maps, positive definite everywhere, identified that far), so a
        run that goes there is not a result of the modelled motor. Counted for every
        flux map.
        """
        return self._core.out_of_range()

    @property
    def load(self) -> LoadProfile:
        """The present load profile."""
        return self._load

    def set_load(self, profile: LoadProfile) -> None:
        """Replace the load profile (times in the profile are absolute, s)."""
        self._load = profile
        self._core.set_load(profile.tau, _constant_tau(profile))

    def impose_speed(self, w_m: float | None) -> None:
        """Hold the mechanical speed at ``w_m`` (rad/s) like a dynamometer; None releases it."""
        if w_m is None:
            self._w_imp = None
        else:
            self._w_imp = float(w_m)
            self._w_m = self._w_imp
        self._state_to_core()

    def imposed_speed(self) -> float | None:
        """The speed the dynamometer holds (rad/s), or None."""
        return self._w_imp

    def currents_abc(self) -> tuple[float, float, float]:
        """True phase currents at ``t = k T_s`` (A)."""
        return self._core.currents()

    def sample(self) -> Sample:
        """Measurement at ``t = k T_s``; repeated calls within a period return the same one.

        With a sensor delay (``SensorPars.t_delay``) the values are those of
        ``k T_s - t_delay``, recorded while the previous period was
        integrated (the present values at ``k = 0`` or after a jump in ``k``).
        """
        smp = self._sample
        if smp is not None and smp.k == self.k:
            return smp
        meas = self._meas
        if meas is not None and meas[0] == self.k:
            m_a, m_b, m_c, m_u = self._core.measure(meas[1], meas[2], meas[3], meas[4])
        else:
            m_a, m_b, m_c, m_u = self._core.measure()
        smp = Sample(self.k, m_a, m_b, m_c, m_u)
        self._sample = smp
        return smp

    def protection_inputs(self) -> tuple[float, float, float, float, float]:
        """What an inverter's protection sees at ``t = k T_s``.

        Returns
        -------
        tuple of float
            True phase currents ``i_a, i_b, i_c`` (A), DC-link voltage
            ``u_dc`` (V) and mechanical speed ``w_m`` (rad/s), the inputs of
            :meth:`plant_rt.Protection.check`.
        """
        i_a, i_b, i_c = self.currents_abc()
        return i_a, i_b, i_c, self._u_dc, self._w_m

    def torque(self) -> float:
        """Electromagnetic torque at ``t = k T_s`` (N m)."""
        return self._core.torque()

    def truth(self) -> Truth:
        """Plant truth at ``t = k T_s``."""
        tau_e = self.torque()
        w_m = self._w_m
        imposed = self._w_imp is not None
        n_p = float(self.motor.n_p)
        tau_L = tau_e - float(self.motor.b) * w_m if imposed else self._load.tau(self.t, w_m)
        return Truth(
            k=self.k,
            t=self.t,
            theta_e=(n_p * self._th_m) % TWO_PI,
            w_e=n_p * w_m,
            theta_m=self._th_m,
            w_m=w_m,
            tau_e=tau_e,
            tau_L=tau_L,
            i_d=self._i_d,
            i_q=self._i_q,
            u_dc=self._u_dc,
        )

    def stored_energy(self) -> tuple[float, float]:
        """Magnetic field energy and kinetic energy at ``t = k T_s`` (J)."""
        w_mag = magnetic_energy(
            self.motor, self._i_d, self._i_q, self.saturation, self.cross_saturation
        )
        return w_mag, 0.5 * self.motor.J * self._w_m * self._w_m

    def back_emf_abc(self) -> tuple[float, float, float]:
        """Phase back-EMF ``-w_e psi_d(0) sin(theta_e - phi_x)`` at ``t = k T_s`` (V)."""
        return self._core.back_emf()

    def step(self, d_a: float, d_b: float, d_c: float, enable: bool = True) -> None:
        """Apply duties for period ``k`` and advance to ``k + 1``.

        Parameters
        ----------
        d_a, d_b, d_c : float
            Duty cycles of the phase legs; clamped to [0, 1].
        enable : bool
            False opens all switches (diode bridge, see class notes).
        """
        core = self._core
        t0 = self.k * self.T_s
        st = core.step(d_a, d_b, d_c, t0) if enable else core.step_off(t0)
        (self._i_d, self._i_q, self._w_m, self._th_m, self._u_dc, u_al, u_be) = st
        self.u_s_ab = (u_al, u_be)
        self.k += 1
        if self._t_meas > 0.0:
            i_a, i_b, i_c, u_dc = core.meas()
            self._meas = (self.k, i_a, i_b, i_c, u_dc)
        if self.meter is not None:
            m = self.meter
            (m.e_in, m.e_cu, m.e_em, m.e_fric, m.e_load, m.q_a, m.q_b, m.q_c) = core.meter()

    def _core_pars(self) -> tuple[float | int | bool, ...]:
        """The design parameters in the order of ``plant_pars`` (``plant_rt/core/plant.h``)."""
        m = self.motor
        inv = self.inverter
        return (
            float(m.n_p),
            float(m.R_s),
            float(m.L_d),
            float(m.L_q),
            float(m.psi_f),
            float(m.J),
            float(m.b),
            float(m.i_max),
            float(m.sat.sigma),
            float(m.sat.i_sat),
            float(m.cross.c_dq),
            self.saturation,
            self.cross_saturation,
            self.T_s,
            self.substeps,
            float(self.sensor_pars.t_delay),
            self._switching,
            self._pwm_peak,
            float(inv.u_dc),
            float(inv.t_dead),
            float(inv.v_ce),
            float(inv.v_f),
            float(inv.r_dc),
            float(inv.c_dc),
        )

    def step_n(self, duties: Iterable[Sequence[float]]) -> array:
        """Apply the duties of ``n`` enabled periods in one call and advance to ``k + n``.

        The periods are those of ``n`` calls of :meth:`step` (the same
        trace bit for bit) without a :meth:`sample` between them: the
        compiled core steps them in one C call (``plant_step_n``,
        ``plant_rt/core/plant.h``).

        Parameters
        ----------
        duties : iterable of (d_a, d_b, d_c)
            Duty cycles per period; clamped to [0, 1].

        Returns
        -------
        array.array of float
            Seven values per period, after it: ``i_d, i_q, w_m, theta_m,
            u_dc`` and the period's mean stator voltage ``u_alpha, u_beta``.
        """
        flat = array("d")
        for d in duties:
            if len(d) != 3:
                raise ValueError(f"step_n: three duties per period, got {len(d)}")
            flat.extend(d)
        n = len(flat) // 3
        out = array("d")
        core = self._core
        if n == 0:
            return out
        out.frombytes(core.step_n(self.k, flat))
        (self._i_d, self._i_q, self._w_m, self._th_m, self._u_dc, u_al, u_be) = out[-7:]
        self.u_s_ab = (u_al, u_be)
        self.k += n
        if self._t_meas > 0.0:
            i_a, i_b, i_c, u_dc = core.meas()
            self._meas = (self.k, i_a, i_b, i_c, u_dc)
        if self.meter is not None:
            m = self.meter
            (m.e_in, m.e_cu, m.e_em, m.e_fric, m.e_load, m.q_a, m.q_b, m.q_c) = core.meter()
        return out

    def core_address(self) -> int:
        """The address of the core's instance (``plant *``, ``plant_rt/core/plant.h``).

        For a C caller that steps this plant itself (the native plant node,
        ``bench/nodes/native/bn_plant.h``); valid while this plant lives.
        After it stepped, :meth:`adopt_core` takes the states back.
        """
        return self._core.address()

    def noise_generator(self) -> random.Random:
        """The sensors' noise generator (for a C caller that takes its values in order)."""
        return self._sensors.rng

    def meas_step(self) -> int:
        """The period whose sample the sensor-instant record holds (-1: none)."""
        return self._meas[0] if self._meas is not None else -1

    def adopt_core(self, k: int, meas_k: int) -> None:
        """Take the core's states after a C caller stepped it to period ``k``.

        ``meas_k``: the step of the core's sensor-instant record (``meas()``),
        -1 for none. A constant load the caller set becomes :attr:`load`, and the
        energy meter's integrals are the core's.
        """
        core = self._core
        (self._i_d, self._i_q, self._w_m, self._th_m, self._u_dc, u_al, u_be) = core.state()
        self.u_s_ab = (u_al, u_be)
        self.k = int(k)
        self._sample = None
        if meas_k >= 0 and self._t_meas > 0.0:
            i_a, i_b, i_c, u_dc = core.meas()
            self._meas = (int(meas_k), i_a, i_b, i_c, u_dc)
        tau = core.load_const()
        if tau is not None and _constant_tau(self._load) != tau:
            self._load = ConstantLoad(tau)
        if self.meter is not None:  # the core integrated it
            m = self.meter
            (m.e_in, m.e_cu, m.e_em, m.e_fric, m.e_load, m.q_a, m.q_b, m.q_c) = core.meter()

    def _state_to_core(self) -> None:
        """Hand the states changed on the Python side to the core."""
        self._core.set_state(
            self._i_d, self._i_q, self._w_m, self._th_m, self._u_dc, self._w_imp is not None
        )
