"""Full speed range: HF injection at low speed handed over to the flux observer above a band.

``hybrid-tt-dq`` and ``hybrid-square-wave`` compose an injection estimator
(:mod:`controller._tt_dq` or :mod:`controller._square_wave`, unchanged) with
the reduced-order flux observer of :mod:`controller._flux_observer`.

Hand-over: a blend of the two estimates, each with its own tracker.
``theta_hat = theta_HF + lam wrap(theta_obs - theta_HF)``, ``w_hat = w_HF +
lam (w_obs - w_HF)``, with the observer's weight ``lam`` in [0, 1]. Why not
one tracker driven by a blend of the two error signals: the trackers were
designed for their own error signals (the tt-dq PLL around Wen's BPF and LPF,
the square-wave Luenberger observer around a 3.5-period latency and with a
torque feed-forward, the flux observer's PLL with no filter and no delay in
its loop); one tracker for a blended error would have to be designed for the
slowest of them and its loop gain would change across the band. Blending the
outputs keeps every loop at its design. Continuity: each estimate is the
output of an integrator, and between two samples the blend moves by at most
``|dlam| |wrap(theta_obs - theta_HF)|`` beyond the estimates' own motion.
The estimator that carries no weight is *slaved* to the output so it is
locked when its turn comes: below the band the observer runs in sensored
mode at the HF angle (its flux converges at the rate ``k_1``), above the
blend the HF tracker's angle and speed are set to the output every period
(the square-wave observer's load state to ``a - n_p tau / J``, with the
flux observer's acceleration estimate ``a``).

Schedule, on the estimated speed ``s = |w|`` (electrical, the trackers'
integral states, which carry no demodulation ripple), through a play
(backlash) operator of width ``h`` for hysteresis: ``y`` follows ``s`` when
``s`` falls and lags it by ``h`` when ``s`` rises. Then::

    lam = clip((y - w_lo) / (w_mid - w_lo))      observer weight
    g   = clip((w_hi - y) / (w_hi - w_mid))      injection amplitude factor

Rising, the observer takes over between ``w_lo + h`` and ``w_mid + h``; the
injection, no longer needed, fades out between ``w_mid + h`` and ``w_hi +
h``, and is exactly zero above (``g = 0``, :meth:`HybridEstimator.injection`
returns ``(0.0, 0.0)``); these are estimated speeds, and with one more play
for the estimate's error the band on the true speed is
``[w_lo - h, w_hi + 2 h]`` (:attr:`TransitionBand.edges`, the split the
bench's per-band metrics should use, :meth:`TransitionBand.band_of`). Falling, the injection returns between ``w_hi`` and
``w_mid`` (the HF estimator slaved meanwhile, so its filters settle with the
injection back on) and the HF estimator takes over between ``w_mid`` and
``w_lo``. Every HF period with weight is at full amplitude, so the HF loops
keep their designed gains. The fundamental current for the current loop is
``i + g (i_f,HF - i)``: the HF estimator's filtered current while it
injects, the raw sample once the injection is off.

Band from physics (:func:`design`), not from a scenario. Target: wherever
the observer carries weight its steady angle error stays within the
steady-speed budget ``theta_max`` (5 degrees electrical) for a stated
stator-voltage uncertainty ``du`` it cannot see: a resistance error of
``r_tol`` (20 %, copper over about +/-50 K) at the current limit, plus an
inverter voltage error ``u_err`` (0 on the bench's ideal inverter; the
residual after dead-time compensation on a real one). The observer's
flux-error gain is ``k_1 = zeta_f max(|w|, w_lo)`` with ``zeta_f = 0.2``
(damping of its flux-error poles, :mod:`controller._flux_observer`), so
from there the error is at most ``du sqrt(1 + 4 zeta_f^2) / (|w| psi_f)``
wherever the observer carries weight, and the lower edge is::

    w_lo = sqrt(1 + 4 zeta_f^2) du / (psi_f theta_max) = 1.077 du / (psi_f theta_max)

the speed where the back-EMF ``w psi_f`` is ``1.077/theta_max`` (12.3) times
the voltage uncertainty. ``w_mid = 1.5 w_lo`` and ``w_hi = 2 w_lo``: the
observer's bound is ``2/3`` of the budget when it carries the full weight
and half of it where the injection ends. On the presets with ``u_err = 0``:
wen2023 440, 660, 880 rpm (w_lo = 184 rad/s electrical), xue2022 56, 84,
112 rpm (23.4 rad/s).

Choosing ``u_err`` for an inverter with dead time and device drops. The
dead-time feed-forward (:mod:`controller._compensation`) removes the error
wherever it knows the sign of each phase current at the switching edges. It
cannot near zero current when the PWM ripple within a period is larger than
the fundamental current: the sign at the edges is then the ripple's, and
the whole error, ``(4/pi) (t_dead u_dc / T_s + v_drop)`` in the fundamental
of its six-step pattern, stays in the voltage the observer integrates,
which is what a drive running light at the band's speeds sees. The ripple
is of the order ``|u| T_s / (3 L)`` with ``|u| ~ w psi_f``. wen2023 at 10 kHz:
0.03 A at 440 rpm, below the 0.13 A its ramps need, so the sign is known and
``u_err = 0`` (measured on the drive profile: 4 degrees at most above the
band). xue2022 at 1 kHz: about 3 A at 300 rpm against 0.26 A, so the sign
is not known and ``u_err`` = (4/pi)(2 us 540 V 1 kHz + 1.5 V) = 3.3 V for
the drive profile's 2 us and 1.5 V. With ``u_err = 0`` there the observer,
which then serves down to 84 rpm, takes a relay-like voltage error from the
current's sign flipping with the ripple, and the stop from 1200 rpm without
load rings at 12 Hz with +-4 degrees and a 22 % speed dip at the hand-over
(measured); with 3.3 V the band moves to 299-598 rpm, where that error is
within the budget. ``wide-speed-xue`` states it.

The play ``h = 0.1 w_lo`` (18.4 rad/s on wen2023, 2.3 rad/s on xue2022): a
speed held in or near the band does not move the schedule while the ripple
of the trackers' integral speed states stays below it (measured at steady
speed: at most 0.8 rad/s peak to peak, tt-dq at 100 rpm). On a falling
ramp the play passes the ripple on (``y`` follows ``|w|`` down), which moves
``lam`` by ``ripple / (w_mid - w_lo)``, a fraction of a per cent. The
injection's fade region ``[w_mid, w_hi]`` must take longer than the
injection chain needs to settle when it returns (tt-dq: BPF envelope 3 ms
and PLL 8 ms; square-wave: observer 35 ms), so the drive must not
decelerate through it faster than ``0.5 w_lo / t_settle``: about 8400
rad/s^2 electrical on wen2023 and 335 rad/s^2 on xue2022 with ``u_err = 0``
(1790 rad/s^2 with ``wide-speed-xue``'s 3.3 V). The scenarios' ramps stay
below that (314 and 251 rad/s^2); a torque-limited stop (15000 rad/s^2)
does not.

Observer bandwidth: the PLL's steady error under a constant angular
acceleration ``a`` is ``a / alpha_o^2``; the largest the controller can
command is ``a_max = n_p tau_max / J`` (electrical, no load). Target: at most
``theta_acc`` (5 degrees, half the transient budget) there:
``alpha_o = sqrt(n_p tau_max / (J theta_acc))`` (about 410 rad/s on both
presets: their inertia-to-torque ratios are equal).

What the band does not cover: a flux-model error (``psi_f``, ``L_q``)
leaves an angle error that does not fall with speed (``-b_i`` in
:mod:`controller._flux_observer`): a 10 % ``L_q`` error at rated torque
leaves 5.8 degrees on wen2023 and 1.1 degrees on xue2022 at any speed. No
band can fix that.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any, ClassVar, Protocol

import numpy as np

from controller._api import option_field
from controller._built import _cctl
from controller._flux_observer import FluxObserver
from controller._luenberger import LuenbergerObserver
from controller._params import MotorModel
from controller._pll import PositionObserver
from controller._rotating import RotatingInjectionPars
from controller._square_wave import SquareWaveOptions

_TWO_PI = 2.0 * math.pi

#: Steady-speed angle budget of the observer where it carries weight (rad).
THETA_MAX = math.radians(5.0)
#: Relative stator-resistance uncertainty (-), copper over about +/-50 K.
R_TOL = 0.2
#: Angle error allowed at the controller's largest acceleration (rad).
THETA_ACC = math.radians(5.0)
#: Band shape, in units of w_lo: end of the blend, end of the injection, play.
MID_RATIO = 1.5
HI_RATIO = 2.0
PLAY_RATIO = 0.1
#: Damping of the observer's flux-error poles (Hinkkanen et al., motulator: 0.2).
ZETA_F = 0.2

BELOW = 0
INSIDE = 1
ABOVE = 2


@dataclass(frozen=True, slots=True)
class TransitionBand:
    """Speeds of the hand-over (rad/s, electrical, on ``|w|``).

    Parameters
    ----------
    w_lo : float
        The observer's weight starts above this (rising: above ``w_lo + h``).
    w_mid : float
        The observer carries the full weight and the injection starts to fade.
    w_hi : float
        The injection is zero above ``w_hi`` of the schedule speed, i.e. above
        ``w_hi + h`` of the estimated speed whatever the history.
    h : float
        Play of the hysteresis.
    """

    w_lo: float
    w_mid: float
    w_hi: float
    h: float

    def __post_init__(self) -> None:
        if not (0.0 < self.w_lo < self.w_mid < self.w_hi and self.h >= 0.0):
            raise ValueError(f"need 0 < w_lo < w_mid < w_hi and h >= 0; got {self}")

    @property
    def edges(self) -> tuple[float, float]:
        """``(w_lo - h, w_hi + 2 h)`` on the *true* speed: below, the injection estimator
        alone; above, the observer alone and no injection.

        The schedule runs on the estimated speed: the injection is exactly zero once
        that is above ``w_hi + h`` and the observer has no weight while it is below
        ``w_lo``. One more play ``h`` covers the estimate's error against the truth
        (its ripple, below 1 rad/s at steady speed, and its lag on a ramp, 1.6 rad/s
        on the ``wide-speed`` ramps), so the edges hold for the true speed."""
        return self.w_lo - self.h, self.w_hi + 2.0 * self.h

    def play(self, y: float, w: float) -> float:
        """Schedule speed after the play operator: ``y`` follows ``|w|`` down at once
        and up with a lag of ``h`` (rad/s) (``cc_band_play``, ``controller/core/cc_hybrid.c``)."""
        return _cctl.band_play(self.w_lo, self.w_mid, self.w_hi, self.h, y, w)

    def weights(self, y: float) -> tuple[float, float]:
        """``(lam, g)`` for the schedule speed ``y``: the observer's weight and the
        injection's amplitude factor, each in [0, 1], exactly 0 or 1 outside the ramps:
        ``lam = (y - w_lo) / (w_mid - w_lo)`` and ``g = (w_hi - y) / (w_hi - w_mid)``,
        clipped (``cc_band_weights``)."""
        return _cctl.band_weights(self.w_lo, self.w_mid, self.w_hi, self.h, y)

    def band_of(self, w_e: float) -> int:
        """:data:`BELOW`, :data:`INSIDE` or :data:`ABOVE` the band (:attr:`edges`) for
        the true speed ``w_e`` (rad/s, electrical): the per-band split of metrics."""
        s = abs(w_e)
        lo, hi = self.edges
        if s < lo:
            return BELOW
        if s > hi:
            return ABOVE
        return INSIDE


@dataclass(frozen=True, slots=True)
class HybridDesign:
    """Band and observer gains from :func:`design`.

    Parameters
    ----------
    band : TransitionBand
        The hand-over speeds.
    zeta_f : float
        Damping of the observer's flux-error poles (-).
    alpha_o : float
        Bandwidth of the observer's PLL (rad/s).
    du : float
        Stator-voltage uncertainty the band was derived for (V).
    """

    band: TransitionBand
    zeta_f: float
    alpha_o: float
    du: float


def design(
    motor: MotorModel,
    theta_max: float = THETA_MAX,
    r_tol: float = R_TOL,
    u_err: float = 0.0,
    theta_acc: float = THETA_ACC,
) -> HybridDesign:
    """Band, ``zeta_f`` and ``alpha_o`` from the targets in the module docstring.

    Parameters
    ----------
    motor : MotorModel
        The controller's motor model.
    theta_max, r_tol, u_err, theta_acc : float
        The targets, as :class:`HybridOptions` states them.
    """
    if not (theta_max > 0.0 and theta_acc > 0.0 and r_tol >= 0.0 and u_err >= 0.0):
        raise ValueError("need theta_max, theta_acc > 0 and r_tol, u_err >= 0")
    du = r_tol * motor.R_s * motor.i_max + u_err
    if not du > 0.0:
        raise ValueError("the voltage uncertainty r_tol R_s i_max + u_err must be > 0")
    w_lo = math.sqrt(1.0 + 4.0 * ZETA_F * ZETA_F) * du / (motor.psi_f * theta_max)
    band = TransitionBand(w_lo, MID_RATIO * w_lo, HI_RATIO * w_lo, PLAY_RATIO * w_lo)
    alpha_o = math.sqrt(motor.n_p * motor.tau_max / (motor.J * theta_acc))
    return HybridDesign(band, ZETA_F, alpha_o, du)


class _Tracker(Protocol):
    """Access to an injection estimator's own tracker, for slaving it."""

    @property
    def w_smooth(self) -> float:
        """The tracker's integral speed state (rad/s), free of the demodulation ripple."""
        ...

    def sync(self, theta: float, w: float, accel: float, torque: float) -> None:
        """Make the estimate of the sample just processed ``theta`` at speed ``w``
        (rad/s) and acceleration ``accel`` (rad/s^2), with the torque ``torque`` (N m)."""
        ...


