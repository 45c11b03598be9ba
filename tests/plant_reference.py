"""The plant's reference model in Python: the readable oracle of ``plant_rt/core``.

This is the plant's per-period step as it was written in Python before the
portable C core took its place (``plant_rt/_plant.py``, ``_pwm.py``,
``_sensors.py`` and the flux map of ``_machine.py``): the same equations
with the same operation order, kept here as a reference model, not as a
second product. ``tests/test_plant_engine.py`` checks :class:`plant_rt.Plant`
against :class:`ReferencePlant` at a tolerance of zero: the same states,
samples and energy integrals bit for bit, feature by feature and in a
closed loop. A change of an equation in the core is a change here, made in
the same commit.
"""

from __future__ import annotations

import math
import random

from plant_rt import ConstantLoad, InverterPars, LoadProfile, MotorPars, SensorPars
from plant_rt._machine import FLUX_FADE, FLUX_RANGE, cross_saturation_check
from plant_rt._plant import EnergyMeter, Sample, Truth

SQRT3 = math.sqrt(3.0)
INV_SQRT3 = 1.0 / SQRT3
TWO_PI = 2.0 * math.pi
# Phase axes a, b, c at 0, +120 and -120 degrees.
_COS_PHI = (1.0, -0.5, -0.5)
_SIN_PHI = (0.0, 0.5 * SQRT3, -0.5 * SQRT3)
# RK4 stages: (offset as a fraction of the step, weight).
_RK4_STAGES = ((0.0, 1.0), (0.5, 2.0), (0.5, 2.0), (1.0, 1.0))


def magnetic_energy(
    motor: MotorPars, i_d: float, i_q: float, saturation: bool, cross: bool
) -> float:
    from plant_rt._machine import magnetic_energy as m

    return m(motor, i_d, i_q, saturation, cross)


def flux_d(motor: MotorPars, i_d: float, saturation: bool) -> tuple[float, float]:
    """d-axis flux linkage and incremental inductance.

    Integral of :class:`SaturationPars`' incremental inductance::

        psi_d(i_d) = psi_f + L_d (i_d - sigma i_sat (sqrt(1 + x^2) - 1))

    The apparent inductance ``(psi_d - psi_f) / i_d`` and the incremental
    inductance ``L_dd`` come from the same function, so the model is
    energy-consistent (see :func:`magnetic_energy`).

    Parameters
    ----------
    motor : MotorPars
        Machine parameters.
    i_d : float
        d-axis current (A).
    saturation : bool
        False gives the linear model ``psi_f + L_d i_d``.

    Returns
    -------
    psi_d : float
        d-axis flux linkage (Wb).
    L_dd : float
        Incremental d-axis inductance (H).
    """
    if not saturation:
        return motor.psi_f + motor.L_d * i_d, motor.L_d
    sat = motor.sat
    x = i_d / sat.i_sat
    r = math.sqrt(1.0 + x * x)
    psi_d = motor.psi_f + motor.L_d * (i_d - sat.sigma * sat.i_sat * (r - 1.0))
    return psi_d, motor.L_d * (1.0 - sat.sigma * x / r)


def flux_dq(
    motor: MotorPars, i_d: float, i_q: float, saturation: bool, cross: bool
) -> tuple[float, float, float, float, float]:
    """Flux linkages and incremental inductances in the rotor frame.

    The d-axis model of :func:`flux_d` plus, with ``cross``, the
    cross-saturation of :class:`CrossSaturationPars`.

    Parameters
    ----------
    motor : MotorPars
        Machine parameters.
    i_d, i_q : float
        d- and q-axis currents (A).
    saturation : bool
        Use the saturated d-axis model.
    cross : bool
        Use the cross-saturation model.

    Returns
    -------
    psi_d, psi_q : float
        Flux linkages (Wb).
    L_dd, L_dq, L_qq : float
        Incremental inductances ``d psi_d / d i_d``, ``d psi_d / d i_q =
        d psi_q / d i_d`` and ``d psi_q / d i_q`` (H).
    """
    psi_d, L_dd = flux_d(motor, i_d, saturation)
    L_q = motor.L_q
    if not cross:
        return psi_d, L_q * i_q, L_dd, 0.0, L_q
    c = motor.cross.c_dq
    i_0 = motor.psi_f / motor.L_d
    x_lim = FLUX_RANGE * motor.i_max
    if abs(i_d) > x_lim or abs(i_q) > x_lim:
        return cross_ext(motor, i_d, i_q, psi_d, L_dd)
    m = i_d + i_0
    # in the operation order of the plant core's one home of these terms (plant_flux_cross)
    hq = 0.5 * c * i_q
    L_qq = L_q - 0.5 * c * i_d * (i_d + 2.0 * i_0)
    return (psi_d - hq * m * i_q, L_qq * i_q, L_dd - hq * i_q, -c * m * i_q, L_qq)


def _limit(u: float, a: float, w: float) -> tuple[float, float, float]:
    """``s(u)``, ``s'(u)``, ``s''(u)`` of the cross map's current limit (plant_flux_cross_ext)."""
    if abs(u) <= a:
        return u, 1.0, 0.0
    e = a if u > 0.0 else -a
    t = 1.0 - 2.0 / (math.exp(2.0 * (u - e) / w) + 1.0)
    s1 = 1.0 - t * t
    return e + w * t, s1, -2.0 * t * s1 / w


def cross_ext(
    motor: MotorPars, i_d: float, i_q: float, psi_d: float, L_dd: float
) -> tuple[float, float, float, float, float]:
    """The cross map beyond its checked range (``plant_flux_cross_ext``, the same operations):
    the co-energy ``-(c/4) (m_d^2 - i_0^2) i_q^2`` at the currents limited by :func:`_limit`."""
    c = motor.cross.c_dq
    i_0 = motor.psi_f / motor.L_d
    a = FLUX_RANGE * motor.i_max
    w = FLUX_FADE * a
    sd, sd1, sd2 = _limit(i_d, a, w)
    sq, sq1, sq2 = _limit(i_q, a, w)
    m = sd + i_0
    p = m * m - i_0 * i_0
    g_d = -0.5 * c * m * sq * sq
    g_q = -0.5 * c * p * sq
    return (
        psi_d + g_d * sd1,
        motor.L_q * i_q + g_q * sq1,
        L_dd + (-0.5 * c * sq * sq * sd1 * sd1 + g_d * sd2),
        -c * m * sq * sd1 * sq1,
        motor.L_q - 0.5 * c * p * sq1 * sq1 + g_q * sq2,
    )


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
    if i_x > 0.0:
        return -(d_x * v_ce + (1.0 - d_x) * v_f)
    if i_x < 0.0:
        return d_x * v_f + (1.0 - d_x) * v_ce
    return 0.0


LOW = 0
"""Lower switch gated on: the pole sits on the negative rail (less a device drop)."""
HIGH = 1
"""Upper switch gated on: the pole sits on the positive rail (less a device drop)."""
DEAD = 2
"""Both switches off: a diode or the floating phase sets the pole voltage."""
_OFF = -1  # command after a disabled period: neither switch


