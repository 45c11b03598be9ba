"""The plant: IPMSM, inverter, mechanics, load and sensing, one PWM period per step.

Timing (DESIGN.md, "Timing model"): step ``k`` is the PWM period
``[k T_s, (k + 1) T_s)``. :meth:`Plant.sample` returns the measurement taken
at ``t = k T_s`` (symmetric PWM: the carrier peak falls on the period
boundary of the average model), :meth:`Plant.step` applies duties for period
``k`` and advances to ``k + 1``.

Integration: classic RK4 with ``substeps`` fixed steps per period on the
states ``(i_d, i_q, w_m, theta_m)``. The average inverter voltage is constant
over the period in the stationary alpha-beta frame, not in d-q, so every RK4
stage rotates it into d-q with the stage's own rotor angle (at 1 kHz and
300 rpm the rotor turns 0.126 rad electrical per period). The load torque is
evaluated once per substep, at its start.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from plant_rt._inverter import INV_SQRT3, SQRT3, InverterPars, clamp_duty, dead_time_error
from plant_rt._load import ConstantLoad, LoadProfile
from plant_rt._machine import MotorPars, flux_d, magnetic_energy
from plant_rt._sensors import SensorPars, Sensors

TWO_PI = 2.0 * math.pi
# Phase axes a, b, c at 0, +120 and -120 degrees.
_COS_PHI = (1.0, -0.5, -0.5)
_SIN_PHI = (0.0, 0.5 * SQRT3, -0.5 * SQRT3)
# RK4 stages: (offset as a fraction of the step, weight).
_RK4_STAGES = ((0.0, 1.0), (0.5, 2.0), (0.5, 2.0), (1.0, 1.0))


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


class Plant:
    """IPMSM drive plant advanced one PWM period at a time.

    Parameters
    ----------
    motor : MotorPars
        Machine and mechanical parameters.
    inverter : InverterPars
        DC-link voltage and dead time.
    T_s : float
        PWM period (s).
    sensors : SensorPars, optional
        Sensor errors; ideal by default.
    load : LoadProfile, optional
        Load-torque profile; no load by default.
    substeps : int, optional
        RK4 steps per PWM period.
    saturation : bool, optional
        Use the saturated d-axis flux model (:class:`SaturationPars`).
    theta_m0, w_m0 : float, optional
        Initial mechanical angle (rad) and speed (rad/s).
    meter : bool, optional
        Integrate the energy flows (:class:`EnergyMeter`); slower.

    Notes
    -----
    Disabled inverter (``enable=False``, all switches open): the legs become
    a diode bridge. A conducting phase sits on the negative rail when its
    current flows into the machine and on the positive rail otherwise, so
    the currents freewheel against the DC link. A phase whose current is
    zero floats: its pole voltage is solved from ``d i_x / dt = 0`` and,
    if it leaves [0, u_dc], that phase's diode starts to conduct. With all
    currents zero the bridge starts to rectify when the line back-EMF
    exceeds ``u_dc``. Simplifications: the DC link is stiff, diodes are
    ideal, and the conduction state is decided at the start of each
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
    ) -> None:
        if not T_s > 0.0:
            raise ValueError(f"T_s must be > 0, got {T_s}")
        if int(substeps) != substeps or substeps < 1:
            raise ValueError(f"substeps must be a positive integer, got {substeps}")
        self.motor = motor
        self.inverter = inverter
        self.T_s = float(T_s)
        self.substeps = int(substeps)
        self.saturation = bool(saturation)
        self.sensor_pars = sensors if sensors is not None else SensorPars()
        self._sensors = Sensors(self.sensor_pars)
        self._load: LoadProfile = load if load is not None else ConstantLoad(0.0)
        self.k = 0
        # States.
        self._i_d = 0.0
        self._i_q = 0.0
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
        """Measurement at ``t = k T_s``; repeated calls within a period return the same one."""
        smp = self._sample
        if smp is not None and smp.k == self.k:
            return smp
        i_a, i_b, i_c = self.currents_abc()
        sens = self._sensors
        m_a, m_b, m_c = sens.currents(i_a, i_b, i_c)
        smp = Sample(self.k, m_a, m_b, m_c, sens.voltage(self._u_dc))
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
        w_mag = magnetic_energy(self.motor, self._i_d, self._i_q, self.saturation)
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
        if enable:
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
            u_al = (2.0 * v_a - v_b - v_c) / 3.0
            u_be = (v_b - v_c) * INV_SQRT3
            for j in range(self.substeps):
                tau_L = self._tau_load(t0 + j * h)
                if meter is None:
                    self._rk4_fast(h, u_al, u_be, tau_L)
                else:
                    self._rk4(h, v_a, v_b, v_c, -1, tau_L)
            self.u_s_ab = (u_al, u_be)
        else:
            sa = sb = 0.0
            for j in range(self.substeps):
                ua, ub = self._substep_off(h, self._tau_load(t0 + j * h))
                sa += ua
                sb += ub
            self.u_s_ab = (sa / self.substeps, sb / self.substeps)
        self._th_m %= TWO_PI
        self.k += 1

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

    def _rk4_fast(self, h: float, u_al: float, u_be: float, tau_L: float) -> None:
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

    def _rk4(
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
