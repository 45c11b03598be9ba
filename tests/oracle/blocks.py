"""The per-period kernels of the controller's blocks whose designs live in ``controller/``,
in Python: each a subclass of its design class adding the step the core runs in C.

Tolerance 0 (:data:`tests.oracle.TOLERANCE`): the core's block repeats these operations
in the same order.

The design class computes the coefficients (``__init__``) and holds the states the core
starts from (``reset``); its oracle adds the period's step. :func:`oracle` turns a built
design (a block, an estimator, everything it holds) into its oracle in place: the same
object, the same values, the step added, so that shared blocks stay shared (a hybrid's
tracker and its injection estimator hold one observer).

The public blocks (``PIController``, ``PositionObserver``, ``FluxObserver``,
``PolarityTest``, ``Supervisor``, ``TransitionBand``) are bindings of the core: their
class subclasses a type of ``controller/_cctl.c`` whose members are the core struct's
fields and whose methods are the core's steps. Their oracle overrides those methods with
the Python below, which reads and writes the same members (storage only: every operation
is Python's), so one object can be turned into its oracle in place as the others are; the
supervisor's windows, which the struct holds as arrays, live in the oracle's
``__dict__`` (:meth:`OracleSupervisor.oracle_start`). The free functions (``svpwm``,
``limit_magnitude``, ``smooth_sign``, ``cross_saturation_offset``) are the Python of the
core's functions of those names.
"""

from __future__ import annotations

import math
from typing import Any, TypeVar

from controller._api import MODE_RUN, ControlOutput
from controller._cic import CicFilter, CicInterpolator
from controller._compensation import DeadTimeCompensator, OffsetCalibration
from controller._controller import ReferenceModel
from controller._filters import Biquad2, FirstOrder, FirstOrder2
from controller._flux_observer import FluxObserver
from controller._hybrid import TransitionBand
from controller._luenberger import LuenbergerObserver
from controller._pi import PIController
from controller._pll import PositionObserver
from controller._startup import PolarityTest
from controller._supervision import (
    MODE_CURRENT_SENSOR,
    MODE_DC_OVERVOLTAGE,
    MODE_DC_UNDERVOLTAGE,
    MODE_OPEN_PHASE,
    Supervisor,
)

_TWO_PI = 2.0 * math.pi
_SQRT3_HALF = 0.5 * math.sqrt(3.0)
_TWO_OVER_PI = 2.0 / math.pi


def _clip01(d: float) -> float:
    return 1.0 if d > 1.0 else (0.0 if d < 0.0 else d)


def smooth_sign(i_x: float, i_band: float, sine: bool) -> float:
    """:func:`controller._compensation.smooth_sign` (``cc_smooth_sign``): the mean of
    ``sign(i_x + i_h)`` over one period of a ripple ``i_h`` of amplitude ``i_band``.

    ``sine``: sinusoidal ripple, ``(2/pi) asin(i_x / i_band)``; otherwise
    triangular, ``i_x / i_band``; +-1 outside the band, hard sign if ``i_band`` is 0.
    """
    if i_x >= i_band:
        return 1.0 if i_x > 0.0 else 0.0
    if i_x <= -i_band:
        return -1.0 if i_x < 0.0 else 0.0
    r = i_x / i_band
    return _TWO_OVER_PI * math.asin(r) if sine else r


def cross_saturation_offset(k_dq: float, i_q: float, L_d: float, L_q: float) -> float:
    """:func:`controller._compensation.cross_saturation_offset`
    (``cc_cross_saturation_offset``): ``-1/2 atan(2 L_dq / (L_q - L_d))``, ``L_dq = k_dq i_q``.
    """
    return -0.5 * math.atan2(2.0 * k_dq * i_q, L_q - L_d)


#: design class -> its oracle (:func:`oracle`), filled by :func:`oracle_of`.
ORACLES: dict[type, type] = {}

_C = TypeVar("_C", bound=type)


def oracle_of(design: type) -> Any:
    """Class decorator: the decorated class is the oracle of ``design``."""

    def put(cls: _C) -> _C:
        ORACLES[design] = cls
        return cls

    return put


def _members(obj: Any) -> list[Any]:
    """The values ``obj`` holds (its slots along the classes, its ``__dict__``)."""
    out: list[Any] = []
    for cls in type(obj).__mro__:
        for name in getattr(cls, "__slots__", ()):
            if name not in ("__dict__", "__weakref__") and hasattr(obj, name):
                out.append(getattr(obj, name))
    out.extend(getattr(obj, "__dict__", {}).values())
    return out