class PwmTimeline:
    """Gate states of the three legs over each PWM period.

    Parameters
    ----------
    T_s : float
        PWM period (s).
    t_dead : float
        Dead time (s), >= 0 and below ``T_s / 2``.
    sample_at : {"peak", "valley"}
        Carrier extremum on the period boundary.
    """

    __slots__ = ("T_s", "_cmd", "_dead_end", "_peak", "t_dead")

    def __init__(self, T_s: float, t_dead: float, sample_at: str) -> None:
        if not 0.0 <= t_dead < 0.5 * T_s:
            raise ValueError(f"dead time must be in [0, T_s / 2), got {t_dead} s at T_s = {T_s} s")
        self.T_s = float(T_s)
        self.t_dead = float(t_dead)
        self._peak = sample_at == "peak"
        level = LOW if self._peak else HIGH
        # Commanded level at the end of the last period, and the end of a dead
        # interval that runs into the next period (s, from its start; <= 0: none).
        self._cmd = [level, level, level]
        self._dead_end = [0.0, 0.0, 0.0]

    def disable(self) -> None:
        """All switches opened for a period: each leg's next command is a turn-on edge."""
        self._cmd = [_OFF, _OFF, _OFF]
        self._dead_end = [0.0, 0.0, 0.0]

    def period(
        self, d_a: float, d_b: float, d_c: float, cuts: tuple[float, ...]
    ) -> list[tuple[float, float, int, int, int]]:
        """Sub-intervals of the next period with constant gate states.

        Parameters
        ----------
        d_a, d_b, d_c : float
            Duties, already clamped to [0, 1].
        cuts : tuple of float
            Extra instants in (0, T_s) where a sub-interval must end (the
            integration grid, the sensor instant), ascending.

        Returns
        -------
        list of (t_start, t_end, s_a, s_b, s_c)
            Times from the period start (s), covering [0, T_s) without gaps;
            states :data:`LOW`, :data:`HIGH` or :data:`DEAD`.
        """
        T = self.T_s
        la = self._leg(0, d_a)
        lb = self._leg(1, d_b)
        lc = self._leg(2, d_c)
        times = {T}
        for pts in (la, lb, lc):
            for t, _ in pts:
                if t > 0.0:
                    times.add(t)
        for t in cuts:
            times.add(t)
        ja = jb = jc = 0
        na, nb, nc = len(la), len(lb), len(lc)
        sa, sb, sc = la[0][1], lb[0][1], lc[0][1]
        out: list[tuple[float, float, int, int, int]] = []
        t0 = 0.0
        for t1 in sorted(times):
            while ja + 1 < na and la[ja + 1][0] <= t0:
                ja += 1
                sa = la[ja][1]
            while jb + 1 < nb and lb[jb + 1][0] <= t0:
                jb += 1
                sb = lb[jb][1]
            while jc + 1 < nc and lc[jc + 1][0] <= t0:
                jc += 1
                sc = lc[jc][1]
            if t1 > t0:
                out.append((t0, t1, sa, sb, sc))
                t0 = t1
        return out

    def _leg(self, x: int, d: float) -> list[tuple[float, int]]:
        """Change points ``(t, state)`` of leg ``x`` over the period, the first at t = 0."""
        T = self.T_s
        t_d = self.t_dead
        prof: tuple[tuple[float, int], ...]
        if d >= 1.0:
            prof = ((0.0, HIGH),)
        elif d <= 0.0:
            prof = ((0.0, LOW),)
        elif self._peak:
            prof = ((0.0, LOW), (0.5 * (1.0 - d) * T, HIGH), (0.5 * (1.0 + d) * T, LOW))
        else:
            prof = ((0.0, HIGH), (0.5 * d * T, LOW), (T - 0.5 * d * T, HIGH))
        tol = 1e-9 * T  # instants closer than this coincide (rounding of d T / 2 + t_dead)
        level = self._cmd[x]
        du = self._dead_end[x]  # end of the pending dead interval
        pts: list[tuple[float, int]] = [(0.0, DEAD if du > tol else level)]
        for e, new in prof:
            if new == level:
                continue
            if tol < du < e - tol:  # the pending dead interval ends before this edge
                pts.append((du, level))
            level = new
            if t_d > 0.0:
                du = e + t_d
                state = DEAD
            else:
                du = 0.0
                state = new
            if pts[-1][0] == e:
                pts[-1] = (e, state)
            else:
                pts.append((e, state))
        if tol < du < T - tol:
            pts.append((du, level))
            du = 0.0
        self._cmd[x] = level
        self._dead_end[x] = du - T if du > T + tol else 0.0
        return pts


class Sensors:
    """Stateful sensing chain (owns the noise generator).

    Parameters
    ----------
    pars : SensorPars
        Sensor errors.
    """

    __slots__ = ("_code_max", "_g", "_lsb_i", "_lsb_u", "_o", "_rng", "_ucode_max", "pars")

    def __init__(self, pars: SensorPars) -> None:
        self.pars = pars
        self._rng = random.Random(pars.seed)
        self._g = tuple(float(g) for g in pars.gain_abc)
        self._o = tuple(float(o) for o in pars.offset_abc)
        self._lsb_i = pars.lsb_i
        self._lsb_u = pars.lsb_u
        bits = pars.bits or 1
        self._code_max = 2 ** (bits - 1) - 1
        self._ucode_max = 2**bits - 1

    def constants(self) -> tuple[float | int | random.Random, ...]:
        """The constants of the sensors."""
        p = self.pars
        return (
            *self._g,
            *self._o,
            self._lsb_i,
            self._code_max,
            p.noise_i,
            p.gain_u_dc,
            p.offset_u_dc,
            self._lsb_u,
            self._ucode_max,
            p.noise_u,
            self._rng,
        )

    def _quant_i(self, x: float) -> float:
        lsb = self._lsb_i
        if lsb == 0.0:
            return x
        code = math.floor(x / lsb + 0.5)
        code = max(-self._code_max - 1, min(self._code_max, code))
        return code * lsb

    def currents(self, i_a: float, i_b: float, i_c: float) -> tuple[float, float, float]:
        """Measured phase currents (A)."""
        g = self._g
        o = self._o
        m_a = g[0] * i_a + o[0]
        m_b = g[1] * i_b + o[1]
        m_c = g[2] * i_c + o[2]
        sd = self.pars.noise_i
        if sd > 0.0:
            gauss = self._rng.gauss
            m_a += gauss(0.0, sd)
            m_b += gauss(0.0, sd)
            m_c += gauss(0.0, sd)
        return self._quant_i(m_a), self._quant_i(m_b), self._quant_i(m_c)

    def voltage(self, u_dc: float) -> float:
        """Measured DC-link voltage (V)."""
        p = self.pars
        m = p.gain_u_dc * u_dc + p.offset_u_dc
        if p.noise_u > 0.0:
            m += self._rng.gauss(0.0, p.noise_u)
        lsb = self._lsb_u
        if lsb == 0.0:
            return m
        code = max(0, min(self._ucode_max, math.floor(m / lsb + 0.5)))
        return code * lsb