class _PllTracker:
    """Slaving of the rotating-injection estimators' PLL (its state is one period ahead)."""

    __slots__ = ("T_s", "pll")

    def __init__(self, pll: PositionObserver, T_s: float) -> None:
        self.pll = pll
        self.T_s = T_s

    @property
    def w_smooth(self) -> float:
        return self.pll.w_i

    def sync(self, theta: float, w: float, accel: float, torque: float) -> None:
        self.pll.reset(theta + self.T_s * w, w)


class _LuenbergerTracker:
    """Slaving of the square-wave estimator's observer (its state is at the sample).

    Its integral state ``x`` (rad/s^2) is what the model ``dw/dt = n_p tau / J + x``
    lacks, ``accel - n_p tau / J``: set so, the observer is released without an
    acceleration error (a deceleration of 250 rad/s^2 through the band would
    otherwise be a step of that size into its loop)."""

    __slots__ = ("_k_x", "obs")

    def __init__(self, obs: LuenbergerObserver) -> None:
        self.obs = obs
        self._k_x = -obs.n_p / obs.J

    @property
    def w_smooth(self) -> float:
        return self.obs.w_hat

    def sync(self, theta: float, w: float, accel: float, torque: float) -> None:
        self.obs.reset(theta, w, accel + self._k_x * torque)