def oracle(obj: Any) -> Any:
    """``obj`` (a built design: an estimator, a block) with every design object it holds
    turned into its oracle, in place (module docstring); returns ``obj``."""
    seen: set[int] = set()

    def walk(x: Any) -> None:
        if id(x) in seen or isinstance(x, (int, float, str, bool, type(None), type)):
            return
        seen.add(id(x))
        if isinstance(x, (list, tuple)):
            for v in x:
                walk(v)
            return
        if not type(x).__module__.startswith(("controller.", "tests.oracle.")):
            return
        cls = ORACLES.get(type(x))
        if cls is not None:
            object.__setattr__(x, "__class__", cls)  # a frozen dataclass's too
            start = getattr(x, "oracle_start", None)
            if start is not None:  # an oracle whose states the design object lacks
                start()
        for v in _members(x):
            walk(v)

    walk(obj)
    return obj


@oracle_of(FirstOrder2)
class OracleFirstOrder2(FirstOrder2):
    """:class:`controller._filters.FirstOrder2`'s step (``controller/core/cc_filters.c``)."""

    __slots__ = ()

    def update(self, x_1: float, x_2: float) -> tuple[float, float]:
        """Filter one sample of each signal and return the outputs."""
        y_1 = self.b0 * x_1 + self._s1
        y_2 = self.b0 * x_2 + self._s2
        self._s1 = self.b1 * x_1 - self.a1 * y_1
        self._s2 = self.b1 * x_2 - self.a1 * y_2
        return y_1, y_2


@oracle_of(FirstOrder)
class OracleFirstOrder(FirstOrder):
    """:class:`controller._filters.FirstOrder`'s step (``controller/core/cc_filters.c``)."""

    __slots__ = ()

    def update(self, x: float) -> float:
        """Filter one sample and return the output."""
        y = self.b0 * x + self._s
        self._s = self.b1 * x - self.a1 * y
        return y


@oracle_of(Biquad2)
class OracleBiquad2(Biquad2):
    """:class:`controller._filters.Biquad2`'s step, DF2T (``controller/core/cc_filters.c``)."""

    __slots__ = ()

    def update(self, x_1: float, x_2: float) -> tuple[float, float]:
        """Filter one sample of each signal and return the outputs."""
        y_1 = self.b0 * x_1 + self._p1
        y_2 = self.b0 * x_2 + self._q1
        self._p1 = self.b1 * x_1 - self.a1 * y_1 + self._p2
        self._q1 = self.b1 * x_2 - self.a1 * y_2 + self._q2
        self._p2 = self.b2 * x_1 - self.a2 * y_1
        self._q2 = self.b2 * x_2 - self.a2 * y_2
        return y_1, y_2


@oracle_of(CicFilter)
class OracleCicFilter(CicFilter):
    """:class:`controller._cic.CicFilter`'s step (``controller/core/cc_cic.c``)."""

    __slots__ = ()

    def step(self, x: float) -> float:
        """Filter one fast-rate sample ``x`` and return the output."""
        buf = self._buf
        i = self._i
        self._acc += x - buf[i]  # comb H_1 then integrator H_2
        buf[i] = x
        i += 1
        self._i = 0 if i == self.M else i
        self._n += 1
        if self._n >= 4096:  # re-anchor the integrator on the delay line
            self._n = 0
            self._acc = sum(buf)
        return self._acc * self._inv_M


@oracle_of(CicInterpolator)
class OracleCicInterpolator(CicInterpolator):
    """:class:`controller._cic.CicInterpolator`'s step and priming (``controller/core/cc_cic.c``)."""

    __slots__ = ()

    def __init__(self, M: int = 2, R: int = 2) -> None:
        super().__init__(M, R)
        oracle(self)

    def prime(self, x0: float) -> None:
        """Fill the delay line with ``x0`` so the output starts at ``x0`` (no start-up ramp)."""
        cic: Any = self._cic
        cic.reset()
        self._held = x0
        for _ in range(cic.M):
            cic.step(x0)

    def step(self, x: float | None) -> float:
        """One fast step; ``x`` is a new slow sample or None. Returns the interpolated value."""
        if x is not None:
            self._held = x
        cic: Any = self._cic
        y: float = cic.step(self._held)
        return y


