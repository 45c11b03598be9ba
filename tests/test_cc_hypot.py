"""The core's ``cc_hypot`` (controller/core/cc_math.h) rounds as CPython's
``math.hypot``, bit for bit.

The Python engine's ``normalise = "measured"`` divides by ``math.hypot`` of the
demodulated pair; the compiled core divides by ``cc_hypot``, so the two engines agree
only if the two round alike on every pair the demodulators can meet.  CPython's
``math.hypot`` is not C's ``hypot``: it scales by a power of two, sums the exact squares
with their errors and corrects the square root once (its ``vector_norm``), and libm's
``hypot`` rounds differently on about one pair in three thousand.

One algorithm in every build (the extension, the native node library, the firmware):
CPython 3.12's and later's.  3.11 parts from it only where ``max(|x|, |y|) < 2**-1024``,
so ``math.hypot`` is the oracle over the normal range on every interpreter, and over the
range below only on 3.12+; there, on every interpreter, the oracle is 3.12's definition,
``DBL_MIN * math.hypot(x / DBL_MIN, y / DBL_MIN)`` (the inner call in the normal range).
Where the versions part the norm is below ``DBL_MIN`` on either, under every
demodulator's amplitude floor (a tenth of its model HF amplitude), so ``err`` is the
same bits on a 3.11 Python engine too.  10**6 pairs: every exponent of either argument,
pairs of close magnitude (where the correction decides the last bit), pairs below
``2**-1024``, and the edge cases (zeros of either sign, inf beating nan, the largest and
least doubles).
"""

from __future__ import annotations

import functools
import math
import sys
from collections.abc import Callable
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import controller_pars
from controller import compiled_controller_missing
from controller._registry import SPECS

N = 1_000_000
#: Below it (``max(|x|, |y|)``) CPython 3.11 and 3.12+ part: the scale ``2**-e`` overflows.
TINY = 2.0**-1024
DBL_MIN = sys.float_info.min
#: The interpreter's math.hypot is the core's algorithm below TINY too.
SAME_BELOW_TINY = sys.version_info >= (3, 12)


@pytest.fixture(scope="module")
def cc_hypot() -> Callable[[float, float], float]:
    why = compiled_controller_missing()
    if why is not None:
        pytest.skip(why)
    from controller import _cctl

    return _cctl.hypot


@functools.cache
def _pairs() -> tuple[np.ndarray, np.ndarray]:
    """N pairs: a third over all exponents, a third of ratio 0.01..100 (inf where the
    product overflows), a third below 2**-1024 (the branch where 3.11 and 3.12 part).
    Made once (the tests split them by range)."""
    rng = np.random.default_rng(20261126)
    m = N // 3

    def wide(k: int) -> np.ndarray:
        return rng.uniform(-1.0, 1.0, k) * np.ldexp(1.0, rng.integers(-1074, 1024, k))

    x1, y1 = wide(m), wide(m)
    x2 = wide(m)
    with np.errstate(over="ignore"):
        y2 = x2 * rng.uniform(0.01, 100.0, m) * rng.choice([-1.0, 1.0], m)
    k = N - 2 * m
    x3 = rng.uniform(-1.0, 1.0, k) * 2.0**-1024
    y3 = rng.uniform(-1.0, 1.0, k) * 2.0**-1024
    return np.concatenate([x1, x2, x3]), np.concatenate([y1, y2, y3])


EDGES = [
    0.0,
    -0.0,
    5e-324,
    -5e-324,
    2.0**-1074 * 3,
    sys.float_info.min,
    sys.float_info.min * (1 - 2.0**-52),
    2.0**-1024,
    2.0**-1023,
    1.0,
    -1.0,
    3.0,
    4.0,
    1.0 + 2.0**-52,
    1e-300,
    1e300,
    sys.float_info.max,
    -sys.float_info.max,
    math.inf,
    -math.inf,
    math.nan,
]


def _bits(v: list[float]) -> np.ndarray:
    return np.asarray(v, dtype=np.float64).view(np.uint64)


def _scaled_up(x: float, y: float) -> float:
    """CPython 3.12+'s ``hypot`` below ``2**-1024``: both scaled up by ``DBL_MIN``
    (exact) into the normal range, where every interpreter's algorithm is the same."""
    return DBL_MIN * math.hypot(x / DBL_MIN, y / DBL_MIN)


def _oracle(x: float, y: float) -> float:
    """The core's algorithm on this interpreter: math.hypot, but 3.12's below TINY."""
    if SAME_BELOW_TINY or not max(abs(x), abs(y)) < TINY or math.isnan(x) or math.isnan(y):
        return math.hypot(x, y)
    return _scaled_up(x, y)