class _MechanicalTracker(_LuenbergerTracker):
    """Slaving of the rotating-injection estimators' mechanical observer: the square-wave
    observer's load state, with its angle one period ahead as the PLL's."""

    __slots__ = ("T_s",)

    def __init__(self, obs: LuenbergerObserver, T_s: float) -> None:
        super().__init__(obs)
        self.T_s = T_s

    def sync(self, theta: float, w: float, accel: float, torque: float) -> None:
        self.obs.reset(theta + self.T_s * w, w, accel + self._k_x * torque)


class HybridEstimator:
    """Injection estimator below the band, flux observer above, blended in between.

    The design (the band, the flux observer, the trackers that slave the
    injection estimator); the period runs in the controller's core
    (``controller/core/cc_hybrid.c``) with a shipped injection estimator, tt-dq
    or square-wave. Its readable Python is the tests' oracle
    (``tests/oracle/estimators.py``, tolerance 0).

    Parameters
    ----------
    hf : TTDQEstimator or SquareWaveEstimator
        The injection estimator (built by this module's :func:`create`).
    tracker : _Tracker
        Access to ``hf``'s tracker.
    observer : FluxObserver
        The model-based observer.
    band : TransitionBand
        Hand-over speeds.

    Attributes
    ----------
    weight : float
        The observer's weight ``lam`` for the next sample.
    gain : float
        Injection amplitude factor ``g`` for the next period.
    y : float
        Schedule speed after the play (rad/s).
    saliency_offset : float
        Angle (rad) by which the injection estimator's saliency axis leads the
        rotor's, set by the controller before each period's ``update`` when it
        corrects cross-saturation (:func:`controller._compensation.cross_saturation_offset`).
        It is a property of the saliency the injection sees, not of the flux
        the observer models, so it is subtracted from the injection estimate
        alone, before the blend: the controller applying it to the blended
        angle would turn it into an error of that size above the band (5
        degrees at rated current on the drive profile). The observer, slaved,
        follows the corrected angle, and the injection tracker, slaved, is set
        to the output plus the offset, where it will lock.
    """

    #: The period predicts the injection's HF current for the dead-time feed-forward
    #: (its injection estimator's, times the fade; zero for one that predicts none).
    predicts_hf: ClassVar[bool] = True

    def __init__(
        self, hf: Any, tracker: _Tracker, observer: FluxObserver, band: TransitionBand
    ) -> None:
        self.hf = hf
        #: The injection family of its injection estimator (``controller._registry``).
        self.injection_family: str = getattr(hf, "injection_family", "none")
        self.tracker = tracker
        self.observer = observer
        self.band = band
        self.theta_hat = 0.0
        self.w_hat = 0.0
        self.err = 0.0
        self.i_alpha_f = 0.0
        self.i_beta_f = 0.0
        self.weight = 0.0
        self.gain = 1.0
        self.y = 0.0
        self.saliency_offset = 0.0
        # The controller designs its speed loop with the estimator's speed
        # response: below the band, the slowest regime, the hybrid is its
        # injection estimator, so that estimator's response is the design case.
        self.speed_response: Callable[[np.ndarray], np.ndarray] | None = getattr(
            hf, "speed_response", None
        )

    # The injection's amplitudes and period, which the controller's dead-time sign
    # model reads from its estimator (0.0 where the injection has none).
    @property
    def I_p(self) -> float:
        return float(getattr(self.hf, "I_p", 0.0))

    @property
    def wT(self) -> float:
        return float(getattr(self.hf, "wT", 0.0))

    @property
    def U_h(self) -> float:
        return float(getattr(self.hf, "U_h", 0.0))

    def reset(self, theta0: float) -> None:
        """Restart both estimators at ``theta0`` (rad), standstill, injection on."""
        self.hf.reset(theta0)
        self.observer.reset(theta0)
        self.theta_hat = self.hf.theta_hat
        self.w_hat = 0.0
        self.err = 0.0
        self.weight = 0.0
        self.gain = 1.0
        self.y = 0.0

    def gains(self) -> dict[str, float]:
        """The injection estimator's gains, the band (rad/s electrical) and the observer's."""
        inner: dict[str, float] = self.hf.gains() if hasattr(self.hf, "gains") else {}
        obs = self.observer
        return {
            **inner,
            "band.w_lo": self.band.w_lo,
            "band.w_mid": self.band.w_mid,
            "band.w_hi": self.band.w_hi,
            "band.h": self.band.h,
            "observer.alpha_o": obs.alpha_o,
            "observer.zeta_f": obs.zeta_f,
            "observer.w_min": obs.w_min,
            "observer.k_p": obs.k_p,
            "observer.k_i": obs.k_i,
        }