@oracle_of(LuenbergerObserver)
class OracleLuenbergerObserver(LuenbergerObserver):
    """:class:`controller._luenberger.LuenbergerObserver`'s step
    (``controller/core/cc_luenberger.c``)."""

    __slots__ = ()

    def step(self, e: float, tau_e: float) -> None:
        """Advance one period with position error ``e`` (rad) and torque ``tau_e`` (N m)."""
        w = self.w_hat
        th = self.theta_hat + self.T_s * w + self._g3 * e
        if th >= _TWO_PI:
            th -= _TWO_PI
            if th >= _TWO_PI:
                th %= _TWO_PI
        elif th < 0.0:
            th += _TWO_PI
            if th < 0.0:
                th %= _TWO_PI
        self.theta_hat = th
        self.w_hat = w + self.T_s * self.x + self._g2 * e + self._gt * tau_e
        self.x += self._g1 * e


@oracle_of(DeadTimeCompensator)
class OracleDeadTimeCompensator(DeadTimeCompensator):
    """:class:`controller._compensation.DeadTimeCompensator`'s duties
    (``controller/core/cc_compensation.c``)."""

    __slots__ = ()

    def voltage(self, i_x: float, u_dc: float, d_x: float) -> float:
        """Expected mean pole-voltage error (V) of a leg with duty ``d_x`` for the current ``i_x``
        (A), sign smoothed; between the two hard-sign values of :func:`dead_time_voltage`."""
        s = smooth_sign(i_x, self.i_band, self.sine)
        on = d_x * self.v_ce + (1.0 - d_x) * self.v_f  # i > 0: upper transistor, lower diode
        off = d_x * self.v_f + (1.0 - d_x) * self.v_ce  # i < 0: upper diode, lower transistor
        return -s * self._k_dt * u_dc - 0.5 * (1.0 + s) * on + 0.5 * (1.0 - s) * off

    def duties(
        self,
        d_a: float,
        d_b: float,
        d_c: float,
        i_a: float,
        i_b: float,
        i_c: float,
        u_dc: float,
    ) -> tuple[float, float, float]:
        """Duties with the expected error of each leg added back, clipped to [0, 1]."""
        inv = 1.0 / u_dc
        d_a2 = d_a - self.voltage(i_a, u_dc, d_a) * inv
        d_b2 = d_b - self.voltage(i_b, u_dc, d_b) * inv
        d_c2 = d_c - self.voltage(i_c, u_dc, d_c) * inv
        return _clip01(d_a2), _clip01(d_b2), _clip01(d_c2)


@oracle_of(OffsetCalibration)
class OracleOffsetCalibration(OffsetCalibration):
    """:class:`controller._compensation.OffsetCalibration`'s sample
    (``controller/core/cc_compensation.c``)."""

    __slots__ = ()

    def add(self, i_a: float, i_b: float, i_c: float) -> None:
        """Take one standstill sample; the offsets are updated when the ``n``-th arrives."""
        self._s_a += i_a
        self._s_b += i_b
        self._s_c += i_c
        self.k += 1
        if self.k == self.n:
            inv = 1.0 / self.n
            self.o_a = self._s_a * inv
            self.o_b = self._s_b * inv
            self.o_c = self._s_c * inv


class OracleReferenceModel(ReferenceModel):
    """:class:`controller._controller.ReferenceModel`'s step (``controller/core/cc_reference.c``):
    the designed response ``alpha_s / (s + alpha_s)`` to the speed reference, forward Euler,
    and its slope times ``n_p``, limited to ``a_max``."""

    __slots__ = ("w",)

    def __init__(self, alpha_s: float, n_p: int, J: float, tau_max: float, T_s: float) -> None:
        super().__init__(alpha_s, n_p, J, tau_max, T_s)
        self.w = 0.0

    @classmethod
    def of(cls, design: ReferenceModel) -> OracleReferenceModel:
        """The oracle of the designed ``design`` (its values, a fresh state)."""
        m = cls.__new__(cls)
        m.alpha_s, m.n_p, m.a_max, m.T_s = design.alpha_s, design.n_p, design.a_max, design.T_s
        m.w = 0.0
        return m

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