class ReferencePlant:
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
        RK4 steps per PWM period (average model); the switching model cuts
        its sub-intervals at the same grid, so none is longer than
        ``T_s / substeps``, and evaluates the load torque at each grid point.
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

    Notes
    -----
    Switching inverter. Each leg's pole voltage over a sub-interval follows
    its gate state (:mod:`plant_rt._pwm`) and the direction of its phase
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
    ) -> None:
        if not T_s > 0.0:
            raise ValueError(f"T_s must be > 0, got {T_s}")
        if int(substeps) != substeps or substeps < 1:
            raise ValueError(f"substeps must be a positive integer, got {substeps}")
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
        # Constants for the per-step code (Python floats).
        self._n_p = float(motor.n_p)
        self._R = float(motor.R_s)
        self._L_d = float(motor.L_d)
        self._L_q = float(motor.L_q)
        self._psi_f = float(motor.psi_f)
        self._b = float(motor.b)
        self._inv_J = 1.0 / motor.J
        self._k_tau = 1.5 * motor.n_p
        self._sig = float(motor.sat.sigma)
        self._inv_i_sat = 1.0 / motor.sat.i_sat
        self._sig_isat = motor.sat.sigma * motor.sat.i_sat
        self._u_dc = float(inverter.u_dc)
        self._h = self.T_s / self.substeps
        self._i_eps = 1e-9 * max(1.0, motor.i_max)
        self.meter: EnergyMeter | None = EnergyMeter() if meter else None
        self._sample: Sample | None = None
        # Mean stator voltage in alpha-beta over the last period (V).
        self.u_s_ab = (0.0, 0.0)
        # Cross-saturation constants.
        self._c_dq = float(motor.cross.c_dq)
        self._i_0 = motor.psi_f / motor.L_d
        # Inverter: switching timeline, device drops, DC link.
        self._switching = inverter.model == "switching"
        self._pwm = (
            PwmTimeline(self.T_s, inverter.t_dead, inverter.sample_at) if self._switching else None
        )
        self._v_ce = float(inverter.v_ce)
        self._v_f = float(inverter.v_f)
        self._drops = inverter.v_ce > 0.0 or inverter.v_f > 0.0
        self._u_src = float(inverter.u_dc)
        self._r_dc = float(inverter.r_dc)
        self._c_dc = float(inverter.c_dc)
        self._dc_dyn = inverter.r_dc > 0.0
        # Sensor delay: the state at T_s - t_delay of each period, sampled at the next.
        self._t_meas = self.T_s - sens.t_delay if sens.t_delay > 0.0 else 0.0
        self._meas: tuple[int, float, float, float, float] | None = None
        # Cut points of the switching model's sub-intervals: the substep grid
        # (load evaluated at each) and the sensor instant.
        grid = [j * self._h for j in range(1, self.substeps)]
        self._grid = (0.0, *grid)
        cuts = set(grid)
        if self._t_meas > 0.0:
            cuts.add(self._t_meas)
        self._cuts = tuple(sorted(cuts))
        self._segs = self._segments()
        # Average model on the legacy per-period path unless a feature needs substeps.
        self._avg_general = self._dc_dyn or self._t_meas > 0.0

    # ------------------------------------------------------------------ API
    @property
    def t(self) -> float:
        """Time of the present sample instant, ``k T_s`` (s)."""
        return self.k * self.T_s

    @property
    def load(self) -> LoadProfile:
        """The present load profile."""
        return self._load

    def set_load(self, profile: LoadProfile) -> None:
        """Replace the load profile (times in the profile are absolute, s)."""
        self._load = profile

    def impose_speed(self, w_m: float | None) -> None:
        """Hold the mechanical speed at ``w_m`` (rad/s) like a dynamometer; None releases it."""
        if w_m is None:
            self._w_imp = None
        else:
            self._w_imp = float(w_m)
            self._w_m = self._w_imp

    @property
    def imposed_speed(self) -> float | None:
        """The speed the dynamometer holds (rad/s), or None."""
        return self._w_imp

    def currents_abc(self) -> tuple[float, float, float]:
        """True phase currents at ``t = k T_s`` (A)."""
        th_e = self._n_p * self._th_m
        c = math.cos(th_e)
        s = math.sin(th_e)
        i_al = c * self._i_d - s * self._i_q
        i_be = s * self._i_d + c * self._i_q
        return i_al, -0.5 * i_al + 0.5 * SQRT3 * i_be, -0.5 * i_al - 0.5 * SQRT3 * i_be

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
            _, i_a, i_b, i_c, u_dc = meas
        else:
            i_a, i_b, i_c = self.currents_abc()
            u_dc = self._u_dc
        sens = self._sensors
        m_a, m_b, m_c = sens.currents(i_a, i_b, i_c)
        smp = Sample(self.k, m_a, m_b, m_c, sens.voltage(u_dc))
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
        if self.cross_saturation:
            i_d = self._i_d
            i_q = self._i_q
            psi_d, psi_q, _, _, _ = flux_dq(self.motor, i_d, i_q, self.saturation, True)
            return self._k_tau * (psi_d * i_q - psi_q * i_d)
        psi_d, _ = flux_d(self.motor, self._i_d, self.saturation)
        return self._k_tau * (psi_d - self._L_q * self._i_d) * self._i_q

    def truth(self) -> Truth:
        """Plant truth at ``t = k T_s``."""
        tau_e = self.torque()
        w_m = self._w_m
        imposed = self._w_imp is not None
        tau_L = tau_e - self._b * w_m if imposed else self._load.tau(self.t, w_m)
        return Truth(
            k=self.k,
            t=self.t,
            theta_e=(self._n_p * self._th_m) % TWO_PI,
            w_e=self._n_p * w_m,
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
        psi0 = flux_d(self.motor, 0.0, self.saturation)[0]
        th_e = self._n_p * self._th_m
        amp = -self._n_p * self._w_m * psi0
        return (
            amp * math.sin(th_e),
            amp * math.sin(th_e - 2.0 * math.pi / 3.0),
            amp * math.sin(th_e + 2.0 * math.pi / 3.0),
        )

    def step(self, d_a: float, d_b: float, d_c: float, enable: bool = True) -> None:
        """Apply duties for period ``k`` and advance to ``k + 1``.

        Parameters
        ----------
        d_a, d_b, d_c : float
            Duty cycles of the phase legs; clamped to [0, 1].
        enable : bool
            False opens all switches (diode bridge, see class notes).
        """
        h = self._h
        t0 = self.k * self.T_s
        meter = self.meter
        if meter is not None:
            meter.q_a = meter.q_b = meter.q_c = 0.0
        if enable and self._switching:
            self._step_switching(d_a, d_b, d_c, t0)
        elif enable and self._avg_general:
            self._step_average_general(d_a, d_b, d_c, t0)
        elif enable:
            u_dc = self._u_dc
            v_a = clamp_duty(d_a) * u_dc
            v_b = clamp_duty(d_b) * u_dc
            v_c = clamp_duty(d_c) * u_dc
            t_dead = self.inverter.t_dead
            if t_dead > 0.0:
                # only a switching leg has dead time: one held at a rail
                # (duty 0 or 1) keeps its switch on the whole period
                i_a, i_b, i_c = self.currents_abc()
                if 0.0 < v_a < u_dc:
                    v_a += dead_time_error(i_a, u_dc, t_dead, self.T_s)
                if 0.0 < v_b < u_dc:
                    v_b += dead_time_error(i_b, u_dc, t_dead, self.T_s)
                if 0.0 < v_c < u_dc:
                    v_c += dead_time_error(i_c, u_dc, t_dead, self.T_s)
            if self._drops:
                v_a, v_b, v_c = self._add_drops(v_a, v_b, v_c, u_dc)
            u_al = (2.0 * v_a - v_b - v_c) / 3.0
            u_be = (v_b - v_c) * INV_SQRT3
            cross = self.cross_saturation
            for j in range(self.substeps):
                tau_L = self._tau_load(t0 + j * h)
                if meter is not None:
                    self._rk4(h, v_a, v_b, v_c, -1, tau_L)
                elif cross:
                    self._rk4_cross(h, u_al, u_be, tau_L)
                else:
                    self._rk4_fast(h, u_al, u_be, tau_L)
            self.u_s_ab = (u_al, u_be)
        elif not (self._dc_dyn or self._t_meas > 0.0):
            if self._pwm is not None:
                self._pwm.disable()
            sa = sb = 0.0
            for j in range(self.substeps):
                ua, ub = self._substep_off(h, self._tau_load(t0 + j * h))
                sa += ua
                sb += ub
            self.u_s_ab = (sa / self.substeps, sb / self.substeps)
        else:
            self._step_off_general(t0)
        self._th_m %= TWO_PI
        self.k += 1

    # ------------------------------------------------------- inverter models
    def _add_drops(
        self, v_a: float, v_b: float, v_c: float, u_dc: float
    ) -> tuple[float, float, float]:
        """Average model: the period-mean device drops (:func:`device_drop_error`).

        ``v_x / u_dc`` is the leg's time on the positive rail after dead time;
        the current direction is the one at the start of the period.
        """
        i_a, i_b, i_c = self.currents_abc()
        v_ce = self._v_ce
        v_f = self._v_f
        return (
            v_a + device_drop_error(i_a, v_a / u_dc, v_ce, v_f),
            v_b + device_drop_error(i_b, v_b / u_dc, v_ce, v_f),
            v_c + device_drop_error(i_c, v_c / u_dc, v_ce, v_f),
        )

    def _segments(self) -> list[tuple[float, float, int]]:
        """The substep grid cut at the sensor instant: ``(t_start, t_end, grid index)``."""
        T = self.T_s
        grid = self._grid
        out: list[tuple[float, float, int]] = []
        t0 = 0.0
        j = 0
        for t1 in (*self._cuts, T):
            while j + 1 < len(grid) and t0 >= grid[j + 1]:
                j += 1
            out.append((t0, t1, j))
            t0 = t1
        return out

    def _step_average_general(self, d_a: float, d_b: float, d_c: float, t0: float) -> None:
        """Average model with a dynamic DC link or a sensor delay: one RK4 step per segment.

        The duties' mean pole voltages are recomputed on each segment from the
        DC-link voltage at its start; the dead-time and drop errors take the
        current directions at the start of the period, as on the fast path.
        """
        d_a = clamp_duty(d_a)
        d_b = clamp_duty(d_b)
        d_c = clamp_duty(d_c)
        t_dead = self.inverter.t_dead
        T = self.T_s
        i_a, i_b, i_c = self.currents_abc()
        # effective fractions on the positive rail after dead time
        if t_dead > 0.0:
            r = t_dead / T
            if 0.0 < d_a < 1.0:
                d_a += dead_time_error(i_a, 1.0, r, 1.0)
            if 0.0 < d_b < 1.0:
                d_b += dead_time_error(i_b, 1.0, r, 1.0)
            if 0.0 < d_c < 1.0:
                d_c += dead_time_error(i_c, 1.0, r, 1.0)
        if self._drops:
            v_ce = self._v_ce
            v_f = self._v_f
            e_a = device_drop_error(i_a, d_a, v_ce, v_f)
            e_b = device_drop_error(i_b, d_b, v_ce, v_f)
            e_c = device_drop_error(i_c, d_c, v_ce, v_f)
        else:
            e_a = e_b = e_c = 0.0
        meter = self.meter
        cross = self.cross_saturation
        h_grid = self._h
        s_al = s_be = 0.0
        j_load = -1
        tau_L = 0.0
        for ta, tb, j in self._segs:
            if j != j_load:
                tau_L = self._tau_load(t0 + j * h_grid)
                j_load = j
            h = tb - ta
            if self._dc_dyn:
                i0 = d_a * i_a + d_b * i_b + d_c * i_c
                if self._c_dc == 0.0:
                    self._u_dc = self._u_src - self._r_dc * i0
            u_dc = self._u_dc
            v_a = d_a * u_dc + e_a
            v_b = d_b * u_dc + e_b
            v_c = d_c * u_dc + e_c
            u_al = (2.0 * v_a - v_b - v_c) / 3.0
            u_be = (v_b - v_c) * INV_SQRT3
            if meter is not None:
                self._rk4(h, v_a, v_b, v_c, -1, tau_L)
            elif cross:
                self._rk4_cross(h, u_al, u_be, tau_L)
            else:
                self._rk4_fast(h, u_al, u_be, tau_L)
            s_al += h * u_al
            s_be += h * u_be
            i_a, i_b, i_c = self.currents_abc()
            if self._dc_dyn:
                i1 = d_a * i_a + d_b * i_b + d_c * i_c
                self._dc_update(h, 0.5 * (i0 + i1), i1)
            if tb == self._t_meas:
                self._record_meas(i_a, i_b, i_c)
        self.u_s_ab = (s_al / T, s_be / T)

    def _step_off_general(self, t0: float) -> None:
        """Disabled bridge with a dynamic DC link or a sensor delay.

        A conducting phase whose current flows out of the machine (``i_x <
        0``) sits on the positive rail through its upper diode, so the DC
        link receives ``i_dc = sum_x min(i_x, 0)`` (negative: it charges).
        """
        if self._pwm is not None:
            self._pwm.disable()
        T = self.T_s
        h_grid = self._h
        s_al = s_be = 0.0
        j_load = -1
        tau_L = 0.0
        i_a, i_b, i_c = self.currents_abc()
        for ta, tb, j in self._segs:
            if j != j_load:
                tau_L = self._tau_load(t0 + j * h_grid)
                j_load = j
            h = tb - ta
            i0 = min(i_a, 0.0) + min(i_b, 0.0) + min(i_c, 0.0)
            if self._dc_dyn and self._c_dc == 0.0:
                self._u_dc = self._u_src - self._r_dc * i0
            ua, ub = self._substep_off(h, tau_L)
            s_al += h * ua
            s_be += h * ub
            i_a, i_b, i_c = self.currents_abc()
            if self._dc_dyn:
                i1 = min(i_a, 0.0) + min(i_b, 0.0) + min(i_c, 0.0)
                self._dc_update(h, 0.5 * (i0 + i1), i1)
            if tb == self._t_meas:
                self._record_meas(i_a, i_b, i_c)
        self.u_s_ab = (s_al / T, s_be / T)

    def _dc_update(self, h: float, i_dc: float, i_dc_end: float) -> None:
        """Advance the DC link over ``h``: mean inverter current ``i_dc``, ``i_dc_end`` at the end (A).

        With a capacitor its voltage moves exactly for a constant ``i_dc``;
        without one the link is algebraic, ``u_src - r_dc i_dc`` with the
        current at hand (the callers set it from the current at the start of
        each step, this sets it from the one at its end).
        """
        r = self._r_dc
        if self._c_dc > 0.0:
            u_inf = self._u_src - r * i_dc
            self._u_dc = u_inf + (self._u_dc - u_inf) * math.exp(-h / (r * self._c_dc))
        else:
            self._u_dc = self._u_src - r * i_dc_end

    def _record_meas(self, i_a: float, i_b: float, i_c: float) -> None:
        """Keep the currents and DC-link voltage for the next period's (delayed) sample."""
        self._meas = (self.k + 1, i_a, i_b, i_c, self._u_dc)

    def _step_switching(self, d_a: float, d_b: float, d_c: float, t0: float) -> None:
        """Switching model: one period, sub-interval by sub-interval (class notes)."""
        pwm = self._pwm
        assert pwm is not None
        T = self.T_s
        segs = pwm.period(clamp_duty(d_a), clamp_duty(d_b), clamp_duty(d_c), self._cuts)
        grid = self._grid
        n_grid = len(grid)
        j = 0
        tau_L = self._tau_load(t0)
        t_meas = self._t_meas
        i_abc = self.currents_abc()
        s_al = s_be = 0.0
        for ta, tb, sa, sb, sc in segs:
            while j + 1 < n_grid and ta >= grid[j + 1]:
                j += 1
                tau_L = self._tau_load(t0 + grid[j])
            h = tb - ta
            ua, ub, i_abc = self._sw_interval(h, sa, sb, sc, tau_L, i_abc)
            s_al += h * ua
            s_be += h * ub
            if tb == t_meas:
                self._record_meas(*i_abc)
        self.u_s_ab = (s_al / T, s_be / T)

    def _sw_interval(
        self,
        h: float,
        sa: int,
        sb: int,
        sc: int,
        tau_L: float,
        i_abc: tuple[float, float, float],
    ) -> tuple[float, float, tuple[float, float, float]]:
        """Integrate one sub-interval with constant gate states.

        Returns the mean stator voltage in alpha-beta over it and the phase
        currents at its end.
        """
        v_ce = self._v_ce
        v_f = self._v_f
        eps = self._i_eps
        states = (sa, sb, sc)
        i_dc0 = 0.0
        if self._dc_dyn:
            # legs on the positive rail: upper switch on, or dead with the upper diode conducting
            for x in range(3):
                if states[x] == HIGH or (states[x] == DEAD and i_abc[x] < -eps):
                    i_dc0 += i_abc[x]
            if self._c_dc == 0.0:
                self._u_dc = self._u_src - self._r_dc * i_dc0
        u_dc = self._u_dc
        v = [0.0, 0.0, 0.0]
        # direction of a dead leg's diode current: +1 lower diode, -1 upper diode
        cond = [0, 0, 0]
        upper = [False, False, False]  # pole on the positive rail (DC-link current)
        floating: list[int] = []
        for x in range(3):
            s = states[x]
            i = i_abc[x]
            if s == HIGH:
                upper[x] = True
                v[x] = u_dc - v_ce if i > eps else (u_dc + v_f if i < -eps else u_dc)
            elif s == DEAD:
                if i > eps:
                    v[x] = -v_f
                    cond[x] = 1
                elif i < -eps:
                    v[x] = u_dc + v_f
                    cond[x] = -1
                    upper[x] = True
                else:
                    floating.append(x)
            else:
                v[x] = -v_f if i > eps else (v_ce if i < -eps else 0.0)
        if len(floating) >= 2:
            # no current path: the currents stay zero for the rest of the dead interval
            self._i_d = 0.0
            self._i_q = 0.0
            ua, ub = self._open_circuit(h, tau_L)
            if self._dc_dyn:
                self._dc_update(h, 0.0, 0.0)
            return ua, ub, (0.0, 0.0, 0.0)
        fx = -1
        if floating:
            x = floating[0]
            u_al0 = (2.0 * v[0] - v[1] - v[2]) / 3.0
            u_be0 = (v[1] - v[2]) * INV_SQRT3
            v_x = self._f_float(
                self._i_d, self._i_q, self._w_m, self._th_m, u_al0, u_be0, x, tau_L
            )[4]
            if v_x > u_dc + v_f:  # the upper diode takes the current
                v[x] = u_dc + v_f
                cond[x] = -1
                upper[x] = True
            elif v_x < -v_f:  # the lower diode takes it
                v[x] = -v_f
                cond[x] = 1
            else:
                fx = x
        if fx >= 0:
            ua, ub = self._rk4(h, v[0], v[1], v[2], fx, tau_L)
            self._zero_phase(fx)
            i_new = self.currents_abc()
        elif cond[0] == 0 and cond[1] == 0 and cond[2] == 0:
            ua, ub = self._rk4_const(h, v[0], v[1], v[2], tau_L)
            i_new = self.currents_abc()
        else:
            ua, ub, i_new = self._dead_with_clamp(h, v, cond, tau_L, i_abc)
        if self._dc_dyn:
            i_dc1 = sum(i_new[x] for x in range(3) if upper[x])
            self._dc_update(h, 0.5 * (i_dc0 + i_dc1), i_dc1)
        return ua, ub, i_new

    def _rk4_const(
        self, h: float, v_a: float, v_b: float, v_c: float, tau_L: float
    ) -> tuple[float, float]:
        """One RK4 step with constant pole voltages; returns the stator voltage in alpha-beta."""
        if self.meter is not None:
            return self._rk4(h, v_a, v_b, v_c, -1, tau_L)
        u_al = (2.0 * v_a - v_b - v_c) / 3.0
        u_be = (v_b - v_c) * INV_SQRT3
        if self.cross_saturation:
            self._rk4_cross(h, u_al, u_be, tau_L)
        else:
            self._rk4_fast(h, u_al, u_be, tau_L)
        return u_al, u_be

    def _dead_with_clamp(
        self,
        h: float,
        v: list[float],
        cond: list[int],
        tau_L: float,
        i_abc: tuple[float, float, float],
    ) -> tuple[float, float, tuple[float, float, float]]:
        """A sub-interval with diode-conducting dead legs: stop a diode at its current zero.

        Integrates the whole sub-interval; if a diode's current has reversed,
        redoes the step up to the (linearly interpolated) zero of the first
        such phase, clamps that phase to zero and integrates the rest with it
        floating. Returns the mean stator voltage in alpha-beta and the phase
        currents at the end.
        """
        saved = self._save()
        ua, ub = self._rk4_const(h, v[0], v[1], v[2], tau_L)
        i_new = self.currents_abc()
        first = -1
        frac = 1.0
        for x in range(3):
            c = cond[x]
            if c != 0 and i_new[x] * c < 0.0:
                f = i_abc[x] / (i_abc[x] - i_new[x])
                if f < frac:
                    frac = f
                    first = x
        if first < 0:
            return ua, ub, i_new
        self._restore(saved)
        h1 = frac * h
        ua1, ub1 = self._rk4_const(h1, v[0], v[1], v[2], tau_L) if h1 > 0.0 else (ua, ub)
        self._zero_phase(first)
        h2 = h - h1
        ua2, ub2 = self._rk4(h2, v[0], v[1], v[2], first, tau_L)
        self._zero_phase(first)
        return (h1 * ua1 + h2 * ua2) / h, (h1 * ub1 + h2 * ub2) / h, self.currents_abc()

    def _save(self) -> tuple[float, ...]:
        m = self.meter
        st = (self._i_d, self._i_q, self._w_m, self._th_m)
        if m is None:
            return st
        return (*st, m.e_in, m.e_cu, m.e_em, m.e_fric, m.e_load, m.q_a, m.q_b, m.q_c)

    def _restore(self, st: tuple[float, ...]) -> None:
        self._i_d, self._i_q, self._w_m, self._th_m = st[0], st[1], st[2], st[3]
        m = self.meter
        if m is not None:
            m.e_in, m.e_cu, m.e_em, m.e_fric, m.e_load = st[4], st[5], st[6], st[7], st[8]
            m.q_a, m.q_b, m.q_c = st[9], st[10], st[11]

    # ------------------------------------------------------------ internals
    def _tau_load(self, t: float) -> float:
        if self._w_imp is not None:
            return 0.0  # not used: the speed is held
        return self._load.tau(t, self._w_m)

    def _f(
        self,
        i_d: float,
        i_q: float,
        w_m: float,
        th_m: float,
        u_al: float,
        u_be: float,
        tau_L: float,
    ) -> tuple[float, float, float, float]:
        """State derivatives (di_d, di_q, dw_m) and tau_e for a voltage fixed in alpha-beta.

        Wen eq. (1) / Xue eq. (1), written on flux linkages so that the
        saturated model stays energy-consistent.
        """
        n_p = self._n_p
        th_e = n_p * th_m
        c = math.cos(th_e)
        s = math.sin(th_e)
        u_d = c * u_al + s * u_be
        u_q = c * u_be - s * u_al
        w_e = n_p * w_m
        if self.cross_saturation:
            psi_d, psi_q, L_dd, L_dq, L_qq = flux_dq(self.motor, i_d, i_q, self.saturation, True)
            e_d = u_d - self._R * i_d + w_e * psi_q
            e_q = u_q - self._R * i_q - w_e * psi_d
            det = L_dd * L_qq - L_dq * L_dq
            tau_e = self._k_tau * (psi_d * i_q - psi_q * i_d)
            dw = 0.0 if self._w_imp is not None else (tau_e - tau_L - self._b * w_m) * self._inv_J
            return (L_qq * e_d - L_dq * e_q) / det, (L_dd * e_q - L_dq * e_d) / det, dw, tau_e
        L_q = self._L_q
        if self.saturation:
            x = i_d * self._inv_i_sat
            r = math.sqrt(1.0 + x * x)
            psi_d = self._psi_f + self._L_d * (i_d - self._sig_isat * (r - 1.0))
            L_dd = self._L_d * (1.0 - self._sig * x / r)
        else:
            psi_d = self._psi_f + self._L_d * i_d
            L_dd = self._L_d
        R = self._R
        tau_e = self._k_tau * (psi_d - L_q * i_d) * i_q
        dw = 0.0 if self._w_imp is not None else (tau_e - tau_L - self._b * w_m) * self._inv_J
        return (
            (u_d - R * i_d + w_e * L_q * i_q) / L_dd,
            (u_q - R * i_q - w_e * psi_d) / L_q,
            dw,
            tau_e,
        )

    def _f_float(
        self,
        i_d: float,
        i_q: float,
        w_m: float,
        th_m: float,
        u_al0: float,
        u_be0: float,
        x: int,
        tau_L: float,
    ) -> tuple[float, float, float, float, float]:
        """Derivatives with phase ``x`` floating (current held at zero).

        ``u_al0, u_be0`` is the stator voltage from the other two legs with
        ``v_x = 0``. Leg ``x`` adds ``(2/3) v_x e^{j phi_x}``; ``v_x`` is
        solved from ``d i_x/dt = 0`` with ``i_x = i_d cos(theta_e - phi_x)
        - i_q sin(theta_e - phi_x)``. Returns the derivatives, tau_e and v_x.
        """
        n_p = self._n_p
        th_e = n_p * th_m
        c = math.cos(th_e)
        s = math.sin(th_e)
        u_d = c * u_al0 + s * u_be0
        u_q = c * u_be0 - s * u_al0
        w_e = n_p * w_m
        if self.cross_saturation:
            return self._f_float_cross(i_d, i_q, w_m, c, s, u_d, u_q, x, tau_L)
        L_q = self._L_q
        psi_d, L_dd = flux_d(self.motor, i_d, self.saturation)
        R = self._R
        f_d = (u_d - R * i_d + w_e * L_q * i_q) / L_dd
        f_q = (u_q - R * i_q - w_e * psi_d) / L_q
        c_x = c * _COS_PHI[x] + s * _SIN_PHI[x]
        s_x = s * _COS_PHI[x] - c * _SIN_PHI[x]
        a = c_x * f_d - s_x * f_q - w_e * (i_d * s_x + i_q * c_x)
        g = (2.0 / 3.0) * (c_x * c_x / L_dd + s_x * s_x / L_q)
        v_x = -a / g
        tau_e = self._k_tau * (psi_d - L_q * i_d) * i_q
        dw = 0.0 if self._w_imp is not None else (tau_e - tau_L - self._b * w_m) * self._inv_J
        return (
            f_d + (2.0 / 3.0) * v_x * c_x / L_dd,
            f_q - (2.0 / 3.0) * v_x * s_x / L_q,
            dw,
            tau_e,
            v_x,
        )

    def _f_float_cross(
        self,
        i_d: float,
        i_q: float,
        w_m: float,
        c: float,
        s: float,
        u_d: float,
        u_q: float,
        x: int,
        tau_L: float,
    ) -> tuple[float, float, float, float, float]:
        """:meth:`_f_float` with the cross-saturated flux map (full inductance matrix).

        ``d i / dt = Y (e + (2/3) v_x e_x)`` with ``Y`` the inverse of the
        incremental inductance matrix and ``e_x = (c_x, -s_x)`` phase x's axis
        in d-q; ``v_x`` makes ``d i_x / dt = 0``.
        """
        w_e = self._n_p * w_m
        psi_d, psi_q, L_dd, L_dq, L_qq = flux_dq(self.motor, i_d, i_q, self.saturation, True)
        R = self._R
        e_d = u_d - R * i_d + w_e * psi_q
        e_q = u_q - R * i_q - w_e * psi_d
        det = L_dd * L_qq - L_dq * L_dq
        f_d = (L_qq * e_d - L_dq * e_q) / det
        f_q = (L_dd * e_q - L_dq * e_d) / det
        c_x = c * _COS_PHI[x] + s * _SIN_PHI[x]
        s_x = s * _COS_PHI[x] - c * _SIN_PHI[x]
        y_d = (L_qq * c_x + L_dq * s_x) / det
        y_q = (-L_dq * c_x - L_dd * s_x) / det
        a = c_x * f_d - s_x * f_q - w_e * (i_d * s_x + i_q * c_x)
        g = (2.0 / 3.0) * (c_x * y_d - s_x * y_q)
        v_x = -a / g
        tau_e = self._k_tau * (psi_d * i_q - psi_q * i_d)
        dw = 0.0 if self._w_imp is not None else (tau_e - tau_L - self._b * w_m) * self._inv_J
        return (
            f_d + (2.0 / 3.0) * v_x * y_d,
            f_q + (2.0 / 3.0) * v_x * y_q,
            dw,
            tau_e,
            v_x,
        )

    def _rk4_cross_step(self, h: float, u_al: float, u_be: float, tau_L: float) -> None:
        """:meth:`_rk4_fast_step` with the cross-saturated flux map (:class:`CrossSaturationPars`).

        ``L_inc d i_dq / dt = u_dq - R i_dq - w_e J psi_dq``, solved with the
        2x2 incremental inductance matrix at every stage.
        """
        cos = math.cos
        sin = math.sin
        n_p = self._n_p
        R = self._R
        L_d = self._L_d
        L_q = self._L_q
        psi_f = self._psi_f
        k_tau = self._k_tau
        sat = self.saturation
        free = self._w_imp is None
        b = self._b
        inv_J = self._inv_J
        c_dq = self._c_dq
        x_lim = FLUX_RANGE * self.motor.i_max
        i_0 = self._i_0
        i_d0 = self._i_d
        i_q0 = self._i_q
        w0 = self._w_m
        th0 = self._th_m
        i_d = i_d0
        i_q = i_q0
        w = w0
        th = th0
        s_d = s_q = s_w = s_th = 0.0
        di_d = di_q = dw = 0.0
        for o, wgt in _RK4_STAGES:
            if o != 0.0:
                i_d = i_d0 + o * h * di_d
                i_q = i_q0 + o * h * di_q
                th = th0 + o * h * w
                w = w0 + o * h * dw
            th_e = n_p * th
            c = cos(th_e)
            s = sin(th_e)
            w_e = n_p * w
            if sat:
                x = i_d * self._inv_i_sat
                r = math.sqrt(1.0 + x * x)
                psi_d = psi_f + L_d * (i_d - self._sig_isat * (r - 1.0))
                L_dd = L_d * (1.0 - self._sig * x / r)
            else:
                psi_d = psi_f + L_d * i_d
                L_dd = L_d
            if abs(i_d) > x_lim or abs(i_q) > x_lim:
                psi_d, psi_q, L_dd, L_dq, L_qq = cross_ext(self.motor, i_d, i_q, psi_d, L_dd)
            else:
                m = i_d + i_0
                hq = 0.5 * c_dq * i_q
                L_qq = L_q - 0.5 * c_dq * i_d * (i_d + 2.0 * i_0)
                psi_d -= hq * m * i_q
                psi_q = L_qq * i_q
                L_dd -= hq * i_q
                L_dq = -c_dq * m * i_q
            e_d = c * u_al + s * u_be - R * i_d + w_e * psi_q
            e_q = c * u_be - s * u_al - R * i_q - w_e * psi_d
            inv_det = 1.0 / (L_dd * L_qq - L_dq * L_dq)
            di_d = (L_qq * e_d - L_dq * e_q) * inv_det
            di_q = (L_dd * e_q - L_dq * e_d) * inv_det
            dw = (k_tau * (psi_d * i_q - psi_q * i_d) - tau_L - b * w) * inv_J if free else 0.0
            s_d += wgt * di_d
            s_q += wgt * di_q
            s_w += wgt * dw
            s_th += wgt * w
        h6 = h / 6.0
        self._i_d = i_d0 + h6 * s_d
        self._i_q = i_q0 + h6 * s_q
        self._w_m = w0 + h6 * s_w
        self._th_m = th0 + h6 * s_th

    def _rk4_fast_step(self, h: float, u_al: float, u_be: float, tau_L: float) -> None:
        """One RK4 step with a stator voltage constant in alpha-beta.

        Same equations as :meth:`_f`, inlined: this is the per-period hot path.
        """
        cos = math.cos
        sin = math.sin
        n_p = self._n_p
        R = self._R
        L_d = self._L_d
        L_q = self._L_q
        psi_f = self._psi_f
        k_tau = self._k_tau
        sat = self.saturation
        free = self._w_imp is None
        b = self._b
        inv_J = self._inv_J
        i_d0 = self._i_d
        i_q0 = self._i_q
        w0 = self._w_m
        th0 = self._th_m
        i_d = i_d0
        i_q = i_q0
        w = w0
        th = th0
        s_d = s_q = s_w = s_th = 0.0
        di_d = di_q = dw = 0.0
        for o, wgt in _RK4_STAGES:
            if o != 0.0:
                i_d = i_d0 + o * h * di_d
                i_q = i_q0 + o * h * di_q
                th = th0 + o * h * w
                w = w0 + o * h * dw
            th_e = n_p * th
            c = cos(th_e)
            s = sin(th_e)
            w_e = n_p * w
            if sat:
                x = i_d * self._inv_i_sat
                r = math.sqrt(1.0 + x * x)
                psi_d = psi_f + L_d * (i_d - self._sig_isat * (r - 1.0))
                L_dd = L_d * (1.0 - self._sig * x / r)
            else:
                psi_d = psi_f + L_d * i_d
                L_dd = L_d
            di_d = (c * u_al + s * u_be - R * i_d + w_e * L_q * i_q) / L_dd
            di_q = (c * u_be - s * u_al - R * i_q - w_e * psi_d) / L_q
            dw = (k_tau * (psi_d - L_q * i_d) * i_q - tau_L - b * w) * inv_J if free else 0.0
            s_d += wgt * di_d
            s_q += wgt * di_q
            s_w += wgt * dw
            s_th += wgt * w
        h6 = h / 6.0
        self._i_d = i_d0 + h6 * s_d
        self._i_q = i_q0 + h6 * s_q
        self._w_m = w0 + h6 * s_w
        self._th_m = th0 + h6 * s_th

    def _substeps(self, h: float) -> int:
        """Equal RK4 steps over an interval h: ``ceil(|w_e| h / 1)``, at least 1, with
        ``w_em h`` added beyond the flux map's range when the speed is free.

        The rotor-frame pole pair at ``+-j w_e`` leaves RK4's stability region
        at ``|w_e| h = 2 sqrt(2)``; ``plant_rt/core/plant_rk4.h`` derives the
        bound of 1.
        """
        x = abs(self._n_p * self._w_m) * h / 1.0
        i_d, i_q = self._i_d, self._i_q
        x_lim = FLUX_RANGE * self.motor.i_max
        if self._w_imp is None and i_d * i_d + i_q * i_q > x_lim * x_lim:
            # the electromechanical mode beyond the range (plant_rk4.h derives w_em)
            psi_d, psi_q, L_dd, L_dq, L_qq = flux_dq(
                self.motor, i_d, i_q, self.saturation, self.cross_saturation
            )
            mid = 0.5 * (L_dd + L_qq)
            hd = 0.5 * (L_dd - L_qq)
            rad = math.sqrt(hd * hd + L_dq * L_dq)
            L_lo, L_hi = mid - rad, mid + rad
            psi = math.sqrt(psi_d * psi_d + psi_q * psi_q)
            i_s = math.sqrt(i_d * i_d + i_q * i_q)
            w_em = (
                math.sqrt(self._n_p * self._k_tau * self._inv_J * psi * (psi + L_hi * i_s) / L_lo)
                if L_lo > 0.0
                else math.inf
            )
            x += w_em * h / 1.0
        if not x > 1.0:
            return 1
        return min(math.ceil(x), 1_000_000)

    def _rk4_cross(self, h: float, u_al: float, u_be: float, tau_L: float) -> None:
        n = self._substeps(h)
        for _ in range(n):
            self._rk4_cross_step(h / n if n > 1 else h, u_al, u_be, tau_L)

    def _rk4_fast(self, h: float, u_al: float, u_be: float, tau_L: float) -> None:
        n = self._substeps(h)
        for _ in range(n):
            self._rk4_fast_step(h / n if n > 1 else h, u_al, u_be, tau_L)

    def _rk4(
        self, h: float, v_a: float, v_b: float, v_c: float, fx: int, tau_L: float
    ) -> tuple[float, float]:
        """:meth:`_rk4_step` in :meth:`_substeps` equal steps; their mean stator voltage."""
        n = self._substeps(h)
        if n == 1:
            return self._rk4_step(h, v_a, v_b, v_c, fx, tau_L)
        ua_sum = ub_sum = 0.0
        for _ in range(n):
            ua, ub = self._rk4_step(h / n, v_a, v_b, v_c, fx, tau_L)
            ua_sum += ua
            ub_sum += ub
        return ua_sum / n, ub_sum / n

    def _rk4_step(
        self, h: float, v_a: float, v_b: float, v_c: float, fx: int, tau_L: float
    ) -> tuple[float, float]:
        """General RK4 step: optional floating phase ``fx`` and energy metering.

        Returns the RK4-weighted mean stator voltage in alpha-beta over the step.
        """
        vs = [v_a, v_b, v_c]
        if fx >= 0:
            vs[fx] = 0.0
        u_al = (2.0 * vs[0] - vs[1] - vs[2]) / 3.0
        u_be = (vs[1] - vs[2]) * INV_SQRT3
        x0 = (self._i_d, self._i_q, self._w_m, self._th_m)
        weights = (1.0, 2.0, 2.0, 1.0)
        offsets = (0.0, 0.5 * h, 0.5 * h, h)
        k_prev: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
        acc = [0.0, 0.0, 0.0, 0.0]
        meter = self.meter
        ua_sum = 0.0
        ub_sum = 0.0
        for n in range(4):
            o = offsets[n]
            xs = (
                x0[0] + o * k_prev[0],
                x0[1] + o * k_prev[1],
                x0[2] + o * k_prev[2],
                x0[3] + o * k_prev[3],
            )
            if fx >= 0:
                di_d, di_q, dw, tau_e, v_x = self._f_float(*xs, u_al, u_be, fx, tau_L)
                vs[fx] = v_x
                ua_n = u_al + (2.0 / 3.0) * v_x * _COS_PHI[fx]
                ub_n = u_be + (2.0 / 3.0) * v_x * _SIN_PHI[fx]
            else:
                di_d, di_q, dw, tau_e = self._f(*xs, u_al, u_be, tau_L)
                ua_n = u_al
                ub_n = u_be
            wgt = weights[n]
            ua_sum += wgt * ua_n
            ub_sum += wgt * ub_n
            k_prev = (di_d, di_q, dw, xs[2])
            for m in range(4):
                acc[m] += wgt * k_prev[m]
            if meter is not None:
                self._meter_stage(meter, xs, vs, tau_e, tau_L, wgt * h / 6.0)
        h6 = h / 6.0
        self._i_d = x0[0] + h6 * acc[0]
        self._i_q = x0[1] + h6 * acc[1]
        self._w_m = x0[2] + h6 * acc[2]
        self._th_m = x0[3] + h6 * acc[3]
        return ua_sum / 6.0, ub_sum / 6.0

    def _meter_stage(
        self,
        meter: EnergyMeter,
        xs: tuple[float, float, float, float],
        vs: list[float],
        tau_e: float,
        tau_L: float,
        dt: float,
    ) -> None:
        i_d, i_q, w_m, th_m = xs
        th_e = self._n_p * th_m
        c = math.cos(th_e)
        s = math.sin(th_e)
        i_al = c * i_d - s * i_q
        i_be = s * i_d + c * i_q
        i_a = i_al
        i_b = -0.5 * i_al + 0.5 * SQRT3 * i_be
        i_c = -0.5 * i_al - 0.5 * SQRT3 * i_be
        meter.e_in += dt * (vs[0] * i_a + vs[1] * i_b + vs[2] * i_c)
        meter.e_cu += dt * self._R * (i_a * i_a + i_b * i_b + i_c * i_c)
        meter.e_em += dt * tau_e * w_m
        meter.e_fric += dt * self._b * w_m * w_m
        if self._w_imp is not None:
            tau_L = tau_e - self._b * w_m
        meter.e_load += dt * tau_L * w_m
        meter.q_a += dt * i_a
        meter.q_b += dt * i_b
        meter.q_c += dt * i_c

    def _phase_currents(self) -> list[float]:
        return list(self.currents_abc())

    def _substep_off(self, h: float, tau_L: float) -> tuple[float, float]:
        """One substep with all switches open (diode bridge). Returns mean u_s_ab."""
        u_dc = self._u_dc
        i_abc = self._phase_currents()
        eps = self._i_eps
        sgn = [0, 0, 0]
        for x in range(3):
            if i_abc[x] > eps:
                sgn[x] = 1
            elif i_abc[x] < -eps:
                sgn[x] = -1
        n_cond = sum(1 for x in range(3) if sgn[x] != 0)
        fx = -1
        if n_cond < 2:
            # All currents zero: open circuit unless the line back-EMF exceeds u_dc.
            self._i_d = 0.0
            self._i_q = 0.0
            e = self.back_emf_abc()
            hi = max(range(3), key=lambda x: e[x])
            lo = min(range(3), key=lambda x: e[x])
            if e[hi] - e[lo] <= u_dc:
                return self._open_circuit(h, tau_L)
            sgn = [0, 0, 0]
            sgn[hi] = -1
            sgn[lo] = 1
            fx = 3 - hi - lo
        elif n_cond == 2:
            fx = sgn.index(0)
        vs = [0.0 if sgn[x] > 0 else u_dc for x in range(3)]
        if fx >= 0 and n_cond == 2:
            # Is the floating phase's pole voltage inside the rails?
            vs_f = list(vs)
            vs_f[fx] = 0.0
            u_al = (2.0 * vs_f[0] - vs_f[1] - vs_f[2]) / 3.0
            u_be = (vs_f[1] - vs_f[2]) * INV_SQRT3
            v_x = self._f_float(self._i_d, self._i_q, self._w_m, self._th_m, u_al, u_be, fx, tau_L)[
                4
            ]
            if v_x > u_dc:
                sgn[fx] = -1
                fx = -1
            elif v_x < 0.0:
                sgn[fx] = 1
                fx = -1
            vs = [0.0 if sgn[x] > 0 else u_dc for x in range(3)]
        u_mean = self._rk4(h, vs[0], vs[1], vs[2], fx, tau_L)
        # Current zeros within the substep.
        i_new = self._phase_currents()
        flipped = [x for x in range(3) if sgn[x] != 0 and i_new[x] * sgn[x] <= 0.0]
        remaining = sum(1 for x in range(3) if sgn[x] != 0) - len(flipped)
        if remaining < 2:
            self._i_d = 0.0
            self._i_q = 0.0
        else:
            for x in [*flipped, fx]:
                if x >= 0:
                    self._zero_phase(x)
        return u_mean

    def _zero_phase(self, x: int) -> None:
        """Remove phase ``x``'s current by projecting i_dq onto its null line."""
        th_e = self._n_p * self._th_m
        c = math.cos(th_e)
        s = math.sin(th_e)
        c_x = c * _COS_PHI[x] + s * _SIN_PHI[x]
        s_x = s * _COS_PHI[x] - c * _SIN_PHI[x]
        i_x = self._i_d * c_x - self._i_q * s_x
        self._i_d -= i_x * c_x
        self._i_q += i_x * s_x

    def _open_circuit(self, h: float, tau_L: float) -> tuple[float, float]:
        """Substep with all currents zero: mechanics only; returns the mean terminal voltage."""
        w0 = self._w_m
        th0 = self._th_m
        if self._w_imp is None:
            inv_J = self._inv_J
            b = self._b

            def dw(w: float) -> float:
                return (-tau_L - b * w) * inv_J

            k1 = dw(w0)
            k2 = dw(w0 + 0.5 * h * k1)
            k3 = dw(w0 + 0.5 * h * k2)
            k4 = dw(w0 + h * k3)
            w1 = w0 + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        else:
            w1 = w0
        th1 = th0 + 0.5 * h * (w0 + w1)
        meter = self.meter
        if meter is not None:
            w_mid = 0.5 * (w0 + w1)
            if self._w_imp is None:
                meter.e_load += h * tau_L * w_mid
                meter.e_fric += h * self._b * w_mid * w_mid
            else:
                meter.e_load -= h * self._b * w0 * w0
                meter.e_fric += h * self._b * w0 * w0
        # Terminal voltage = back-EMF j w_e psi_f e^{j theta_e}; Simpson mean over the substep.
        psi0 = flux_d(self.motor, 0.0, self.saturation)[0]
        n_p = self._n_p
        ua = 0.0
        ub = 0.0
        for wgt, th, w in (
            (1.0, th0, w0),
            (4.0, 0.5 * (th0 + th1), 0.5 * (w0 + w1)),
            (1.0, th1, w1),
        ):
            amp = n_p * w * psi0
            ua -= wgt * amp * math.sin(n_p * th)
            ub += wgt * amp * math.cos(n_p * th)
        self._w_m = w1
        self._th_m = th1
        return ua / 6.0, ub / 6.0