@dataclass(frozen=True)
class HybridOptions:
    """The hybrids' own options, beside their injection estimator's (:func:`design`'s
    targets and two overrides of the observer's designed gains).

    Parameters
    ----------
    theta_max : float
        Steady angle budget of the observer where it carries weight (rad).
    r_tol : float
        Relative uncertainty of ``R_s`` (-), taken at ``motor.i_max``.
    u_err : float
        Inverter voltage uncertainty (V).
    theta_acc : float
        PLL angle error allowed at the largest acceleration (rad).
    alpha_o : float or None
        Bandwidth of the hybrids' flux observer's speed tracker (rad/s); default:
        designed from theta_acc.
    zeta_f : float or None
        Damping of the flux observer's correction (-); default: the design's.
    """

    theta_max: float = option_field(THETA_MAX, positive=True)
    r_tol: float = option_field(R_TOL, positive=True)
    u_err: float = option_field(0.0, minimum=0.0)
    theta_acc: float = option_field(THETA_ACC, positive=True)
    alpha_o: float | None = option_field(None, positive=True)
    zeta_f: float | None = option_field(None, positive=True)


@dataclass(frozen=True)
class HybridTtDqOptions(HybridOptions, RotatingInjectionPars):
    """The options of ``hybrid-tt-dq``: tt-dq's, then the hybrids' own."""