@oracle_of(PIController)
class OraclePIController(PIController):
    """:class:`controller.PIController`'s step (``controller/core/cc_pi.c``)."""

    __slots__ = ()

    def output(self, r: float, y: float, u_ff: float = 0.0) -> float:
        """Unlimited controller output for reference ``r`` and measurement ``y``."""
        self._e = r - y
        self._u = self.k_t * r - self.k_p * y + self.u_i + u_ff
        return self._u

    def update(self, u_lim: float) -> None:
        """Advance the integrator with the realised (limited) output ``u_lim``."""
        self.u_i += self.T_s * self.k_i * (self._e + (u_lim - self._u) / self.k_t)

    def reset(self, u_i: float = 0.0) -> None:
        """Set the integral state."""
        self.u_i = float(u_i)
        self._e = 0.0
        self._u = 0.0


def limit_magnitude(x_1: float, x_2: float, x_max: float) -> tuple[float, float]:
    """:func:`controller._svpwm.limit_magnitude` (``cc_limit_magnitude``)."""
    m2 = x_1 * x_1 + x_2 * x_2
    if m2 > x_max * x_max:
        s = x_max / math.sqrt(m2)
        return x_1 * s, x_2 * s
    return x_1, x_2


def svpwm(u_alpha: float, u_beta: float, u_dc: float) -> tuple[float, float, float]:
    """:func:`controller.svpwm` (``controller/core/cc_svpwm.c``)."""
    u_a = u_alpha
    u_b = -0.5 * u_alpha + _SQRT3_HALF * u_beta
    u_c = -0.5 * u_alpha - _SQRT3_HALF * u_beta
    if u_a > u_b:
        hi = u_a
        lo = u_b
    else:
        hi = u_b
        lo = u_a
    if u_c > hi:
        hi = u_c
    elif u_c < lo:
        lo = u_c
    k = 1.0 / u_dc
    off = 0.5 - 0.5 * (hi + lo) * k
    d_a = off + u_a * k
    d_b = off + u_b * k
    d_c = off + u_c * k
    if (hi - lo) * k > 1.0 - 1e-12:  # at or beyond the linear range: clip
        return _clip01(d_a), _clip01(d_b), _clip01(d_c)
    return d_a, d_b, d_c


@oracle_of(PositionObserver)
class OraclePositionObserver(PositionObserver):
    """:class:`controller.PositionObserver`'s step (``controller/core/cc_pll.c``)."""

    __slots__ = ()

    def update(self, err: float, accel: float = 0.0) -> None:
        """Take the error of sample ``k``; advance ``theta_hat`` to ``(k+1) T_s``."""
        self.w_i += self.T_s * self.k_i * err
        if accel != 0.0:
            self.w_i += self.T_s * accel
        self.w_hat = self.k_p * err + self.w_i
        self.theta_hat = (self.theta_hat + self.T_s * self.w_hat) % _TWO_PI

    def reset(self, theta0: float, w0: float = 0.0) -> None:
        """Restart at angle ``theta0`` (rad) and speed ``w0`` (rad/s)."""
        self.theta_hat = theta0 % _TWO_PI
        self.w_hat = w0
        self.w_i = w0


@oracle_of(PolarityTest)
class OraclePolarityTest(PolarityTest):
    """:class:`controller.PolarityTest`'s start and step (``controller/core/cc_startup.c``)."""

    __slots__ = ()

    def start(self, u_dc: float, i_d0: float) -> None:
        """Begin a test at DC-link voltage ``u_dc`` (V) and d current ``i_d0`` (A)."""
        flux = self.L_d * self.i_pulse
        self.U = min(self.u_frac * u_dc / math.sqrt(3.0), flux / (2.0 * self.T_s))
        self.N = max(2, math.ceil(flux / (self.U * self.T_s) - 1e-9))
        self._n = 0
        self._i0 = i_d0
        self._i1 = i_d0
        self.d_i_pos = 0.0
        self.d_i_neg = 0.0
        self.done = False
        self.flip = False

    def step(self, i_d: float) -> float:
        """Take the d current of sample ``k`` (A); return ``u_d`` (V) for period ``k + 1``."""
        n = self._n
        N = self.N
        if n < 3 * N:
            d = i_d - self._i0
            if d > self.d_i_pos:
                self.d_i_pos = d
        else:
            if n == 3 * N:  # start of the second half: its own reference
                self._i1 = i_d
            d = self._i1 - i_d
            if d > self.d_i_neg:
                self.d_i_neg = d
        self._n = n + 1
        if n >= 6 * N:
            self.done = True
            self.flip = self.d_i_pos < self.d_i_neg
            return 0.0
        phase = n // N
        if phase in (0, 4):
            return self.U
        if phase in (1, 3):
            return -self.U
        return 0.0


