"""Assertions on a run, for a user's tests (docs/TESTING.md).

::

    from bench.testing import assert_lock_kept, assert_settles, assert_tracks, assert_within

    run = bench.run("wen-5.1", estimator="tt-dq", duration=1.5)   # or hil.run(...)
    assert_lock_kept(run)
    assert_within(run, theta_err_abs_mean_deg=4.0, speed_err_max_rpm=20.0)
    assert_tracks(run, "w_hat_rpm", "w_m_rpm", within=10.0, after_s=0.5)
    assert_settles(run, "w_m_rpm", to=100.0, within=5.0, by_s=0.8)

Each failure is an :class:`AssertionError` of one line naming the metric or
signal, the bound, the measured value, the time and the run folder, e.g.
``theta_err_abs_mean_deg: |2.31| > 2.0 (scored t = 0.5 .. 1.5 s); run runs/x``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

    from bench._api import Run

__all__ = ["assert_lock_kept", "assert_settles", "assert_tracks", "assert_within"]


def _where(run: Run) -> str:
    return f"run {run.folder}" if run.folder is not None else f"run ({run.transport}, no folder)"


def _fail(text: str, run: Run) -> AssertionError:
    return AssertionError(f"{text}; {_where(run)}")


def _span(run: Run) -> str:
    t0 = run.meta.get("scored_from_s")
    t1 = run.metrics.get("sim_s")
    T_s = run.meta.get("T_s")
    if isinstance(t0, int | float) and isinstance(t1, int | float):
        if isinstance(T_s, int | float) and t1 >= T_s:
            t1 -= T_s  # sim_s is rows x T_s: the last row is one period before it
        return f"scored t = {t0:g} .. {t1:.6g} s"
    return "scored span unknown"


def assert_lock_kept(run: Run) -> None:
    """The estimator kept the rotor angle (``lock_lost`` false: never ``|dtheta|`` > 90 deg
    electrical for more than 50 ms after the scoring start; the plant did not trip)."""
    __tracebackhide__ = True  # pytest: the failure line, not this helper's body
    m = run.metrics
    if m.get("lock_lost"):
        at = m.get("lock_lost_at_s")
        when = f"t = {at:.4f} s" if isinstance(at, int | float) else "an unknown time"
        raise _fail(
            f"lock_lost: the estimator lost the rotor angle at {when} (bound: |dtheta| <= 90 deg "
            f"electrical; max |dtheta| {m.get('theta_err_abs_max_deg')} deg)",
            run,
        )
    fault = m.get("plant_fault", "none")
    if fault not in (None, "none"):
        k = m.get("plant_fault_step", -1)
        T_s = run.meta.get("T_s") or 0.0
        raise _fail(
            f"plant_fault: the plant tripped its {fault} protection at t = {k * T_s:.4f} s "
            "(bound: no trip)",
            run,
        )


def assert_within(run: Run, **bounds: float) -> None:
    """The magnitude of each named metric (``metrics.json``, docs/RUNS.md) is at most its bound.

    A metric the run does not have, or without a value, fails: a bound that
    cannot be checked is not met.
    """
    __tracebackhide__ = True  # pytest: the failure line, not this helper's body
    if not bounds:
        raise TypeError("assert_within: name at least one metric, e.g. theta_err_abs_mean_deg=4.0")
    for name, bound in bounds.items():
        if name not in run.metrics:
            raise _fail(f"{name}: not a metric of this run (bound {bound:g}; docs/RUNS.md)", run)
        v = run.metrics[name]
        if not isinstance(v, int | float) or isinstance(v, bool) or not math.isfinite(v):
            raise _fail(f"{name}: no value ({v!r}; bound {bound:g}, {_span(run)})", run)
        if abs(v) > bound:
            raise _fail(f"{name}: |{v:.6g}| > {bound:g} ({_span(run)})", run)


def _signal(run: Run, name: str) -> np.ndarray:
    __tracebackhide__ = True  # pytest: the failure line, not this helper's body
    sig = run.signals
    if name not in sig:
        raise _fail(f"{name}: not a signal of this run (signals.csv: {', '.join(sig)})", run)
    return sig[name]


def _reference(run: Run, reference: Any, n: int) -> tuple[np.ndarray, str]:
    __tracebackhide__ = True  # pytest: the failure line, not this helper's body
    import numpy as np

    if isinstance(reference, str):
        return _signal(run, reference), reference
    if isinstance(reference, int | float):
        return np.full(n, float(reference)), f"{reference:g}"
    arr = np.asarray(reference, dtype=float)
    if arr.shape != (n,):
        raise TypeError(
            f"reference: {n} values (one per row of signals.csv) expected, got {arr.shape}"
        )
    return arr, "the reference"


def _first_outside(
    run: Run, signal: str, ref: np.ndarray, ref_name: str, within: float, from_s: float, what: str
) -> None:
    __tracebackhide__ = True  # pytest: the failure line, not this helper's body
    import numpy as np

    x = _signal(run, signal)
    t = run.signals["t"]
    sel = t >= from_s
    if not sel.any():
        end = float(t[-1]) if len(t) else 0.0
        raise _fail(f"{signal}: no sample at t >= {from_s:g} s (the run ends at {end:g} s)", run)
    err = np.abs(x[sel] - ref[sel])
    bad = np.flatnonzero(~(err <= within))  # NaN counts as outside
    if bad.size:
        i = int(bad[0])
        raise _fail(
            f"{signal}: |{signal} - {ref_name}| = {err[i]:.6g} > {within:g} at t = "
            f"{t[sel][i]:.4f} s ({what}; {signal} = {x[sel][i]:.6g}, "
            f"{bad.size} of {err.size} samples outside, worst {np.nanmax(err):.6g})",
            run,
        )


def assert_tracks(
    run: Run,
    signal: str,
    reference: str | float | Sequence[float] | np.ndarray,
    within: float,
    after_s: float = 0.0,
) -> None:
    """``signal`` follows ``reference`` within ``within`` at every period from ``after_s`` (s) on.

    ``reference``: another signal's name (``"w_ref_rpm"``), a number, or one
    value per row of ``signals.csv``.  Units are the signals'
    (``signals.md``: angles electrical, speeds mechanical rpm).
    """
    __tracebackhide__ = True  # pytest: the failure line, not this helper's body
    ref, name = _reference(run, reference, len(_signal(run, signal)))
    _first_outside(run, signal, ref, name, within, after_s, f"tracking from t = {after_s:g} s")


def assert_settles(run: Run, signal: str, to: float, within: float, by_s: float) -> None:
    """``signal`` is within ``within`` of ``to`` by ``by_s`` (s) and stays there to the run's end."""
    __tracebackhide__ = True  # pytest: the failure line, not this helper's body
    import numpy as np

    n = len(_signal(run, signal))
    _first_outside(
        run, signal, np.full(n, float(to)), f"{to:g}", within, by_s, f"settled by {by_s:g} s"
    )
