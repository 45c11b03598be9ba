"""The native loop's clock (bench/nodes/native/bn_clock.c): what holds on a busy machine.

Absolute deadlines: no wake-up before its deadline, and N periods take N T
plus the last wake-up's lateness, however late the ones between were (a loop
of relative sleeps takes N (T + wake-up latency): at least 50 us more per
period, the default timer slack).  Missed deadlines are counted.  How many
periods a quiet host misses is measured by ``bench perf``, not asserted here.
"""

from __future__ import annotations

import ctypes
import os
import shutil

import pytest

from bench.nodes.native import _native

pytestmark = pytest.mark.skipif(
    not any(shutil.which(c) for c in ("cc", "gcc")), reason="needs a C compiler"
)

#: No stall handling in these runs: every deadline is kept (the loop catches up).
NO_STALL = 1e3


@pytest.fixture(scope="module")
def dll(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    return _native.load(_native.build(tmp_path_factory.mktemp("native")).lib)


def test_deadlines_are_absolute(dll: ctypes.CDLL) -> None:
    T, n = 100e-6, 5000
    st = _native.timing_run(dll, T, n, stall_s=NO_STALL)
    assert st["periods"] == n and st["period_ns"] == round(T * 1e9)
    assert st["late_min_ns"] >= 0  # never woke before a deadline
    assert st["stalls"] == st["skipped"] == 0
    # the last deadline is t0 + n T: reached, and not pushed back by the late wake-ups
    assert n * T <= st["wall_ns"] * 1e-9 <= n * T + 0.15
    assert 0 <= st["missed"] <= n and 0 <= st["late_half"] <= n


def test_busy_tail_keeps_the_deadlines(dll: ctypes.CDLL) -> None:
    T, n = 250e-6, 2000
    st = _native.timing_run(dll, T, n, busy_tail_s=50e-6, stall_s=NO_STALL)
    assert st["periods"] == n and st["late_min_ns"] >= 0
    assert n * T <= st["wall_ns"] * 1e-9 <= n * T + 0.15


def test_work_longer_than_a_period_misses_every_deadline(dll: ctypes.CDLL) -> None:
    T, n = 200e-6, 500
    st = _native.timing_run(dll, T, n, work_s=1.5 * T, stall_s=NO_STALL)
    assert st["missed"] == n
    assert st["late_half"] >= n - 1
    assert st["busy_median_ns"] >= 1.5 * T * 1e9  # the work is the busy time


def test_busy_time_is_the_work_of_a_period(dll: ctypes.CDLL) -> None:
    T, n = 1e-3, 300
    st = _native.timing_run(dll, T, n, work_s=0.3 * T, stall_s=NO_STALL)
    assert st["busy_median_ns"] >= 0.3 * T * 1e9
    assert st["busy_max_ns"] >= st["busy_median_ns"]
    assert st["wall_ns"] * 1e-9 >= n * T


def test_stalls_move_the_schedule_on(dll: ctypes.CDLL) -> None:
    """Work of 3 periods with a stall threshold of 2: every wait skips whole periods."""
    T, n = 1e-3, 50
    st = _native.timing_run(dll, T, n, work_s=3 * T, stall_s=2 * T)
    assert st["stalls"] == n and st["missed"] == n
    assert st["skipped"] >= 2 * n  # at least the two whole periods each stall passed


def test_rt_settings_are_granted_or_refused_and_given_back(dll: ctypes.CDLL) -> None:
    policy, cpus = os.sched_getscheduler(0), os.sched_getaffinity(0)
    cpu = min(cpus)
    st = _native.timing_run(
        dll, 1e-3, 20, rt_priority=10, lock_memory=True, cpu=cpu, stall_s=NO_STALL
    )
    rt = st["rt"]
    assert rt["priority"] == 10
    assert (rt["fifo"] == 1) != (rt["err_sched"] != 0)
    assert (rt["memory_locked"] == 1) != (rt["err_mlock"] != 0)
    assert (rt["cpu"] == cpu) != (rt["err_cpu"] != 0)
    assert os.sched_getscheduler(0) == policy and os.sched_getaffinity(0) == cpus
    plain = _native.timing_run(dll, 1e-3, 20, stall_s=NO_STALL)["rt"]
    assert plain["fifo"] == plain["memory_locked"] == 0 and plain["cpu"] == -1
