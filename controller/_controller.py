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

Speed-loop bandwidth by design (:func:`speed_loop_margin`). The target
is ``min(2 pi 5, alpha_c / 10)``, which the load steps of the scenarios
need (full load, 7.5 N m on 0.003 kg m^2 in Wen 5.3 and 5.4). The speed
estimate is filtered at ``w_f = 4 alpha_s``; the filter removes the
demodulation ripple and cuts the fast path from the current, through
the demodulator's BPF, back to the speed estimate. The loop ``C(s)
alpha_c/(s + alpha_c) 1/(J s) w_f/(s + w_f) E(s) e^{-1.5 s T_s}`` also
holds the estimator's speed response ``E = w_hat / w``. With an exact
speed ``E = 1``: the sensored baseline, and the square-wave observer,
whose torque feed-forward gives the speed without the correction loop's
lag in the nominal case. The loop then has 44 degrees of phase margin at
the target (35 at 1 kHz, where the delay counts). A rotating-injection
PLL says what its ``E`` is (its ``speed_response``): the demodulation
filters and the PLL, a low-pass at the PLL's bandwidth. ``alpha_s`` is
lowered from the target only as far as needed to keep
:data:`SPEED_PM_MIN_DEG` (30 degrees). That is the usual minimum for an
outer loop, not the 45 of the angle loops: at 45 the tt-dq PLL would cut
the speed loop to 1.6 Hz, too slow for the full-load steps (wen-5.3 then
loses the rotor). With tt-dq's designed PLL (58.5 rad/s) the target
would keep 3 degrees, so its speed loop runs at 18.8 rad/s (3.0 Hz).
sfhf runs at 4.9 Hz and tt-ab at 4.4 Hz. The sensored and the
square-wave drives keep the target exactly.

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

Current fed to the PIs (``current_feedback``): ``"filtered"`` (default)
is the estimator's current with the HF response removed, so the PIs do
not react to the injection. ``"raw"`` is the sampled current, HF
included. That is the assumption of Wen Sec. 3.3, eqs. (14)-(16): the
PI then shapes the HF response. With the gains above, ``k_p + R_s = 2
alpha_c L`` and ``k_i = alpha_c^2 L``, so eq. (14) becomes ``i/u =
s^2 / (L s (s + alpha_c)^2)``. That is the inductance's response times
``s^2/(s + alpha_c)^2``, the same factor on both axes, whose phase
``phi_pi = 2 atan(alpha_c / w)`` is odd in the frequency ``w`` the HF
current has in the estimated frame. The decoupling always uses the
filtered current.

Drive countermeasures (``compensation``, :mod:`controller._compensation`),
each off by default: dead-time feed-forward on the duties, the
cross-saturation angle correction (the angle used for the transforms and
reported is ``theta_hat`` of the estimator minus its cross-saturation
offset; an estimator with a ``saliency_offset`` attribute, the hybrids, is
given the offset and subtracts it from its injection estimate alone), and a
current-offset calibration with the PWM disabled before
each start (the controller reports ``MODE_ALIGN`` with the PWM disabled
meanwhile).

:meth:`Controller.gains` lists every gain, bandwidth, corner and delay
the controller uses, the estimator's included.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controller._api import (
    MODE_ALIGN,
    MODE_DISABLED,
    MODE_POLARITY,
    MODE_RUN,
    ControlOutput,
    EstimatorInput,
    Measurement,
)
from controller._compensation import (
    CompensationPars,
    DeadTimeCompensator,
    OffsetCalibration,
    cross_saturation_offset,
    offset_periods,
)
from controller._compiled import build_core
from controller._engine import KIND_EXTERNAL, resolve_controller_engine
from controller._filters import lpf_first_order
from controller._hybrid import HybridEstimator
from controller._params import MotorModel
from controller._pi import PIController
from controller._registry import estimator_family, injection_family, make_estimator
from controller._startup import PolarityTest
from controller._supervision import SupervisionPars, Supervisor
from controller._svpwm import svpwm

_TWO_PI = 2.0 * math.pi
_SQRT3_INV = 1.0 / math.sqrt(3.0)

#: The states :meth:`Controller.states` reports (the compiled core's readable members).
STATE_NAMES = (
    "mode",
    "w_m_ref",
    "w_m_hat",
    "i_d_ref",
    "i_q_ref",
    "tau_ref",
    "u_d",
    "u_q",
    "pi_d_u_i",
    "pi_q_u_i",
    "pi_w_u_i",
    "polarity_flip",
    "theta_hat",
    "w_hat",
    "err",
)