@oracle_of(FluxObserver)
class OracleFluxObserver(FluxObserver):
    """:class:`controller.FluxObserver`'s steps (``controller/core/cc_flux_observer.c``)."""

    __slots__ = ()

    def reset(self, theta0: float, w0: float = 0.0) -> None:
        """Restart at angle ``theta0`` (rad) and speed ``w0`` (rad/s); the next sample
        sets the flux estimate to the current model at that angle."""
        self._th_next = theta0 % _TWO_PI
        self.theta_hat = self._th_next
        self.w_hat = w0
        self.eps = 0.0
        self.accel = 0.0
        self._init = True

    def set_state(self, psi_alpha: float, psi_beta: float, i_alpha: float, i_beta: float) -> None:
        """Set the flux estimate (Wb) and the current sample (A) of the last sample."""
        self.psi_alpha = psi_alpha
        self.psi_beta = psi_beta
        self._ia1 = i_alpha
        self._ib1 = i_beta
        self._init = False

    def _k1T(self, w: float) -> float:
        """``k_1 T_s`` at the speed ``w``: ``zeta_f max(|w|, w_min) T_s``, at most 0.5."""
        a = w if w >= 0.0 else -w
        if a < self.w_min:
            a = self.w_min
        g = self._zT * a
        return g if g < 0.5 else 0.5

    def _predict(self, i_a: float, i_b: float, u_a: float, u_b: float, c: float, s: float) -> None:
        """Voltage model over the period that ended at this sample (stationary frame)."""
        if self._init:
            # current model at the present angle: psi = e^{j theta} psi_m(i)
            i_d = c * i_a + s * i_b
            i_q = c * i_b - s * i_a
            p_d = self.psi_f + self.L_d * i_d
            p_q = self.L_q * i_q
            self.psi_alpha = c * p_d - s * p_q
            self.psi_beta = s * p_d + c * p_q
            self._init = False
        else:
            T = self.T_s
            r = self._rT2
            self.psi_alpha += T * u_a - r * (i_a + self._ia1)
            self.psi_beta += T * u_b - r * (i_b + self._ib1)
        self._ia1 = i_a
        self._ib1 = i_b

    def _flux_error(
        self, i_alpha: float, i_beta: float, c: float, s: float
    ) -> tuple[float, float, float, float, float]:
        """In the frame at ``(c, s)``: the flux error ``e`` (model minus estimate), the
        active flux ``psi_a`` (both d, q; Wb) and ``|psi_a|^2``."""
        i_d = c * i_alpha + s * i_beta
        i_q = c * i_beta - s * i_alpha
        pa = self.psi_alpha
        pb = self.psi_beta
        e_d = self.psi_f + self.L_d * i_d - (c * pa + s * pb)
        e_q = self.L_q * i_q - (c * pb - s * pa)
        a_d = self.psi_f + self._dL * i_d
        a_q = -self._dL * i_q
        return e_d, e_q, a_d, a_q, a_d * a_d + a_q * a_q

    def update(self, i_alpha: float, i_beta: float, u_alpha: float, u_beta: float) -> None:
        """Sensorless step: sample ``k`` (A) and the voltage of ``[(k-1) T_s, k T_s]`` (V)."""
        th = self._th_next
        c = math.cos(th)
        s = math.sin(th)
        self._predict(i_alpha, i_beta, u_alpha, u_beta, c, s)
        pa = self.psi_alpha
        pb = self.psi_beta
        e_d, e_q, a_d, a_q, den = self._flux_error(i_alpha, i_beta, c, s)
        if den > 0.0:
            inv = 1.0 / den
            x = (e_d * a_d + e_q * a_q) * inv  # Re(e / psi_a)
            eps = (e_d * a_q - e_q * a_d) * inv  # -Im(e / psi_a)
        else:  # pragma: no cover - psi_a = 0 needs i_d = psi_f / (L_q - L_d)
            x = eps = 0.0
        # k_1 e + k_2 conj(e) = 2 k_1 psi_a Re(e / psi_a), rotated to stationary
        g = 2.0 * self._k1T(self.w_hat) * x
        cd = g * a_d
        cq = g * a_q
        self.psi_alpha = pa + c * cd - s * cq
        self.psi_beta = pb + s * cd + c * cq
        w_i = self.w_hat + self._ki_T * eps
        self.w_hat = w_i
        self.eps = eps
        self.accel = self.k_i * eps
        self.theta_hat = th
        th += self.T_s * (w_i + self.k_p * eps)
        if th >= _TWO_PI or th < 0.0:
            th %= _TWO_PI
        self._th_next = th

    def update_slaved(
        self,
        i_alpha: float,
        i_beta: float,
        u_alpha: float,
        u_beta: float,
        theta: float,
        w: float,
    ) -> None:
        """Sensored step at a given angle ``theta`` (rad) and speed ``w`` (rad/s): the flux
        is corrected with ``k_1 e`` (``k_2 = 0``); the PLL state follows ``theta, w``."""
        c = math.cos(theta)
        s = math.sin(theta)
        self._predict(i_alpha, i_beta, u_alpha, u_beta, c, s)
        pa = self.psi_alpha
        pb = self.psi_beta
        e_d, e_q, a_d, a_q, den = self._flux_error(i_alpha, i_beta, c, s)
        self.eps = (e_d * a_q - e_q * a_d) / den if den > 0.0 else 0.0
        self.accel = 0.0
        g = self._k1T(w)
        self.psi_alpha = pa + g * (c * e_d - s * e_q)
        self.psi_beta = pb + g * (s * e_d + c * e_q)
        self.w_hat = w
        th = theta % _TWO_PI
        self.theta_hat = th
        th += self.T_s * w
        if th >= _TWO_PI or th < 0.0:
            th %= _TWO_PI
        self._th_next = th


