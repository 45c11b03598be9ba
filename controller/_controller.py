"""Field-oriented speed controller with a pluggable rotor-position estimator.

Structure per PWM period (the motulator template: measure, compute output,
update states)::

    sample k -> Clarke -> estimator.update -> Park(theta_hat)  (HF removed)
             -> speed PI -> torque/current limits -> d-q current PI + decoupling
             -> voltage limit -> inverse Park(theta_hat + w_hat 1.5 T_s) + HF injection
             -> SVPWM duties for period k + 1
             -> PI integrators updated with the realised (limited) outputs

Gains from bandwidths (model parameters of :class:`MotorModel`):

- current loop, 2DOF PI per axis (``L = L_d`` or ``L_q``)::

      k_t = alpha_c L,  k_p = 2 alpha_c L - R_s,  k_i = alpha_c^2 L

  with the decoupling ``u_d += -w L_q i_q``, ``u_q += w (L_d i_d + psi_f)``
  the closed loop from reference to current is ``alpha_c / (s + alpha_c)``
  and disturbances are rejected by the double pole at ``-alpha_c``;
- speed loop, 2DOF PI on the mechanical speed::

      k_t = alpha_s J,  k_p = 2 alpha_s J,  k_i = alpha_s^2 J

  giving ``w_m / w_m,ref = alpha_s / (s + alpha_s)`` for a rigid inertia.

Delay compensation: the voltage computed from sample ``k`` acts over
``[(k+1) T_s, (k+2) T_s]``, whose mid-point is ``1.5 T_s`` after the sample,
so the inverse Park uses ``theta_hat + 1.5 T_s w_hat``.

Voltage bookkeeping: the stator-voltage command of every period (fundamental
plus HF, stationary frame) is kept for two periods, so the estimator gets
with sample ``k`` the voltage that acted over ``[(k-1) T_s, k T_s]`` (computed
from sample ``k - 2``; :attr:`EstimatorInput.u_alpha`), which model-based
observers integrate. The polarity test's pulses are recorded the same way.

Voltage limit: the fundamental reference is limited to ``u_dc/sqrt(3) -
|u_h|`` (the linear range of SVPWM less the HF injection) before the HF
voltage is added, so the injection is never clipped and the current PIs
integrate what was actually applied.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from controller._api import (
    MODE_ALIGN,
    MODE_DISABLED,
    MODE_POLARITY,
    MODE_RUN,
    ControlOutput,
    EstimatorInput,
    Measurement,
)
from controller._filters import lpf_first_order
from controller._params import MotorModel
from controller._pi import PIController
from controller._registry import injection_family, make_estimator
from controller._startup import PolarityTest
from controller._svpwm import svpwm

_TWO_PI = 2.0 * math.pi
_SQRT3_INV = 1.0 / math.sqrt(3.0)


@dataclass(frozen=True, slots=True)
class ControllerPars:
    """Controller settings; ``None`` fields get defaults derived from ``motor`` and ``T_s``.

    Parameters
    ----------
    motor : MotorModel
        The controller's own motor model.
    T_s : float
        Control period = PWM period (s).
    estimator : str
        Estimator name (``controller.ESTIMATOR_NAMES``).
    estimator_options : Mapping
        Keyword options of the estimator's ``create``.
    alpha_c : float, optional
        Current-loop bandwidth (rad/s). Default ``min(2 pi 100, 2 pi / (20 T_s))``:
        100 Hz, well below the 500 Hz injection, and at most 1/20 of the
        sampling rate.
    alpha_s : float, optional
        Speed-loop bandwidth (rad/s). Default ``min(2 pi 5, alpha_c / 10)``,
        below the position observers' bandwidth.
    w_f : float, optional
        Corner of the low-pass filter on the estimated speed used by the
        speed loop and the decoupling (rad/s). Default ``4 alpha_s``.
    i_max : float, optional
        Current limit, peak (A). Default ``motor.i_max``.
    tau_max : float, optional
        Torque limit (N m). Default ``motor.tau_max``.
    delay_periods : float
        Delay compensation in the inverse Park (periods); 1.5 = one period
        of computation delay plus half a period of PWM averaging.
    startup : bool
        Run the start-up sequence (align, polarity test) for HF estimators.
        The sensored baseline always starts in ``MODE_RUN``.
    theta0 : float
        Angle (rad, electrical) the estimator starts from on enable; with
        ``startup=False`` this is a known initial rotor angle.
    t_align : float
        Standstill time for the HF estimator to converge (s).
    t_settle : float
        Standstill time after the polarity test before the speed loop is
        released (s).
    i_pulse : float, optional
        Polarity-test peak current (A). Default ``0.5 i_max``.
    """

    motor: MotorModel
    T_s: float
    estimator: str = "tt-dq"
    estimator_options: Mapping[str, Any] = field(default_factory=dict)
    alpha_c: float | None = None
    alpha_s: float | None = None
    w_f: float | None = None
    i_max: float | None = None
    tau_max: float | None = None
    delay_periods: float = 1.5
    startup: bool = True
    theta0: float = 0.0
    t_align: float = 0.1
    t_settle: float = 0.05
    i_pulse: float | None = None

    def __post_init__(self) -> None:
        if not self.T_s > 0.0:
            raise ValueError(f"ControllerPars.T_s must be > 0, got {self.T_s}")
        injection_family(self.estimator)
        a_c = self.alpha_c
        if a_c is None:
            a_c = min(_TWO_PI * 100.0, _TWO_PI / (20.0 * self.T_s))
            object.__setattr__(self, "alpha_c", a_c)
        if self.alpha_s is None:
            object.__setattr__(self, "alpha_s", min(_TWO_PI * 5.0, a_c / 10.0))
        if self.w_f is None:
            object.__setattr__(self, "w_f", 4.0 * float(self.alpha_s or 0.0))
        if self.i_max is None:
            object.__setattr__(self, "i_max", self.motor.i_max)
        if self.tau_max is None:
            object.__setattr__(self, "tau_max", self.motor.tau_max)
        if self.i_pulse is None:
            object.__setattr__(self, "i_pulse", 0.5 * float(self.i_max or 0.0))


class Controller:
    """Speed-controlled FOC drive with a rotor-position estimator.

    Parameters
    ----------
    pars : ControllerPars
        Settings.
    """

    def __init__(self, pars: ControllerPars) -> None:
        self.pars = pars
        m = pars.motor
        T_s = pars.T_s
        self.T_s = T_s
        self.motor = m
        self.family = injection_family(pars.estimator)
        self.estimator = make_estimator(pars.estimator, m, T_s, **dict(pars.estimator_options))
        a_c = float(pars.alpha_c or 0.0)
        a_s = float(pars.alpha_s or 0.0)
        self.pi_d = PIController(2 * a_c * m.L_d - m.R_s, a_c * a_c * m.L_d, T_s, a_c * m.L_d)
        self.pi_q = PIController(2 * a_c * m.L_q - m.R_s, a_c * a_c * m.L_q, T_s, a_c * m.L_q)
        self.pi_w = PIController(2 * a_s * m.J, a_s * a_s * m.J, T_s, a_s * m.J)
        self.lpf_w = lpf_first_order(float(pars.w_f or 0.0), T_s)
        self.k_tau = 1.5 * m.n_p * m.psi_f
        self.i_max = float(pars.i_max or 0.0)
        self.tau_max = float(pars.tau_max or 0.0)
        self.t_delay = pars.delay_periods * T_s
        self.polarity = PolarityTest(m.L_d, T_s, float(pars.i_pulse or 0.0))
        self.n_align = round(pars.t_align / T_s)
        self.n_settle = round(pars.t_settle / T_s)
        self.mode = MODE_DISABLED
        self.w_m_ref = 0.0
        self.i_d_ref = 0.0
        self.i_q_ref = 0.0
        self.tau_ref = 0.0
        self.w_m_hat = 0.0
        #: Realised fundamental voltage of the last step, estimated frame (V).
        self.u_d = 0.0
        self.u_q = 0.0
        # stator-voltage commands (V, stationary): *_1 computed from the last
        # sample (acting now), *_2 from the one before (acted until this sample)
        self._u_a1 = self._u_b1 = self._u_a2 = self._u_b2 = 0.0
        self._n_mode = 0
        self._settled = False
        self._i_ref: tuple[float, float] | None = None
        self._theta_pol = 0.0

    # -- commands ---------------------------------------------------------------
    def set_speed_ref(self, w_m_ref: float) -> None:
        """Mechanical speed reference (rad/s)."""
        self.w_m_ref = float(w_m_ref)

    def set_current_ref(self, i_dq_ref: tuple[float, float] | None) -> None:
        """Current control: hold ``(i_d, i_q)`` references (A) in ``MODE_RUN``, bypassing
        the speed loop; ``None`` returns to speed control."""
        self._i_ref = None if i_dq_ref is None else (float(i_dq_ref[0]), float(i_dq_ref[1]))
        self.pi_w.reset()

    def set_enable(self, enable: bool) -> None:
        """Enable (start-up sequence, then speed control) or disable the inverter."""
        if enable and self.mode == MODE_DISABLED:
            self._restart()
        elif not enable:
            self.mode = MODE_DISABLED

    def _restart(self) -> None:
        self.pi_d.reset()
        self.pi_q.reset()
        self.pi_w.reset()
        self.lpf_w.reset()
        self.estimator.reset(self.pars.theta0)
        self.i_d_ref = self.i_q_ref = self.tau_ref = 0.0
        self._u_a1 = self._u_b1 = self._u_a2 = self._u_b2 = 0.0
        self._n_mode = 0
        self._settled = False
        if self.family == "none" or not self.pars.startup:
            self.mode = MODE_RUN
        else:
            self.mode = MODE_ALIGN

    # -- one PWM period -----------------------------------------------------------
    def step(self, meas: Measurement) -> ControlOutput:
        """Compute the duties for period ``k + 1`` from the samples of period ``k``."""
        k = meas.k
        mode = self.mode
        est = self.estimator
        if mode == MODE_DISABLED:
            return ControlOutput(
                k, 0.5, 0.5, 0.5, False, est.theta_hat % _TWO_PI, est.w_hat, 0.0, mode
            )
        # Measure (amplitude-invariant Clarke).
        i_alpha = (2.0 * meas.i_a - meas.i_b - meas.i_c) / 3.0
        i_beta = (meas.i_b - meas.i_c) * _SQRT3_INV
        u_dc = meas.u_dc
        m = self.motor
        if mode == MODE_POLARITY:
            return self._polarity_step(k, i_alpha, i_beta, u_dc)
        est.update(
            EstimatorInput(
                k,
                i_alpha,
                i_beta,
                self.tau_ref,
                meas.theta_e,
                meas.w_e,
                self._u_a2,
                self._u_b2,
            )
        )
        th = est.theta_hat
        w = est.w_hat
        c = math.cos(th)
        s = math.sin(th)
        i_af = est.i_alpha_f
        i_bf = est.i_beta_f
        i_d = c * i_af + s * i_bf
        i_q = c * i_bf - s * i_af
        # Compute output: speed loop.
        w_m = self.lpf_w.update(w / m.n_p)
        self.w_m_hat = w_m
        i_ref = self._i_ref
        if mode == MODE_RUN and i_ref is not None:
            i_d_ref, i_q_ref = i_ref
            tau = self.k_tau * i_q_ref
        elif mode == MODE_RUN:
            tau_u = self.pi_w.output(self.w_m_ref, w_m)
            tau_max = self.tau_max
            tau = tau_max if tau_u > tau_max else (-tau_max if tau_u < -tau_max else tau_u)
            i_d_ref = 0.0
            i_q_ref = tau / self.k_tau
            i_q_max = math.sqrt(max(self.i_max * self.i_max - i_d_ref * i_d_ref, 0.0))
            if i_q_ref > i_q_max:
                i_q_ref = i_q_max
            elif i_q_ref < -i_q_max:
                i_q_ref = -i_q_max
            tau = self.k_tau * i_q_ref
        else:
            i_d_ref = i_q_ref = tau = 0.0
        # Current loop with decoupling (estimated speed, filtered).
        w_e = m.n_p * w_m
        u_d = self.pi_d.output(i_d_ref, i_d, -w_e * m.L_q * i_q)
        u_q = self.pi_q.output(i_q_ref, i_q, w_e * (m.L_d * i_d + m.psi_f))
        u_ah, u_bh = est.injection()
        u_lim = u_dc * _SQRT3_INV - math.sqrt(u_ah * u_ah + u_bh * u_bh)
        mag2 = u_d * u_d + u_q * u_q
        if mag2 > u_lim * u_lim:
            r = u_lim / math.sqrt(mag2)
            u_dl = u_d * r
            u_ql = u_q * r
        else:
            u_dl = u_d
            u_ql = u_q
        # Inverse Park at the mid-point of period k + 1, then the HF voltage.
        th_u = th + self.t_delay * w
        c_u = math.cos(th_u)
        s_u = math.sin(th_u)
        u_a = c_u * u_dl - s_u * u_ql + u_ah
        u_b = s_u * u_dl + c_u * u_ql + u_bh
        d_a, d_b, d_c = svpwm(u_a, u_b, u_dc)
        self._u_a2 = self._u_a1
        self._u_b2 = self._u_b1
        self._u_a1 = u_a
        self._u_b1 = u_b
        # The speed reported is the filtered estimate the speed loop uses, not
        # the observer's raw output (which carries the demodulation ripple).
        out = ControlOutput(
            k, d_a, d_b, d_c, True, th % _TWO_PI, w_m * m.n_p, est.err, mode, i_d, i_q
        )
        # Update states with the realised outputs.
        self.pi_d.update(u_dl)
        self.pi_q.update(u_ql)
        self.u_d = u_dl
        self.u_q = u_ql
        if mode == MODE_RUN and i_ref is None:
            self.pi_w.update(tau)
        self.i_d_ref = i_d_ref
        self.i_q_ref = i_q_ref
        self.tau_ref = tau
        self._advance_mode(i_alpha, i_beta, u_dc)
        return out

    def _advance_mode(self, i_alpha: float, i_beta: float, u_dc: float) -> None:
        if self.mode != MODE_ALIGN:
            return
        self._n_mode += 1
        if not self._settled and self._n_mode >= self.n_align:
            th = self.estimator.theta_hat
            i_d0 = math.cos(th) * i_alpha + math.sin(th) * i_beta
            self.polarity.start(u_dc, i_d0)
            self._theta_pol = th
            self.mode = MODE_POLARITY
            self._n_mode = 0
        elif self._settled and self._n_mode >= self.n_settle:
            self.pi_w.reset()
            self.mode = MODE_RUN
            self._n_mode = 0

    def _polarity_step(self, k: int, i_alpha: float, i_beta: float, u_dc: float) -> ControlOutput:
        th = self._theta_pol
        c = math.cos(th)
        s = math.sin(th)
        i_d = c * i_alpha + s * i_beta
        i_q = c * i_beta - s * i_alpha
        pt = self.polarity
        u_d = pt.step(i_d)
        if pt.done:
            th_new = (th + math.pi) % _TWO_PI if pt.flip else th
            self.estimator.reset(th_new)
            self.pi_d.reset()
            self.pi_q.reset()
            self.mode = MODE_ALIGN
            self._settled = True
            self._n_mode = 0
        u_a = c * u_d
        u_b = s * u_d
        d_a, d_b, d_c = svpwm(u_a, u_b, u_dc)
        self._u_a2 = self._u_a1
        self._u_b2 = self._u_b1
        self._u_a1 = u_a
        self._u_b1 = u_b
        return ControlOutput(k, d_a, d_b, d_c, True, th, 0.0, 0.0, MODE_POLARITY, i_d, i_q)