#: The hybrid estimators' own states :meth:`Controller.states` adds for them: the observer's
#: weight, the injection's gain, the schedule speed, and the injection estimator's and the
#: flux observer's angles and speeds (:class:`controller.HybridEstimator`).
HYBRID_STATE_NAMES = (
    "weight",
    "gain",
    "y",
    "hf_theta_hat",
    "hf_w_hat",
    "obs_theta_hat",
    "obs_w_hat",
)

#: Least phase margin of the speed loop, estimator included (deg); module docstring.
SPEED_PM_MIN_DEG = 30.0


@dataclass(frozen=True, slots=True)
class ControllerPars:
    """Controller settings; ``None`` fields get defaults derived from ``motor`` and ``T_s``
    (``alpha_s`` and ``w_f`` by the :class:`Controller`, which holds the values it uses).

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
        Speed-loop bandwidth (rad/s). Default: the target ``min(2 pi 5,
        alpha_c / 10)``, lowered for an estimator whose speed estimate lags
        (module docstring); the controller's ``alpha_s`` holds the value used.
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
    compensation : CompensationPars
        Dead-time feed-forward, cross-saturation correction, offset
        calibration (:mod:`controller._compensation`); all off by default.
    current_feedback : str
        ``"filtered"`` (HF removed, default) or ``"raw"`` (Wen Sec. 3.3: the
        current PIs see the HF current).
    supervision : SupervisionPars, optional
        The drive's fault detection (:mod:`controller._supervision`); None: off.
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
    compensation: CompensationPars = field(default_factory=CompensationPars)
    current_feedback: str = "filtered"
    supervision: SupervisionPars | None = None

    def __post_init__(self) -> None:
        if not self.T_s > 0.0:
            raise ValueError(f"ControllerPars.T_s must be > 0, got {self.T_s}")
        if self.current_feedback not in ("filtered", "raw"):
            raise ValueError(
                f"ControllerPars.current_feedback must be 'filtered' or 'raw', "
                f"got {self.current_feedback!r}"
            )
        injection_family(self.estimator)
        a_c = self.alpha_c
        if a_c is None:
            a_c = min(_TWO_PI * 100.0, _TWO_PI / (20.0 * self.T_s))
            object.__setattr__(self, "alpha_c", a_c)
        if self.i_max is None:
            object.__setattr__(self, "i_max", self.motor.i_max)
        if self.tau_max is None:
            object.__setattr__(self, "tau_max", self.motor.tau_max)
        if self.i_pulse is None:
            object.__setattr__(self, "i_pulse", 0.5 * float(self.i_max or 0.0))


def speed_loop_margin(
    alpha_s: float,
    alpha_c: float,
    w_f: float,
    T_s: float,
    speed_resp: Callable[[np.ndarray], np.ndarray] | None,
) -> tuple[float, float]:
    """Phase margin (deg) and crossover (rad/s) of the speed loop (module docstring).

    ``L = (2 alpha_s s + alpha_s^2) / s^2 * alpha_c / (s + alpha_c) * w_f / (s + w_f) * E
    * exp(-1.5 s T_s)``; the inertia cancels. ``E = speed_resp(w)``, or 1.
    """
    from controller._design import margins

    def loop(w: np.ndarray) -> np.ndarray:
        s = 1j * w
        out = (2.0 * alpha_s * s + alpha_s * alpha_s) / (s * s)
        out = out * alpha_c / (s + alpha_c) * np.exp(-1.5 * s * T_s)
        out = out * w_f / (s + w_f)
        return out * speed_resp(w) if speed_resp is not None else out

    return margins(loop, 1e-3 * alpha_s, 0.999 * math.pi / T_s, 2)


def speed_bandwidth(
    target: float,
    alpha_c: float,
    T_s: float,
    speed_resp: Callable[[np.ndarray], np.ndarray] | None,
    w_f: float | None,
) -> float:
    """Largest ``alpha_s <= target`` whose loop with ``speed_resp`` and the filter ``w_f``
    (None: ``4 alpha_s``) keeps :data:`SPEED_PM_MIN_DEG` (module docstring)."""
    from controller._design import solve_largest

    def wf(a: float) -> float:
        return 4.0 * a if w_f is None else w_f

    if speed_resp is None:
        return target
    if speed_loop_margin(target, alpha_c, wf(target), T_s, speed_resp)[0] >= SPEED_PM_MIN_DEG:
        return target
    return solve_largest(
        lambda a: speed_loop_margin(a, alpha_c, wf(a), T_s, speed_resp)[0],
        SPEED_PM_MIN_DEG,
        1e-3 * target,
        target,
        rising=False,
    )


class ReferenceModel:
    """The speed loop's designed response to its reference, and the acceleration it implies.

    The 2DOF speed PI is designed so that ``w_m / w_m,ref = alpha_s / (s +
    alpha_s)`` for a rigid inertia (module docstring). This model runs that
    response on the reference alone (forward Euler, the same step as the
    PI's integrator): its state ``w`` is the speed the loop is designed to
    reach, and :meth:`update` returns its slope times ``n_p``, the electrical
    acceleration the loop is designed to give the rotor. Limited to what the
    torque limit can give the model's inertia, ``n_p tau_max / J``, since the
    loop cannot give more. It reads no estimate, so whatever takes it as a
    feed-forward keeps its own loop as it was (tt-dq's ``accel_ff``,
    :mod:`controller._rotating`).
    """

    __slots__ = ("T_s", "a_max", "alpha_s", "n_p", "w")

    def __init__(self, alpha_s: float, n_p: int, J: float, tau_max: float, T_s: float) -> None:
        self.alpha_s = alpha_s
        self.n_p = n_p
        self.a_max = n_p * tau_max / J if tau_max > 0.0 else math.inf
        self.T_s = T_s
        self.w = 0.0

    def reset(self, w0: float = 0.0) -> None:
        """Start from the speed ``w0`` (rad/s, mechanical)."""
        self.w = w0

    def update(self, w_ref: float) -> float:
        """Advance one period with the reference ``w_ref`` (rad/s, mechanical); return the
        designed electrical acceleration (rad/s^2) of the period."""
        dw = self.alpha_s * (w_ref - self.w)
        a = self.n_p * dw
        a_max = self.a_max
        if a > a_max:
            a, dw = a_max, a_max / self.n_p
        elif a < -a_max:
            a, dw = -a_max, -a_max / self.n_p
        self.w += self.T_s * dw
        return a


class Controller:
    """Speed-controlled FOC drive with a rotor-position estimator.

    Parameters
    ----------
    pars : ControllerPars
        Settings.
    engine : {"auto", "compiled", "python"}, optional
        Which implementation runs the periods (:mod:`controller._engine`):
        ``"compiled"`` (C, the same trace bit for bit) where it covers the
        estimator and settings, else Python; ``"auto"`` (default) the same,
        and Python when the compiled engine is not built. The engine in use is
        :attr:`engine`, and :attr:`engine_note` says why it is Python.
    """

    #: The engine the periods run on, ``"compiled"`` or ``"python"``.
    engine: str = "python"
    #: Why the controller runs in Python although the compiled engine was asked for.
    engine_note: str | None = None
    #: The compiled core calls the estimator's Python methods each period (a plug-in's
    #: Python estimator, :data:`controller._engine.KIND_EXTERNAL`): the periods need
    #: Python. False for a plug-in's estimator in C (:func:`controller.c_estimator`).
    external_estimator: bool = False

    def __init__(self, pars: ControllerPars, engine: str = "auto") -> None:
        self.pars = pars
        m = pars.motor
        T_s = pars.T_s
        self.T_s = T_s
        self.motor = m
        self.estimator = make_estimator(pars.estimator, m, T_s, **dict(pars.estimator_options))
        # a plug-in that returns a shipped estimator runs as it does (controller._registry)
        self.family = estimator_family(pars.estimator, self.estimator)
        a_c = float(pars.alpha_c or 0.0)
        a_s, w_f = self._speed_loop_design()
        #: Speed-loop bandwidth (rad/s) and speed-estimate filter corner (rad/s) in use.
        self.alpha_s = a_s
        self.w_f = w_f
        self.pi_d = PIController(2 * a_c * m.L_d - m.R_s, a_c * a_c * m.L_d, T_s, a_c * m.L_d)
        self.pi_q = PIController(2 * a_c * m.L_q - m.R_s, a_c * a_c * m.L_q, T_s, a_c * m.L_q)
        self.pi_w = PIController(2 * a_s * m.J, a_s * a_s * m.J, T_s, a_s * m.J)
        self.lpf_w = lpf_first_order(w_f, T_s)
        self.k_tau = 1.5 * m.n_p * m.psi_f
        self.i_max = float(pars.i_max or 0.0)
        self.tau_max = float(pars.tau_max or 0.0)
        #: The speed loop's designed response to the reference (EstimatorInput.accel_ref).
        self.ref_model = ReferenceModel(a_s, m.n_p, m.J, self.tau_max, T_s)
        self.t_delay = pars.delay_periods * T_s
        self.polarity = PolarityTest(m.L_d, T_s, float(pars.i_pulse or 0.0))
        self.n_align = round(pars.t_align / T_s)
        self.n_settle = round(pars.t_settle / T_s)
        cp = pars.compensation
        self.raw_feedback = pars.current_feedback == "raw"
        self.dead_time: DeadTimeCompensator | None = None
        hf_next = getattr(self.estimator, "hf_current_next", None)
        self._hf_next: Callable[[], tuple[float, float]] | None = (
            hf_next if cp.dead_time and callable(hf_next) else None
        )
        if cp.dead_time:
            band, sine = self._dead_time_sign_model()
            if cp.i_band is not None:
                band = cp.i_band
            self.dead_time = DeadTimeCompensator(T_s, cp.t_dead, cp.v_ce, cp.v_f, band, sine)
        self.cross_sat = cp.cross_saturation and self.family != "none"
        # An estimator with a ``saliency_offset`` attribute (the hybrids) takes the
        # correction itself: it belongs to the saliency-based part of its estimate.
        self._sal_own = self.cross_sat and hasattr(self.estimator, "saliency_offset")
        self.calibration: OffsetCalibration | None = None
        if cp.offset_calibration:
            n_cal = cp.offset_periods
            if n_cal is None:
                tol = cp.offset_tol
                if tol is None:
                    tol = 0.5 * cp.adc_lsb if cp.adc_lsb > 0.0 else 1e-3 * self.i_max
                n_cal = offset_periods(cp.current_noise, cp.adc_lsb, tol)
            self.calibration = OffsetCalibration(n_cal)
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
        # the engine: the controller core (controller/core/, by composition) where it
        # covers this controller, else the Python step below
        self._core: Any = None
        used, why = resolve_controller_engine(engine, pars)
        if used == "compiled":
            self._core, why = build_core(self)
        self.engine_note = why
        if self._core is not None:
            self.engine = "compiled"
            self.external_estimator = bool(
                self._core.kind == KIND_EXTERNAL and self._core.calls_python
            )
            # the core's step is called directly (no Python frame per period)
            self.step = self._core.step  # type: ignore[method-assign]
        # the supervision hook: the step (the core's or Python's) with
        # controller._supervision after it
        self.supervisor = None if pars.supervision is None else Supervisor(pars.supervision)
        self.__dict__["step"] = self._supervised(self.step)

    def _supervised(self, step: Callable[[Measurement], ControlOutput]) -> Any:
        """``step`` with the supervision after it, or ``step`` without one (the compiled
        core runs it in C, controller/core/cc_supervision.c, after its own step)."""
        sup = self.supervisor
        if sup is not None and self._core is not None:
            self._core.supervision(*sup.args())
            return step
        return step if sup is None else sup.wrap(step, lambda: self.set_enable(False))

    # -- commands ---------------------------------------------------------------
    def set_speed_ref(self, w_m_ref: float) -> None:
        """Mechanical speed reference (rad/s)."""
        w = float(w_m_ref)
        self.w_m_ref = w
        if self._core is not None:
            self._core.set_speed_ref(w)

    def set_current_ref(self, i_dq_ref: tuple[float, float] | None) -> None:
        """Current control: hold ``(i_d, i_q)`` references (A) in ``MODE_RUN``, bypassing
        the speed loop; ``None`` returns to speed control."""
        self._i_ref = None if i_dq_ref is None else (float(i_dq_ref[0]), float(i_dq_ref[1]))
        self.pi_w.reset()
        if self._core is not None:
            self._core.set_current_ref(self._i_ref)

    def set_enable(self, enable: bool) -> None:
        """Enable (start-up sequence, then speed control) or disable the inverter."""
        if self._core is not None:
            self._core.set_enable(bool(enable))
            return
        if enable and self.mode == MODE_DISABLED:
            self._restart()
        elif not enable:
            self.mode = MODE_DISABLED

    def _restart(self) -> None:
        self.pi_d.reset()
        self.pi_q.reset()
        self.pi_w.reset()
        self.lpf_w.reset()
        self.ref_model.reset()
        self.estimator.reset(self.pars.theta0)
        self.i_d_ref = self.i_q_ref = self.tau_ref = 0.0
        self._u_a1 = self._u_b1 = self._u_a2 = self._u_b2 = 0.0
        self._n_mode = 0
        self._settled = False
        if self.calibration is not None:
            self.calibration.restart()
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
        # Measure (amplitude-invariant Clarke), offsets removed when calibrated.
        i_a = meas.i_a
        i_b = meas.i_b
        i_c = meas.i_c
        cal = self.calibration
        if cal is not None:
            if not cal.done:
                cal.add(i_a, i_b, i_c)
                return ControlOutput(
                    k, 0.5, 0.5, 0.5, False, est.theta_hat % _TWO_PI, 0.0, 0.0, MODE_ALIGN
                )
            i_a -= cal.o_a
            i_b -= cal.o_b
            i_c -= cal.o_c
        i_alpha = (2.0 * i_a - i_b - i_c) / 3.0
        i_beta = (i_b - i_c) * _SQRT3_INV
        u_dc = meas.u_dc
        m = self.motor
        if mode == MODE_POLARITY:
            return self._polarity_step(k, i_alpha, i_beta, u_dc)
        if self._sal_own:
            # the hybrid corrects its injection estimate only (controller._hybrid)
            est.saliency_offset = cross_saturation_offset(  # type: ignore[attr-defined]
                m.k_dq, self.i_q_ref, m.L_d, m.L_q
            )
        speed_loop = mode == MODE_RUN and self._i_ref is None
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
                mode == MODE_RUN,
                self.ref_model.update(self.w_m_ref) if speed_loop else 0.0,
            )
        )
        th = est.theta_hat
        if self.cross_sat and not self._sal_own:
            th -= cross_saturation_offset(m.k_dq, self.i_q_ref, m.L_d, m.L_q)
        w = est.w_hat
        c = math.cos(th)
        s = math.sin(th)
        i_af = est.i_alpha_f
        i_bf = est.i_beta_f
        i_d = c * i_af + s * i_bf
        i_q = c * i_bf - s * i_af
        if self.raw_feedback:
            i_d_pi = c * i_alpha + s * i_beta
            i_q_pi = c * i_beta - s * i_alpha
        else:
            i_d_pi = i_d
            i_q_pi = i_q
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
        u_d = self.pi_d.output(i_d_ref, i_d_pi, -w_e * m.L_q * i_q)
        u_q = self.pi_q.output(i_q_ref, i_q_pi, w_e * (m.L_d * i_d + m.psi_f))
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
        # the voltage commanded for period k + 1 (the dead-time feed-forward below
        # makes the inverter give it), which a model-based estimator integrates
        self._u_a2 = self._u_a1
        self._u_b2 = self._u_b1
        self._u_a1 = u_a
        self._u_b1 = u_b
        dt = self.dead_time
        if dt is not None:
            # phase currents expected at the mid-point of period k + 1: the reference,
            # plus the injection's HF current where the estimator predicts it
            i_ar = c_u * i_d_ref - s_u * i_q_ref
            i_br = s_u * i_d_ref + c_u * i_q_ref
            hf = self._hf_next
            if hf is not None:
                h_a, h_b = hf()
                i_ar += h_a
                i_br += h_b
            h = 0.5 * math.sqrt(3.0) * i_br
            d_a, d_b, d_c = dt.duties(d_a, d_b, d_c, i_ar, -0.5 * i_ar + h, -0.5 * i_ar - h, u_dc)
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

    def _speed_loop_design(self) -> tuple[float, float]:
        """``(alpha_s, w_f)``: given values, or the design of the module docstring."""
        p = self.pars
        a_c = float(p.alpha_c or 0.0)
        resp = getattr(self.estimator, "speed_response", None)
        self._speed_resp: Callable[[np.ndarray], np.ndarray] | None = (
            resp if callable(resp) else None
        )
        if p.alpha_s is not None:
            a_s = float(p.alpha_s)
        else:
            a_s = speed_bandwidth(
                min(_TWO_PI * 5.0, a_c / 10.0), a_c, self.T_s, self._speed_resp, p.w_f
            )
        w_f = float(p.w_f) if p.w_f is not None else 4.0 * a_s
        return a_s, w_f

    def _dead_time_sign_model(self) -> tuple[float, bool]:
        """Smoothing band (A) and law (sinusoid: True) of the current sign for the dead time.

        Rotating injection whose estimator predicts its HF current
        (``hf_current_next``): the sign is that of the reference plus the
        predicted HF current at the mid-point of the period, and the band is
        how far the HF current moves in half a period, ``I_p w_h T_s / 2``
        (triangle law). Rotating injection without that prediction: the HF
        period's mean, band ``I_p`` (sinusoid law). Square wave: the HF
        triangle of the period itself, band ``U_h T_s / (2 L_d)``. No
        injection: 0 (hard sign). :mod:`controller._compensation` derives the
        laws.
        """
        est = self.estimator
        if self.family == "rotating":
            I_p = float(getattr(est, "I_p", 0.0))
            if self._hf_next is not None:
                return 0.5 * I_p * float(getattr(est, "wT", 0.0)), False
            return I_p, True
        if self.family == "square":
            return float(getattr(est, "U_h", 0.0)) * self.T_s / (2.0 * self.motor.L_d), False
        return 0.0, False

    def gains(self) -> dict[str, float]:
        """Every gain, bandwidth, filter corner and delay the controller uses (for ``meta.json``).

        Keys: current loops (``alpha_c`` rad/s, ``k_p_d``/``k_i_d``/``k_t_d`` and
        the q-axis ones, V/A and V/(A s)), speed loop (``alpha_s`` rad/s,
        ``k_p_w``, ``k_i_w``, ``k_t_w``), speed-estimate filter ``w_f`` (rad/s),
        delay compensation ``delay_periods``, limits, start-up timing, the
        countermeasures (``comp.*``; flags as 0/1), the current fed to the PIs
        (``raw_current_feedback``), and the estimator's own (``estimator.*``).
        """
        p = self.pars
        cp = p.compensation
        out: dict[str, float] = {
            "T_s": self.T_s,
            "alpha_c": float(p.alpha_c or 0.0),
            "k_p_d": self.pi_d.k_p,
            "k_i_d": self.pi_d.k_i,
            "k_t_d": self.pi_d.k_t,
            "k_p_q": self.pi_q.k_p,
            "k_i_q": self.pi_q.k_i,
            "k_t_q": self.pi_q.k_t,
            "alpha_s": self.alpha_s,
            "k_p_w": self.pi_w.k_p,
            "k_i_w": self.pi_w.k_i,
            "k_t_w": self.pi_w.k_t,
            "w_f": self.w_f,
            "speed_pm_deg": speed_loop_margin(
                self.alpha_s, float(p.alpha_c or 0.0), self.w_f, self.T_s, self._speed_resp
            )[0],
            "delay_periods": p.delay_periods,
            "i_max": self.i_max,
            "tau_max": self.tau_max,
            "t_align": p.t_align,
            "t_settle": p.t_settle,
            "i_pulse": float(p.i_pulse or 0.0),
            "raw_current_feedback": 1.0 if self.raw_feedback else 0.0,
            "comp.dead_time": 1.0 if self.dead_time is not None else 0.0,
            "comp.t_dead": cp.t_dead,
            "comp.v_ce": cp.v_ce,
            "comp.v_f": cp.v_f,
            "comp.i_band": self.dead_time.i_band if self.dead_time is not None else 0.0,
            "comp.cross_saturation": 1.0 if self.cross_sat else 0.0,
            "comp.k_dq": self.motor.k_dq,
            "comp.offset_calibration": 1.0 if self.calibration is not None else 0.0,
            "comp.offset_periods": float(self.calibration.n) if self.calibration else 0.0,
        }
        if self.supervisor is not None:
            for key, v in self.supervisor.gains().items():
                out["supervision." + key] = v
        g = getattr(self.estimator, "gains", None)
        est_gains: dict[str, float] = g() if callable(g) else {}
        for key, v in est_gains.items():
            out["estimator." + key] = float(v)
        return out

    def states(self) -> dict[str, float]:
        """The controller's present states, from whichever engine keeps them: ``mode``,
        ``w_m_ref``, ``w_m_hat``, the references ``i_d_ref``, ``i_q_ref``, ``tau_ref``,
        the realised voltage ``u_d``, ``u_q``, the PI integrators ``pi_d_u_i``,
        ``pi_q_u_i``, ``pi_w_u_i``, the last polarity test's outcome ``polarity_flip``
        (1: the estimate was turned by pi), the estimate ``theta_hat``, ``w_hat``, ``err``, the
        HF voltage for the next period ``u_h_alpha``, ``u_h_beta``
        (:meth:`injection`) and, for a hybrid estimator, :data:`HYBRID_STATE_NAMES`."""
        c = self._core
        hybrid = isinstance(self.estimator, HybridEstimator)
        u_h = self.injection()
        est = self.estimator
        if c is not None:
            out = {name: getattr(c, name) for name in STATE_NAMES}
            out["u_h_alpha"], out["u_h_beta"] = u_h
            if hybrid and c.kind != KIND_EXTERNAL:
                out.update({name: getattr(c, name) for name in HYBRID_STATE_NAMES})
            elif isinstance(est, HybridEstimator):  # a plug-in's hybrid: its own states
                out.update(_hybrid_states(est))
            return out
        out = {
            "mode": self.mode,
            "w_m_ref": self.w_m_ref,
            "w_m_hat": self.w_m_hat,
            "i_d_ref": self.i_d_ref,
            "i_q_ref": self.i_q_ref,
            "tau_ref": self.tau_ref,
            "u_d": self.u_d,
            "u_q": self.u_q,
            "pi_d_u_i": self.pi_d.u_i,
            "pi_q_u_i": self.pi_q.u_i,
            "pi_w_u_i": self.pi_w.u_i,
            "polarity_flip": int(self.polarity.flip),
            "theta_hat": est.theta_hat,
            "w_hat": est.w_hat,
            "err": est.err,
            "u_h_alpha": u_h[0],
            "u_h_beta": u_h[1],
        }
        if isinstance(est, HybridEstimator):
            out.update(_hybrid_states(est))
        return out

    def injection(self) -> tuple[float, float]:
        """The HF voltage (alpha, beta) (V) the estimator adds to the command of the next
        period, from whichever engine runs the periods."""
        c = self._core
        if c is not None:
            u_a, u_b = c.injection()
            return float(u_a), float(u_b)
        u_a, u_b = self.estimator.injection()
        return float(u_a), float(u_b)

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
        dt = self.dead_time
        if dt is not None:
            # the pulses get the same feed-forward as every other voltage: uncompensated,
            # the bridge's drops oppose the rise and aid the return of each pulse, which
            # leaves a current offset of the order of the saturation asymmetry the test
            # measures; the sign is the present pulse current's, along the pulse axis
            i_a = c * i_d
            h = 0.5 * math.sqrt(3.0) * s * i_d
            d_a, d_b, d_c = dt.duties(d_a, d_b, d_c, i_a, -0.5 * i_a + h, -0.5 * i_a - h, u_dc)
        self._u_a2 = self._u_a1
        self._u_b2 = self._u_b1
        self._u_a1 = u_a
        self._u_b1 = u_b
        return ControlOutput(k, d_a, d_b, d_c, True, th, 0.0, 0.0, MODE_POLARITY, i_d, i_q)


def _hybrid_states(est: HybridEstimator) -> dict[str, float]:
    """:data:`HYBRID_STATE_NAMES` of a hybrid estimator the Python engine steps."""
    return {
        "weight": est.weight,
        "gain": est.gain,
        "y": est.y,
        "hf_theta_hat": est.hf.theta_hat,
        "hf_w_hat": est.hf.w_hat,
        "obs_theta_hat": est.observer.theta_hat,
        "obs_w_hat": est.observer.w_hat,
    }


def _state(name: str) -> property:
    """The controller's state ``name``: the compiled core's when it runs the periods, else
    the Python step's."""

    def get(self: Controller) -> Any:
        core = self.__dict__.get("_core")
        return getattr(core, name) if core is not None else self.__dict__[name]

    def put(self: Controller, value: Any) -> None:
        self.__dict__[name] = value

    return property(get, put, doc=f"``{name}`` (read from the compiled core when it runs)")


for _name in STATE_NAMES[:8]:
    setattr(Controller, _name, _state(_name))