@oracle_of(Supervisor)
class OracleSupervisor(Supervisor):
    """:class:`controller.Supervisor`'s check, release and windows
    (``controller/core/cc_supervision.c``). Its windows live in the instance's
    ``__dict__``: :func:`oracle` empties them (:meth:`oracle_start`), on a
    fresh supervisor as the core's ``cc_sup_init`` does."""

    def oracle_start(self) -> None:
        """Called by :func:`oracle` after the swap: the windows of a fresh supervisor."""
        self._reset_windows()

    def _reset_windows(self) -> None:
        self._n_rail = [0, 0]
        self._stuck_n = 0
        self._stuck_lo = [math.inf, math.inf]
        self._stuck_hi = [-math.inf, -math.inf]
        self._du_lo = [math.inf, math.inf]
        self._du_hi = [-math.inf, -math.inf]
        self._blk_n = 0
        self._blk_len = self.pars.n_open_min
        self._blk_scored = False
        self._ms = [0.0, 0.0, 0.0]
        self._s = [0.0, 0.0, 0.0]
        self._u_sum = 0.0
        self._u_n = 0

    def check(self, i_a: float, i_b: float, u_dc: float, out: ControlOutput) -> int:
        """The detection of this period (a mode of :data:`DETECTION_MODES`, or 0).

        ``i_a``, ``i_b`` and ``u_dc`` are the period's samples, ``out`` what
        the controller answered to them. The current checks run while it
        switches in ``MODE_RUN``; the DC-link check always.
        """
        p = self.pars
        self._u_sum += u_dc
        self._u_n += 1
        if self._u_n >= p.n_dc:
            u = self._u_sum / self._u_n
            self._u_sum = 0.0
            self._u_n = 0
            if u < p.u_uv:
                return MODE_DC_UNDERVOLTAGE
            if u > p.u_ov:
                return MODE_DC_OVERVOLTAGE
        if not (out.enable and out.mode == MODE_RUN):
            self._n_rail = [0, 0]
            self._stuck_n = 0
            self._blk_n = 0
            self._ms = [0.0, 0.0, 0.0]
            self._s = [0.0, 0.0, 0.0]
            return 0
        # out of range
        for j, i in enumerate((i_a, i_b)):
            self._n_rail[j] = self._n_rail[j] + 1 if abs(i) >= p.i_rail else 0
            if self._n_rail[j] >= p.n_range:
                return MODE_CURRENT_SENSOR
        # stuck: reading range against the commanded phase voltage's range
        mean = (out.d_a + out.d_b + out.d_c) / 3.0
        for j, (i, d) in enumerate(((i_a, out.d_a), (i_b, out.d_b))):
            u = (d - mean) * u_dc
            self._stuck_lo[j] = min(self._stuck_lo[j], i)
            self._stuck_hi[j] = max(self._stuck_hi[j], i)
            self._du_lo[j] = min(self._du_lo[j], u)
            self._du_hi[j] = max(self._du_hi[j], u)
        self._stuck_n += 1
        if self._stuck_n >= p.n_stuck:
            lo, hi = self._stuck_lo, self._stuck_hi
            held = [
                j
                for j in (0, 1)
                if hi[j] - lo[j] <= p.i_res
                and self._du_hi[j] - self._du_lo[j] >= p.du_stuck
                and hi[1 - j] - lo[1 - j] > p.i_res
            ]
            # held within a resolution step of zero: the phase carries nothing (an open
            # phase, or a sensor reading zero); held elsewhere: a stuck sensor
            hit = 0
            if held:
                j = held[0]
                zero = abs(0.5 * (hi[j] + lo[j])) <= p.i_res
                hit = MODE_OPEN_PHASE if zero else MODE_CURRENT_SENSOR
            self._stuck_n = 0
            self._stuck_lo = [math.inf, math.inf]
            self._stuck_hi = [-math.inf, -math.inf]
            self._du_lo = [math.inf, math.inf]
            self._du_hi = [-math.inf, -math.inf]
            if hit:
                return hit
        # open phase: mean squares about the block's mean over one electrical period of
        # the estimated speed
        if self._blk_n == 0:
            w = abs(out.w_hat) * p.T_s  # electrical angle per period
            # below one electrical period per n_open_max the block is not scored (0)
            n = 0 if w * p.n_open_max < 2.0 * math.pi else round(2.0 * math.pi / w)
            self._blk_len = max(p.n_open_min, n)
            self._blk_scored = n > 0
        i_c = -i_a - i_b
        ms, sm = self._ms, self._s
        ms[0] += i_a * i_a
        ms[1] += i_b * i_b
        ms[2] += i_c * i_c
        sm[0] += i_a
        sm[1] += i_b
        sm[2] += i_c
        self._blk_n += 1
        if self._blk_n >= self._blk_len:
            n = self._blk_n
            self._blk_n = 0
            ac = [ms[j] - sm[j] * sm[j] / n for j in range(3)]
            self._ms = [0.0, 0.0, 0.0]
            self._s = [0.0, 0.0, 0.0]
            if not self._blk_scored:
                return 0
            floor2 = p.i_min * p.i_min * n
            r2 = p.rho_open * p.rho_open
            for j in range(3):
                others = 0.5 * (ac[(j + 1) % 3] + ac[(j + 2) % 3])
                if others >= floor2 and ac[j] <= r2 * others:
                    return MODE_OPEN_PHASE
        return 0

    def release_ok(self, u_dc: float) -> bool:
        """Whether the latched detection may clear on a new enable (module docstring)."""
        p = self.pars
        if self.latched == MODE_DC_UNDERVOLTAGE:
            return u_dc >= p.u_uv + p.u_hyst
        if self.latched == MODE_DC_OVERVOLTAGE:
            return u_dc <= p.u_ov - p.u_hyst
        return False


@oracle_of(TransitionBand)
class OracleTransitionBand(TransitionBand):
    """:class:`controller.TransitionBand`'s play and weights (``controller/core/cc_hybrid.c``)."""

    __slots__ = ()

    def play(self, y: float, w: float) -> float:
        """Schedule speed after the play operator: ``y`` follows ``|w|`` down at once
        and up with a lag of ``h`` (rad/s)."""
        s = w if w >= 0.0 else -w
        if s < y:
            return s
        if s - self.h > y:
            return s - self.h
        return y

    def weights(self, y: float) -> tuple[float, float]:
        """``(lam, g)`` for the schedule speed ``y``: the observer's weight and the
        injection's amplitude factor, each in [0, 1], exactly 0 or 1 outside the ramps."""
        lam = (y - self.w_lo) / (self.w_mid - self.w_lo)
        g = (self.w_hi - y) / (self.w_hi - self.w_mid)
        return (
            0.0 if lam <= 0.0 else (1.0 if lam >= 1.0 else lam),
            0.0 if g <= 0.0 else (1.0 if g >= 1.0 else g),
        )
