"""The per-period kernels of the controller's blocks whose designs live in ``controller/``,
in Python: each a subclass of its design class adding the step the core runs in C.

Tolerance 0 (:data:`tests.oracle.TOLERANCE`): the core's block repeats these operations
in the same order.

The design class computes the coefficients (``__init__``) and holds the states the core
starts from (``reset``); its oracle adds the period's step. :func:`oracle` turns a built
design (a block, an estimator, everything it holds) into its oracle in place: the same
object, the same values, the step added, so that shared blocks stay shared (a hybrid's
tracker and its injection estimator hold one observer).
"""

from __future__ import annotations

import math
from typing import Any, TypeVar

from controller._cic import CicFilter, CicInterpolator
from controller._compensation import DeadTimeCompensator, OffsetCalibration, _clip01
from controller._controller import ReferenceModel
from controller._filters import Biquad2, FirstOrder, FirstOrder2
from controller._luenberger import LuenbergerObserver
from controller._pi import PIController

_TWO_PI = 2.0 * math.pi
_SQRT3_HALF = 0.5 * math.sqrt(3.0)

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
            x.__class__ = cls
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