def _differ(got: list[float], want: list[float], xs: list[float], ys: list[float]) -> str:
    bad = np.flatnonzero(_bits(got) != _bits(want))
    if bad.size == 0:
        return ""
    return f"{bad.size} pairs differ, the first ({xs[bad[0]].hex()}, {ys[bad[0]].hex()})"


def test_cc_hypot_is_math_hypot_bit_for_bit_over_the_normal_range(
    cc_hypot: Callable[[float, float], float],
) -> None:
    """The pairs with ``max(|x|, |y|) >= 2**-1024`` (every exponent, close magnitudes):
    the same bits as this interpreter's math.hypot, whichever version it is."""
    x, y = _pairs()
    normal = np.maximum(abs(x), abs(y)) >= TINY
    xs, ys = x[normal].tolist(), y[normal].tolist()
    assert len(xs) > N // 2
    want = list(map(math.hypot, xs, ys))
    assert not (why := _differ(list(map(cc_hypot, xs, ys)), want, xs, ys)), why
    # the pairs reach where the algorithms part: C's hypot differs from math.hypot on
    # some of them (so this comparison would catch it)
    with np.errstate(over="ignore"):
        c_hypot = np.hypot(x[normal], y[normal]).tolist()
    assert np.count_nonzero(_bits(c_hypot) != _bits(want)) > 100


def test_cc_hypot_below_2_1024_is_cpython_312s(cc_hypot: Callable[[float, float], float]) -> None:
    """The pairs with ``max(|x|, |y|) < 2**-1024``: 3.12's definition (scaled up by
    DBL_MIN) on every interpreter, math.hypot itself on 3.12+; on 3.11 its own algorithm
    gives other bits there (the choice is real), and every result on either is below
    DBL_MIN, under any demodulator's floor (the next test)."""
    x, y = _pairs()
    tiny = np.maximum(abs(x), abs(y)) < TINY
    xs, ys = x[tiny].tolist(), y[tiny].tolist()
    assert len(xs) > N // 4
    got = list(map(cc_hypot, xs, ys))
    assert not (why := _differ(got, list(map(_scaled_up, xs, ys)), xs, ys)), why
    here = list(map(math.hypot, xs, ys))
    if SAME_BELOW_TINY:
        assert not (why := _differ(got, here, xs, ys)), why
    else:
        assert np.count_nonzero(_bits(got) != _bits(here)) > 100
    assert max(got) < DBL_MIN and max(here) < DBL_MIN


def test_every_measured_normalisation_is_floored_far_above_where_the_versions_part() -> None:
    """Each estimator with the option ``normalise`` (the registry's), built with
    ``"measured"`` in every shipped scenario that lists it: its floor (a tenth of the
    model amplitude, A or A^2) is above 1e-6, 10**301 times the DBL_MIN under which the
    two CPython versions' norms lie, so ``max(hypot, floor)`` is the floor on either."""
    seen: dict[tuple[str, str], str] = {}
    for path in sorted((Path(__file__).parents[1] / "bench" / "scenarios").glob("*.toml")):
        scn = load_scenario(path.stem)
        for name in dict.fromkeys((scn.estimator, *scn.estimators)):
            spec = SPECS[name]
            if spec.options is None or "normalise" not in {f.name for f in fields(spec.options)}:
                continue
            pars = controller_pars(scn, name)
            measured = {**pars.estimator_options, "normalise": "measured"}
            key = (name, repr((pars.motor, pars.T_s, sorted(measured.items()))))
            if key in seen:  # the same estimator built alike in another scenario
                continue
            est: Any = spec.factory(pars.motor, pars.T_s, **measured)
            floor = (est.hf if hasattr(est, "hf") else est)._floor
            assert 1e-6 < floor < 1.0, (path.stem, name, floor)
            seen[key] = path.stem
    assert {"tt-dq", "sfhf", "hybrid-tt-dq"} <= {name for name, _ in seen}


def test_cc_hypot_edge_cases(cc_hypot: Callable[[float, float], float]) -> None:
    """Every pair of the edge values (either sign of zero, the least subnormal, the
    largest double, inf and nan, inf winning over nan): the same bits as the oracle
    (math.hypot, 3.12's below ``2**-1024``)."""
    h = cc_hypot
    for a in EDGES:
        for b in EDGES:
            got, want = h(a, b), _oracle(a, b)
            assert _bits([got]) == _bits([want]), (a, b, got, want)
    assert h(math.nan, math.inf) == math.inf
    assert math.isnan(h(math.nan, 1.0))
    assert h(3.0, 4.0) == 5.0