@dataclass(frozen=True)
class HybridSquareWaveOptions(HybridOptions, SquareWaveOptions):
    """The options of ``hybrid-square-wave``: square-wave's, then the hybrids' own."""


def create_tt_dq(motor: MotorModel, T_s: float, **options: Any) -> HybridEstimator:
    """Build ``hybrid-tt-dq``: tt-dq below the band, its BPF tracking the sequences.

    ``options``: the fields of :class:`controller.RotatingInjectionPars` and of
    :class:`HybridOptions`. Unknown keys raise ``TypeError``.
    """
    from controller._tt_dq import TTDQEstimator

    own = _own(options)
    # the BPF follows the sequences to the band's speeds (RotatingInjectionPars)
    tt = TTDQEstimator(motor, T_s, RotatingInjectionPars(**{"bpf_tracking": True, **options}))
    pll = tt.pll
    tracker = (
        _PllTracker(pll, T_s) if isinstance(pll, PositionObserver) else _MechanicalTracker(pll, T_s)
    )
    return _compose(motor, T_s, tt, tracker, own)


def create_square_wave(motor: MotorModel, T_s: float, **options: Any) -> HybridEstimator:
    """Build ``hybrid-square-wave``: square-wave (with CIC) below the band.

    ``options``: the fields of :class:`controller._square_wave.SquareWaveOptions` and of
    :class:`HybridOptions`. Unknown keys raise ``TypeError``.
    """
    from controller._square_wave import SquareWaveEstimator

    own = _own(options)
    sw = SquareWaveEstimator(motor, T_s, cic=True, **options)
    return _compose(motor, T_s, sw, _LuenbergerTracker(sw.observer), own)


def _own(options: dict[str, Any]) -> dict[str, Any]:
    """The :class:`HybridOptions` keys taken out of ``options``."""
    return {f.name: options.pop(f.name) for f in fields(HybridOptions) if f.name in options}


def _compose(
    motor: MotorModel, T_s: float, est: Any, tracker: _Tracker, own: dict[str, Any]
) -> HybridEstimator:
    """The hybrid of the injection estimator ``est`` and the flux observer :func:`design` gives."""
    alpha_o = own.pop("alpha_o", None)
    zeta_f = own.pop("zeta_f", None)
    d = design(motor, **own)
    observer = FluxObserver(
        motor,
        T_s,
        d.alpha_o if alpha_o is None else float(alpha_o),
        d.zeta_f if zeta_f is None else float(zeta_f),
        d.band.w_lo,
    )
    return HybridEstimator(est, tracker, observer, d.band)
