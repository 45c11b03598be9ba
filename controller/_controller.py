"""Field-oriented speed controller with a pluggable rotor-position estimator.

Python designs the controller (every gain, filter, limit and delay below,
with its derivation); its one engine, the portable C core
(``controller/core/cc_foc.c`` and the blocks it calls, :mod:`controller._engine`),
runs the periods. The same step in Python is the tests' oracle
(``tests/oracle/``), which the core matches bit for bit.

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

import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controller._api import (
    ControlOutput,
    Measurement,
)
from controller._compensation import (
    CompensationPars,
    DeadTimeCompensator,
    OffsetCalibration,
    offset_periods,
)
from controller._compiled import build_core
from controller._design import DesignRecord, designed, designing, settings_digest
from controller._engine import KIND_EXTERNAL, _cctl, resolve_controller_engine
from controller._filters import lpf_first_order
from controller._hybrid import HybridEstimator
from controller._params import MotorModel
from controller._pi import PIController
from controller._registry import estimator_family, injection_family, make_estimator
from controller._startup import PolarityTest
from controller._supervision import SupervisionPars, Supervisor

_TWO_PI = 2.0 * math.pi

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


@designed
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


@designed
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
    reach, and its step returns the slope times ``n_p``, the electrical
    acceleration the loop is designed to give the rotor. Limited to what the
    torque limit can give the model's inertia, ``n_p tau_max / J``, since the
    loop cannot give more. It reads no estimate, so whatever takes it as a
    feed-forward keeps its own loop as it was (tt-dq's ``accel_ff``,
    :mod:`controller._rotating`).

    This class holds the design (``alpha_s``, ``n_p``, ``a_max``, ``T_s``);
    the step runs in the core (``controller/core/cc_reference.c``), and in
    Python in the tests' oracle (``tests/oracle/blocks.py``).
    """

    __slots__ = ("T_s", "a_max", "alpha_s", "n_p")

    def __init__(self, alpha_s: float, n_p: int, J: float, tau_max: float, T_s: float) -> None:
        self.alpha_s = alpha_s
        self.n_p = n_p
        self.a_max = n_p * tau_max / J if tau_max > 0.0 else math.inf
        self.T_s = T_s


