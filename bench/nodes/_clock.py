"""Real-time stepping on absolute deadlines.

Deadline ``n`` is ``t_0 + n T_s`` with ``t_0`` taken from
``time.perf_counter()`` at :meth:`RealTimeClock.start`; sleeps are never
accumulated, so the schedule does not drift. Waiting is hybrid: sleep until
``spin`` seconds before the deadline (the OS wakes threads late by tens to
hundreds of microseconds), then busy-wait on ``perf_counter``.

Late periods and host stalls (the policy).  A caller that finds its deadline
passed by at most ``stall_s`` catches up: the schedule stays absolute and the
next periods run back to back (each counted as an overrun, late).  A caller
late by more than ``stall_s`` met a stall of the host (a descheduled virtual
machine, a page-in): catching up would run a burst of hundreds of
back-to-back periods, each late, for as long again as the stall lasted, and
send the controller under test that burst.  The clock resynchronises instead:
the deadlines that passed during the stall are skipped (no period is
computed for them; they are counted as ``skipped``, not hidden), the
schedule moves forward by whole periods, and the stall is counted apart
(number, total and longest), so that the late-period figure measures the
bench and the stall figures the host.  The default ``stall_s`` is
:data:`STALL_MIN_S` or :data:`STALL_PERIODS` periods, whichever is longer:
above the worst wake-up latency of a general-purpose kernel under load
(``bench rtcheck`` measures it; docs/REALTIME.md), so that ordinary
lateness is caught up and only a stall resynchronises.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

#: A wake-up later than this (s) is a stall of the host, at least (see the module doc).
STALL_MIN_S = 2e-3
#: ... and never less than this many periods.
STALL_PERIODS = 4


def default_stall_s(T_s: float) -> float:
    """The lateness (s) above which a wake-up counts as a host stall at period ``T_s``."""
    return max(STALL_MIN_S, STALL_PERIODS * T_s)


@dataclass(frozen=True, slots=True)
class JitterStats:
    """Lateness of the wake-ups after their deadlines (s).

    Parameters
    ----------
    n : int
        Number of waits.
    median, p99, max : float
        Median, 99th percentile and maximum lateness (s).
    overruns : int
        Waits entered after their deadline had passed.
    busy_median, busy_p99, busy_max : float
        The caller's work per period (s): from one wake-up to the next call
        of :meth:`RealTimeClock.wait` (RT-LAB's "computation time").  Above
        ``T_s`` the schedule cannot be kept whatever the scheduler does.
    stalls : int
        Wake-ups later than the stall threshold (host stalls); each
        resynchronised the schedule.
    stall_total, stall_max : float
        Total and longest stall (s): how late those wake-ups were.
    skipped : int
        Periods skipped by the resynchronisations (deadlines that passed
        during a stall; missed periods, not computed).
    """

    n: int
    median: float
    p99: float
    max: float
    overruns: int
    busy_median: float = 0.0
    busy_p99: float = 0.0
    busy_max: float = 0.0
    stalls: int = 0
    stall_total: float = 0.0
    stall_max: float = 0.0
    skipped: int = 0


#: Longest busy-wait margin before each deadline (s): the OS wakes a sleeping thread tens
#: to hundreds of microseconds late, and the margin absorbs that at the price of its CPU.
SPIN_MAX_S = 200e-6

#: Largest share of a period spent in that margin.  A loop under SCHED_FIFO must sleep in
#: every period: the kernel's real-time throttling (``sched_rt_runtime_us`` over
#: ``sched_rt_period_us``, 950 ms of every 1 s by default) takes a real-time thread that
#: keeps its CPU off it for the rest of the second.  With the whole 200 us margin at 10 kHz
#: (and at 4 kHz beside the plant's 45-50 us of work) the loop never slept, and the native
#: clock alone (``bn_timing_run``, SCHED_FIFO, 4 s) met stalls of 52-153 ms that skipped
#: 1,563-2,276 periods; with a quarter period it met none (0.43-0.69 % of the periods
#: woke more than half a period late).  A quarter leaves the loop's work (about half a
#: period at 10 kHz) and its margin three quarters of the CPU, 20 points below the throttle.
SPIN_SHARE = 0.25


def default_spin_s(T_s: float) -> float:
    """The busy-wait margin before each deadline of a ``T_s`` period (s):
    :data:`SPIN_MAX_S`, at most :data:`SPIN_SHARE` of the period.  The Python clock
    (:class:`RealTimeClock`) and the native loop's (``bn_clock_t``) both take it."""
    return min(SPIN_MAX_S, SPIN_SHARE * T_s)


class RealTimeClock:
    """Absolute-deadline clock with overrun counting and jitter statistics.

    Parameters
    ----------
    T_s : float
        Period (s).
    spin : float, optional
        Busy-wait margin before each deadline (s); default :func:`default_spin_s`.
    keep : int, optional
        Number of most recent lateness values kept for the statistics.
    stall_s : float, optional
        A wake-up later than this is a host stall and resynchronises the
        schedule (default :func:`default_stall_s`); ``math.inf``: always
        catch up.

    Examples
    --------
    >>> clock = RealTimeClock(1e-3)
    >>> clock.start()
    >>> for _ in range(3):
    ...     lateness = clock.wait()  # returns at deadline 1, 2, 3
    """

    def __init__(
        self,
        T_s: float,
        spin: float | None = None,
        keep: int = 100_000,
        stall_s: float | None = None,
    ) -> None:
        if not T_s > 0.0:
            raise ValueError(f"T_s must be > 0, got {T_s}")
        self.T_s = float(T_s)
        self.stall_s = default_stall_s(self.T_s) if stall_s is None else float(stall_s)
        if not self.stall_s > 0.0:
            raise ValueError(f"stall_s must be > 0, got {stall_s}")
        self.spin = default_spin_s(self.T_s) if spin is None else float(spin)
        self.keep = int(keep)
        self.overruns = 0
        self.n = 0
        self._t0: float | None = None
        self._late: list[float] = []
        self._late_max = 0.0
        self._busy: list[float] = []
        self._woke = 0.0
        self.stalls = 0
        self.stall_total = 0.0
        self.stall_max = 0.0
        self.skipped = 0

    def start(self, t0: float | None = None) -> None:
        """Start the schedule at ``t0`` (default: now); deadline ``n`` is ``t0 + n T_s``."""
        self._t0 = time.perf_counter() if t0 is None else float(t0)
        self.n = 0
        self.overruns = 0
        self._late = []
        self._late_max = 0.0
        self._busy = []
        self._woke = self._t0
        self.stalls = 0
        self.stall_total = 0.0
        self.stall_max = 0.0
        self.skipped = 0

    @property
    def next_deadline(self) -> float:
        """The ``perf_counter`` time of the next deadline (s)."""
        if self._t0 is None:
            self.start()
        assert self._t0 is not None
        return self._t0 + (self.n + 1) * self.T_s

    def wait(self) -> float:
        """Wait until the next deadline and return how late the wake-up was (s).

        If the deadline has passed by at most ``stall_s``, return at once and
        count an overrun; the schedule stays absolute, so later deadlines are
        not shifted (the caller catches up).  If it has passed by more, the
        host stalled: count the stall, skip the whole periods that passed
        and move the schedule forward by them (the module doc gives the
        reasons); the lateness returned and kept is that of the stall.
        """
        deadline = self.next_deadline
        now = time.perf_counter()
        busy = self._busy
        busy.append(now - self._woke)
        if len(busy) > 2 * self.keep:
            del busy[: len(busy) - self.keep]
        if now > deadline:
            self.overruns += 1
            behind = now - deadline
            if behind > self.stall_s:
                skip = int(behind / self.T_s)
                assert self._t0 is not None
                self._t0 += skip * self.T_s
                self.skipped += skip
                self.stalls += 1
                self.stall_total += behind
                if behind > self.stall_max:
                    self.stall_max = behind
        else:
            pause = deadline - now - self.spin
            if pause > 0.0:
                time.sleep(pause)
            while time.perf_counter() < deadline:
                pass
            now = time.perf_counter()
        self._woke = now
        late = now - deadline
        self.n += 1
        lst = self._late
        lst.append(late)
        if len(lst) > 2 * self.keep:
            del lst[: len(lst) - self.keep]
        if late > self._late_max:
            self._late_max = late
        return late

    def periods_behind(self) -> int:
        """Whole periods the schedule is behind the wall clock right now."""
        behind = (time.perf_counter() - self.next_deadline) / self.T_s
        return int(behind) + 1 if behind > 0.0 else 0

    def stats(self) -> JitterStats:
        """Lateness statistics over the kept waits (overruns included)."""
        lst = sorted(self._late[-self.keep :])
        if not lst:
            return JitterStats(0, 0.0, 0.0, 0.0, self.overruns)
        median, p99 = _median_p99(lst)
        busy = sorted(self._busy[-self.keep :])
        b_med, b_p99 = _median_p99(busy)
        return JitterStats(
            self.n,
            median,
            p99,
            self._late_max,
            self.overruns,
            b_med,
            b_p99,
            busy[-1],
            self.stalls,
            self.stall_total,
            self.stall_max,
            self.skipped,
        )


def _median_p99(lst: list[float]) -> tuple[float, float]:
    """Median and 99th percentile of a sorted, non-empty list."""
    n = len(lst)
    median = lst[n // 2] if n % 2 else 0.5 * (lst[n // 2 - 1] + lst[n // 2])
    return median, lst[min(n - 1, int(0.99 * (n - 1) + 0.5))]
