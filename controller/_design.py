"""Loop shaping for the angle-tracking loops: phase margin with the loop's delays and filters.

Every angle observer of the controller closes a loop through discrete
filters and delays: the demodulation filters of the rotating-injection
PLLs, the envelope, hold and CIC interpolation of the square-wave
observer. Their gains are not picked; each is the largest gain whose
open loop ``L(e^{jwT})``, computed from the *actual* discrete filters and
the one-period delays of the code, keeps the phase margin
:data:`PM_TARGET_DEG`.

Why 45 degrees: it is the lower end of the usual 45-60 degree range. The
loops here are type 2 (PLL) and type 3 (Luenberger), so margin above that
costs bandwidth they need: their tracking error of an acceleration or a
load step grows as ``1 / w^2``. 45 degrees still keeps a well-damped
closed loop. The sensitivity peak stays below 1.7. The complementary
sensitivity peak, which is how much of the current-sensor noise reaches
the angle estimate, stays at about 1.4. At the tt-dq PLL's old 21 degrees
that peak was 2.9. One more period of transport delay on the bench's link takes
``w_c T`` off the margin (9 degrees at the square-wave crossover), so
the loop stays stable. The margin is measured at the first gain
crossover, on the unwrapped phase, whose low-frequency value is ``-90``
degrees per integrator of the loop.

Design happens once per estimator and runs on numpy (vectorised
frequency responses) and :func:`scipy.optimize.brentq`. The results are
cached, because tests build many estimators with the same settings.

The design record. A controller's design is a pure function of its
settings (:class:`controller.ControllerPars`): every search and
discretisation on its way (the steps marked :func:`designed`: the filters'
bilinear transforms, the PLL's and the speed loop's phase-margin searches,
the margins its gains report) is kept in a :class:`DesignRecord` of the
controller, keyed by the step and its plain arguments (numbers, strings,
tuples of them). An argument of another kind (the estimator's speed
response, the estimator itself) is left out of the key: within one
controller's design it is itself made from the settings, which the record
is tied to by their digest (:func:`settings_digest`). A controller built
with a record of the same digest takes each step's result from it and runs
no search (no scipy import: a node handed its design starts in a fraction of
the time); a step the record lacks is computed as without one. A record of
another digest is never used (:class:`controller.Controller`).
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import hashlib
import json
import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, fields, is_dataclass
from typing import Any, TypeVar

import numpy as np

#: Phase-margin target of every angle-tracking loop (deg); see the module docstring.
PM_TARGET_DEG = 45.0

LoopResponse = Callable[[np.ndarray], np.ndarray]


def freq_response(
    b: tuple[float, ...], a: tuple[float, ...], w: np.ndarray, T_s: float
) -> np.ndarray:
    """``H(e^{j w T_s})`` of the discrete filter ``b(z^-1) / a(z^-1)`` at angular frequencies ``w``
    (rad/s, may be negative; coefficients of ``z^-n``)."""
    zi = np.exp(-1j * np.asarray(w, float) * T_s)
    num = np.zeros_like(zi)
    den = np.zeros_like(zi)
    for n, c in enumerate(b):
        num = num + c * zi**n
    for n, c in enumerate(a):
        den = den + c * zi**n
    return num / den


def _unwrapped_phase(L: np.ndarray, n_int: int) -> np.ndarray:
    """Unwrapped phase (deg) of ``L`` on an ascending grid, anchored so that its first value is
    within 180 degrees of ``-90 n_int`` (the phase of ``n_int`` integrators at low frequency)."""
    ph = np.degrees(np.unwrap(np.angle(L)))
    shift = 360.0 * round((-90.0 * n_int - ph[0]) / 360.0)
    return ph + shift


def margins(
    loop: LoopResponse, w_lo: float, w_hi: float, n_int: int, n: int = 4000
) -> tuple[float, float]:
    """Phase margin (deg) and gain-crossover frequency (rad/s) of ``loop``.

    ``loop(w)`` is the open-loop frequency response (negative feedback) at
    angular frequencies ``w`` (rad/s); the crossover is the first ``|L| = 1``
    above ``w_lo`` (the loops here have integrators: ``|L| > 1`` at low
    frequency), refined by bisection; the margin is ``180 + arg L(w_c)`` on
    the unwrapped phase (``n_int`` integrators at low frequency). Returns
    ``(nan, nan)`` if ``|L|`` never falls to 1 below ``w_hi``.
    """
    from scipy.optimize import brentq

    w = np.geomspace(w_lo, w_hi, n)
    L = loop(w)
    mag = np.abs(L)
    below = np.nonzero(mag < 1.0)[0]
    if below.size == 0 or below[0] == 0:
        return math.nan, math.nan
    i = int(below[0])
    w_c = float(
        brentq(
            lambda x: math.log(float(np.abs(loop(np.array([x]))[0]))), w[i - 1], w[i], xtol=1e-10
        )
    )
    # phase at w_c on the grid's unwrapped branch (w_c lies between grid points i-1 and i)
    grid = np.concatenate([w[:i], [w_c]])
    ph = _unwrapped_phase(loop(grid), n_int)
    return 180.0 + float(ph[-1]), w_c


def solve_largest(
    metric: Callable[[float], float], target: float, lo: float, hi: float, rising: bool
) -> float:
    """The smallest parameter ``p`` in ``[lo, hi]`` where ``metric(p)`` reaches ``target``.

    ``metric`` starts on the good side of ``target`` at ``lo`` (below it if
    ``rising``, above it otherwise); the first crossing on a geometric grid
    of 60 points is refined by bisection. If ``metric`` never reaches
    ``target``, ``hi`` is returned (``lo`` if it is already past it at ``lo``).
    """
    from scipy.optimize import brentq

    def g(p: float) -> float:
        v = metric(p) - target
        return math.inf if math.isnan(v) else (v if rising else -v)

    grid = np.geomspace(lo, hi, 60)
    prev = float(grid[0])
    if g(prev) >= 0.0:
        return lo
    for p in grid[1:]:
        if g(float(p)) >= 0.0:
            return float(brentq(g, prev, float(p), xtol=1e-12 * hi, rtol=1e-10))
        prev = float(p)
    return hi


def largest_with_margin(
    loop_of: Callable[[float], LoopResponse],
    lo: float,
    hi: float,
    w_hi: float,
    n_int: int,
    pm_deg: float,
    w_c_max: float,
) -> tuple[float, float, float]:
    """The largest gain parameter ``p`` in ``[lo, hi]`` whose loop ``loop_of(p)`` keeps the
    phase margin at ``pm_deg`` or more and the gain crossover at or below ``w_c_max``.

    The margins are taken from ``1e-3 p`` to ``w_hi`` with ``n_int``
    integrators (:func:`margins`); each bound is solved by :func:`solve_largest`
    and the smaller parameter kept. Returns ``(p, pm, w_c)``: the parameter,
    its phase margin (deg) and crossover (rad/s).
    """

    def pm_of(x: float) -> float:
        return margins(loop_of(x), 1e-3 * x, w_hi, n_int)[0]

    def wc_of(x: float) -> float:
        return margins(loop_of(x), 1e-3 * x, w_hi, n_int)[1]

    p_pm = solve_largest(pm_of, pm_deg, lo, hi, rising=False)
    p_bw = solve_largest(wc_of, w_c_max, lo, hi, rising=True)
    p = min(p_pm, p_bw)
    pm, w_c = margins(loop_of(p), 1e-3 * p, w_hi, n_int)
    return p, pm, w_c


_F = TypeVar("_F", bound=Callable[..., Any])

#: The design book of the controller being built or asked its gains in this thread
#: (its results by key, :func:`designed`); None: no book, every step computes.
_BOOK: contextvars.ContextVar[dict[str, Any] | None] = contextvars.ContextVar(
    "controller_design_book", default=None
)


@dataclass(frozen=True, slots=True)
class DesignRecord:
    """A controller's design (module docstring): the results of its design steps, by key.

    ``settings`` is the digest of the settings it was made for
    (:func:`settings_digest`); ``results`` maps a step's key (its name and
    plain arguments) to its result, as JSON keeps it (tuples as lists).
    """

    settings: str
    results: Mapping[str, Any]


def settings_digest(pars: Any) -> str:
    """The digest of a controller's settings (a :class:`controller.ControllerPars`): equal for
    settings written to JSON and read back (numbers as floats, tuples as lists)."""
    text = json.dumps(_canonical(pars), sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def _canonical(v: Any) -> Any:
    if is_dataclass(v) and not isinstance(v, type):
        return {f.name: _canonical(getattr(v, f.name)) for f in fields(v)}
    if isinstance(v, Mapping):
        return {str(k): _canonical(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_canonical(x) for x in v]
    if isinstance(v, bool) or v is None or isinstance(v, str):
        return v
    if isinstance(v, (int, float, np.integer, np.floating)):
        return float.__repr__(float(v))
    return repr(v)


def _key_part(v: Any) -> Any:
    """``v`` in a step's key: a plain value as itself, any other kind left out (None)."""
    if isinstance(v, bool) or v is None or isinstance(v, str):
        return v
    if isinstance(v, (int, float, np.integer, np.floating)):
        return float.__repr__(float(v))
    if isinstance(v, (list, tuple)):
        return tuple(_key_part(x) for x in v)
    return None


def _as_tuples(v: Any) -> Any:
    """A result read back from JSON: its lists as the tuples the steps return."""
    return tuple(_as_tuples(x) for x in v) if isinstance(v, list) else v


@contextlib.contextmanager
def designing(book: dict[str, Any]) -> Iterator[None]:
    """Run the design steps inside on ``book`` (a controller's; module docstring)."""
    token = _BOOK.set(book)
    try:
        yield
    finally:
        _BOOK.reset(token)


def designed(fn: _F) -> _F:
    """Mark ``fn`` a design step: inside :func:`designing` its result is kept in (and taken
    from) the book under its name and plain arguments; the steps it calls are part of it."""
    name = f"{fn.__module__}.{fn.__qualname__}"

    @functools.wraps(fn)
    def step(*args: Any, **kwargs: Any) -> Any:
        book = _BOOK.get()
        if book is None:
            return fn(*args, **kwargs)
        key = json.dumps([name, _key_part(args), _key_part(sorted(kwargs.items()))])
        if key in book:
            return _as_tuples(book[key])
        token = _BOOK.set(None)
        try:
            out = fn(*args, **kwargs)
        finally:
            _BOOK.reset(token)
        book[key] = out
        return out

    return step  # type: ignore[return-value]