class Controller:
    """Speed-controlled FOC drive with a rotor-position estimator.

    Parameters
    ----------
    pars : ControllerPars
        Settings.
    engine : {"auto", "compiled", "python"}, optional
        Kept for compatibility (:mod:`controller._engine`): every choice runs the
        periods on the controller core (C), with the bits the Python step gave
        when it was an engine (``tests/oracle/`` checks them).
    design : DesignRecord, optional
        The design of these settings made before (:meth:`design_record`, e.g. in
        the process that wrote a run's plan): its searches are not run again
        (:mod:`controller._design`). A record made for other settings is not
        used: the controller designs itself and :attr:`design_refused` says why.
    """

    #: The engine the periods run on: ``"compiled"``, the core, whatever the choice.
    engine: str = "compiled"
    #: Why the controller would run outside the core: None (kept for the node reports).
    engine_note: str | None = None
    # the core's states, read-only (properties made by _state below)
    mode: int
    w_m_ref: float
    w_m_hat: float
    i_d_ref: float
    i_q_ref: float
    tau_ref: float
    #: Realised fundamental voltage of the last step, estimated frame (V).
    u_d: float
    u_q: float

    def __init__(
        self, pars: ControllerPars, engine: str = "auto", design: DesignRecord | None = None
    ) -> None:
        self.pars = pars
        digest = settings_digest(pars)
        #: Why the given ``design`` was not used (made for other settings), else None.
        self.design_refused: str | None = None
        book: dict[str, Any] = {}
        if design is not None:
            if design.settings == digest:
                book = dict(design.results)
            else:
                self.design_refused = "the design given was made for other controller settings"
        self._design_book = book
        self._design_digest = digest
        with designing(book):
            self._build(pars, engine)

    def design_record(self) -> DesignRecord:
        """This controller's design (its searches' results, :mod:`controller._design`), to
        build the same controller elsewhere without them: its gains' margins included."""
        self.gains()
        # as JSON keeps it (tuples as lists, floats as floats): equal once written and read
        results = json.loads(json.dumps(self._design_book))
        return DesignRecord(self._design_digest, results)

    def _build(self, pars: ControllerPars, engine: str) -> None:
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
        #: The dead-time feed-forward adds the HF current the estimator predicts for the
        #: next period: a shipped estimator's design says so (``predicts_hf``), a plug-in's
        #: Python estimator by having ``hf_current_next``.
        self._predicts_hf = cp.dead_time and bool(
            getattr(self.estimator, "predicts_hf", False)
            or callable(getattr(self.estimator, "hf_current_next", None))
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
        # the supervision: the core runs it after its own step (controller/core/cc_supervision.c)
        self.supervisor = None if pars.supervision is None else Supervisor(pars.supervision)
        resolve_controller_engine(engine, pars)  # an unknown engine name is refused
        self._core: Any = self._attach_engine()
        #: The core calls the estimator's Python methods each period (a plug-in's Python
        #: estimator, :data:`controller._engine.KIND_EXTERNAL`).
        self.external_estimator = bool(
            self._core is not None and self._core.kind == KIND_EXTERNAL and self._core.calls_python
        )

    def _attach_engine(self) -> Any:
        """The core built from this design (:func:`controller._compiled.build_core`), its
        supervision set, and its step taken as the instance's (called directly: no Python
        frame per period)."""
        core, _ = build_core(self)
        if self.supervisor is not None:
            core.supervision(*self.supervisor.args())
        self.step = core.step  # type: ignore[method-assign]
        return core

    # -- commands (forwarded to the core) ------------------------------------------
    def set_speed_ref(self, w_m_ref: float) -> None:
        """Mechanical speed reference (rad/s)."""
        self._core.set_speed_ref(float(w_m_ref))

    def set_current_ref(self, i_dq_ref: tuple[float, float] | None) -> None:
        """Current control: hold ``(i_d, i_q)`` references (A) in ``MODE_RUN``, bypassing
        the speed loop; ``None`` returns to speed control."""
        ref = None if i_dq_ref is None else (float(i_dq_ref[0]), float(i_dq_ref[1]))
        self._core.set_current_ref(ref)

    def set_enable(self, enable: bool) -> None:
        """Enable (start-up sequence, then speed control) or disable the inverter."""
        self._core.set_enable(bool(enable))

    # -- one PWM period -----------------------------------------------------------
    def step(self, meas: Measurement) -> ControlOutput:
        """Compute the duties for period ``k + 1`` from the samples of period ``k``: the
        core's step (module docstring), which an instance calls directly, without this
        Python frame."""
        out: ControlOutput = self._core.step(meas)
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
        (``predicts_hf``): the sign is that of the reference plus the
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
            if self._predicts_hf:
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
        with designing(self._design_book):
            return self._gains()

    def _gains(self) -> dict[str, float]:
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
        """The controller's present states, read from the core: ``mode``,
        ``w_m_ref``, ``w_m_hat``, the references ``i_d_ref``, ``i_q_ref``, ``tau_ref``,
        the realised voltage ``u_d``, ``u_q``, the PI integrators ``pi_d_u_i``,
        ``pi_q_u_i``, ``pi_w_u_i``, the last polarity test's outcome ``polarity_flip``
        (1: the estimate was turned by pi), the estimate ``theta_hat``, ``w_hat``, ``err``, the
        HF voltage for the next period ``u_h_alpha``, ``u_h_beta``
        (:meth:`injection`) and, for a hybrid estimator, :data:`HYBRID_STATE_NAMES`."""
        c = self._core
        out = {name: getattr(c, name) for name in STATE_NAMES}
        out["u_h_alpha"], out["u_h_beta"] = self.injection()
        est = self.estimator
        if isinstance(est, HybridEstimator) and c.kind != KIND_EXTERNAL:
            out.update({name: getattr(c, name) for name in HYBRID_STATE_NAMES})
        elif isinstance(est, HybridEstimator):  # a plug-in's hybrid: its own states
            out.update(hybrid_states(est))
        return out

    def quadrature(self) -> tuple[float, float]:
        """The square-wave estimators' position quadrature signal ``(e_alpha, e_beta)`` (A),
        interpolated or held (Xue Figs. 11-12; the hybrid-square-wave's injection
        estimator's), read from the core; ``(0, 0)`` for another estimator."""
        c = self._core
        if c.kind not in (_cctl.KIND_SQW, _cctl.KIND_HYB_SQW):
            return 0.0, 0.0
        return float(c.e_alpha), float(c.e_beta)

    def injection(self) -> tuple[float, float]:
        """The HF voltage (alpha, beta) (V) the estimator adds to the command of the next
        period, read from the core."""
        u_a, u_b = self._core.injection()
        return float(u_a), float(u_b)


def hybrid_states(est: HybridEstimator) -> dict[str, float]:
    """:data:`HYBRID_STATE_NAMES` of a hybrid estimator whose methods Python runs (a plug-in's,
    which the core calls)."""
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
    """The controller's state ``name``, read from the core."""

    def get(self: Controller) -> Any:
        return getattr(self._core, name)

    return property(get, doc=f"``{name}`` (read from the core)")


for _name in STATE_NAMES[:8]:
    setattr(Controller, _name, _state(_name))
