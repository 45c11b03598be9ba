"""RealTimeClock: absolute deadlines and overrun counting (no timing-accuracy assertions)."""

from __future__ import annotations

import math
import time

import pytest

from bench.nodes._clock import (
    SPIN_MAX_S,
    SPIN_SHARE,
    STALL_MIN_S,
    STALL_PERIODS,
    RealTimeClock,
    default_spin_s,
    default_stall_s,
)


def test_clock_counts_overruns_when_caller_is_late() -> None:
    T_s = 1e-3
    clock = RealTimeClock(T_s, stall_s=math.inf)  # always catch up
    t0 = time.perf_counter()
    clock.start(t0)
    for _ in range(5):
        clock.wait()
    ok_before = clock.overruns
    time.sleep(6 * T_s)  # make the caller late on purpose
    for _ in range(3):
        late = clock.wait()
        assert late >= 0.0
    # The first wait after the sleep starts past its deadline; the schedule is
    # absolute, so the next ones are past theirs too (catching up).
    assert clock.overruns >= ok_before + 3
    for _ in range(10):
        clock.wait()
    # Never returns before the absolute deadline n * T_s.
    assert time.perf_counter() - t0 >= (clock.n - 1) * T_s
    st = clock.stats()
    assert st.n == clock.n == 18
    assert st.overruns == clock.overruns
    assert 0.0 <= st.median <= st.p99 <= st.max
    assert st.max >= 3 * T_s  # the deliberate lateness is recorded


def test_clock_restart_resets() -> None:
    clock = RealTimeClock(2e-3, spin=0.0)
    clock.start()
    clock.wait()
    clock.start()
    assert (clock.n, clock.overruns, clock.stats().n) == (0, 0, 0)


def test_a_stall_resynchronises_the_schedule_and_is_counted_apart() -> None:
    T_s = 1e-3
    clock = RealTimeClock(T_s, stall_s=5e-3)
    t0 = time.perf_counter()
    clock.start(t0)
    for _ in range(3):
        clock.wait()
    # counted from here: a loaded machine may have stalled the first waits too
    stalls, skipped, total = clock.stalls, clock.skipped, clock.stall_total
    time.sleep(0.03)  # a 30 ms stall of the "host"
    clock.wait()
    st = clock.stats()
    assert st.stalls == clock.stalls == stalls + 1
    behind = st.stall_total - total
    assert behind >= 0.03 - 3 * T_s and st.stall_max >= behind
    # the deadlines that passed are skipped, whole periods, and counted
    assert st.skipped == clock.skipped == skipped + int(behind / T_s)
    assert int(behind / T_s) >= 26
    # the schedule moved forward by exactly those periods: no catch-up burst
    assert clock.next_deadline == pytest.approx(t0 + (clock.n + 1 + st.skipped) * T_s, abs=1e-9)
    assert clock.next_deadline > t0 + 0.03


def test_lateness_below_the_stall_threshold_is_caught_up() -> None:
    T_s = 1e-3
    clock = RealTimeClock(T_s, stall_s=1.0)
    t0 = time.perf_counter()
    clock.start(t0)
    time.sleep(0.006)
    clock.wait()
    assert (clock.stalls, clock.skipped) == (0, 0)
    assert clock.next_deadline == pytest.approx(t0 + (clock.n + 1) * T_s, abs=1e-12)


def test_the_default_stall_threshold() -> None:
    assert default_stall_s(1e-4) == STALL_MIN_S  # 10 kHz: 2 ms, 20 periods
    assert default_stall_s(1e-3) == STALL_PERIODS * 1e-3  # 1 kHz: 4 periods
    assert RealTimeClock(1e-3).stall_s == default_stall_s(1e-3)
    with pytest.raises(ValueError):
        RealTimeClock(1e-3, stall_s=0.0)


@pytest.mark.parametrize("rate_hz", [1_000, 4_000, 10_000, 20_000])
def test_the_clock_sleeps_in_every_period(rate_hz: int) -> None:
    """The busy-wait margin stays a quarter period at most: a SCHED_FIFO loop that
    spins through whole periods is throttled by the kernel (50 ms of every second)."""
    T = 1.0 / rate_hz
    spin = default_spin_s(T)
    assert 0.0 < spin <= SPIN_SHARE * T < T and spin <= SPIN_MAX_S
    assert spin == min(SPIN_MAX_S, SPIN_SHARE * T)
    assert RealTimeClock(T).spin == spin
    assert RealTimeClock(T, spin=0.0).spin == 0.0
