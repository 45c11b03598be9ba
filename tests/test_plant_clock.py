"""RealTimeClock: absolute deadlines and overrun counting (no timing-accuracy assertions)."""

from __future__ import annotations

import time

from plant_rt import RealTimeClock


def test_clock_counts_overruns_when_caller_is_late() -> None:
    T_s = 1e-3
    clock = RealTimeClock(T_s)
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
