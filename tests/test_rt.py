"""Real-time settings of the node processes (bench/nodes/_rt.py) and the clock's compute time."""

from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bench.cli import main
from bench.nodes._clock import RealTimeClock
from bench.nodes._rt import apply_rt, no_gc
from tests.ports import free_port


def _in_child(code: str) -> dict[str, object]:
    """Run ``code`` (which prints JSON) in a fresh interpreter: scheduling is per process."""
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True
    )
    return {"result": json.loads(out.stdout), "stderr": out.stderr}


def _fifo_permitted() -> bool:
    code = (
        "import os\n"
        "try:\n"
        "    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1)); print('true')\n"
        "except (OSError, AttributeError):\n"
        "    print('false')\n"
    )
    return bool(_in_child(code)["result"])


def test_nothing_asked_nothing_changed() -> None:
    rt = apply_rt(None, None, role="plant")
    assert rt.policy == "normal" and rt.refused == [] and not rt.memory_locked
    assert rt.cpus == sorted(os.sched_getaffinity(0))


def test_a_refused_setting_is_reported_not_raised() -> None:
    r = _in_child(
        "import json; from bench.nodes._rt import apply_rt\n"
        "print(json.dumps(apply_rt(None, 4096, role='plant').as_dict()))"
    )
    res = r["result"]
    assert isinstance(res, dict)
    assert res["policy"] == "normal"
    assert len(res["refused"]) == 1 and "cpu 4096" in res["refused"][0]
    lines = str(r["stderr"]).strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("plant: real-time setting refused")


def test_fifo_priority_and_cpu_granted_or_refused_with_a_reason() -> None:
    cpu = min(os.sched_getaffinity(0))  # CPU 0 may not be ours (cpuset, taskset)
    r = _in_child(
        "import json, os; from bench.nodes._rt import apply_rt\n"
        f"rt = apply_rt(42, {cpu}, role='controller').as_dict()\n"
        "rt['now'] = [os.sched_getscheduler(0), os.sched_getparam(0).sched_priority]\n"
        "print(json.dumps(rt))"
    )
    res = r["result"]
    assert isinstance(res, dict)
    assert res["cpus"] == [cpu]
    if _fifo_permitted():
        assert res["policy"] == "fifo" and res["priority"] == 42
        assert res["now"] == [os.SCHED_FIFO, 42]
    else:
        assert res["policy"] == "normal" and res["priority"] is None
        assert any("SCHED_FIFO priority 42" in x for x in res["refused"])


def test_no_gc_switches_the_collector_off_and_restores_it() -> None:
    assert gc.isenabled()
    with no_gc():
        assert not gc.isenabled()
        assert gc.get_freeze_count() > 0
    assert gc.isenabled() and gc.get_freeze_count() == 0
    with pytest.raises(RuntimeError), no_gc():
        raise RuntimeError("the loop failed")
    assert gc.isenabled()
    with no_gc(False):
        assert gc.isenabled()


def test_clock_reports_the_callers_compute_time() -> None:
    T_s = 2e-3
    clock = RealTimeClock(T_s)
    clock.start()
    woke = time.perf_counter()
    mine = []
    for _ in range(21):
        while time.perf_counter() - woke < 0.5e-3:  # 0.5 ms of work per period
            pass
        mine.append(time.perf_counter() - woke)
        clock.wait()
        woke = time.perf_counter()
    st = clock.stats()
    # the clock's figure is the caller's own wake-up-to-wait time (what a
    # preempted caller measures too), whatever the machine's load
    assert st.busy_median >= 0.5e-3
    assert abs(st.busy_median - sorted(mine)[10]) < 0.2e-3
    assert st.busy_median <= st.busy_p99 <= st.busy_max


def test_rt_priority_out_of_range_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", "wen-5.1", "--mode", "realtime", "--rt-priority", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("bench: error: "), err
    assert "--rt-priority" in err[0] and "1-99" in err[0]


def test_realtime_run_records_what_the_nodes_were_granted(tmp_path: Path) -> None:
    port = free_port()
    out = tmp_path / "rt"
    code = main(
        [
            "run", "xue-fig13", "-e", "sensored", "--mode", "realtime", "--duration", "0.3",
            "--interface", "udp_multicast", "--channel", "239.74.163.2", "--port", str(port),
            "--rt-priority", "30", "--out", str(out), "--quiet",
        ]
    )  # fmt: skip
    assert code == 0
    reps = json.loads((out / "meta.json").read_text())["node_reports"]
    want = "fifo" if _fifo_permitted() else "normal"
    assert reps["plant"]["rt"]["policy"] == want
    assert reps["controller"]["rt"]["policy"] == want
    if want == "fifo":
        assert (reps["plant"]["rt"]["priority"], reps["controller"]["rt"]["priority"]) == (30, 29)
    m = json.loads((out / "metrics.json").read_text())
    assert m["jitter_us"]["busy_median"] > 0
    # host stalls are counted apart from the late periods (none is an error here)
    assert m["host_stalls"] >= 0 and m["periods_skipped"] >= 0
    assert m["host_stall_ms_max"] >= 0.0
    assert (m["periods_skipped"] > 0) == (m["host_stalls"] > 0)


def test_a_realtime_run_that_did_not_keep_time_gets_a_warning() -> None:
    from bench.runs._results import realtime_warning

    clean = {"steps": 3000, "late_duty_periods": 20, "deadline_misses": 3, "jitter_us": {}}
    assert realtime_warning(clean) is None  # 0.7 %: within what docs/USAGE.md states
    bad = {"steps": 3000, "late_duty_periods": 243, "deadline_misses": 203,
           "jitter_us": {"max": 114000.0}}  # fmt: skip
    line = realtime_warning(bad)
    assert line is not None and "\n" not in line
    assert "8.1 % of periods ran with a late duty" in line and "114.0 ms" in line
    assert "stall" not in line
    stalled = {**bad, "host_stalls": 2, "host_stall_ms_max": 114.0, "periods_skipped": 150}
    line = realtime_warning(stalled)
    assert line is not None and "2 host stalls (longest 114.0 ms, 150 periods skipped)" in line
    # the plant's counters are of the periods it ran, not of the rows recorded: a run
    # whose watchdog tripped early has fewer rows (3,932 of 4,000 periods) and every
    # period with a late duty (it once printed 101.7 %)
    tripped = {"steps": 3932, "plant_periods": 4000, "late_duty_periods": 4000,
               "deadline_misses": 40, "jitter_us": {"max": 4000.0}}  # fmt: skip
    line = realtime_warning(tripped)
    assert line is not None and "100.0 % of periods ran with a late duty" in line
    assert "1.0 % started late" in line


def test_the_paper_column_names_the_method_its_numbers_belong_to() -> None:
    from bench.runs._results import format_metrics

    text = format_metrics({"theta_err_max_deg": 1.0}, {"theta_err_max_deg": 4.0}, "tt-dq")
    head, row = text.splitlines()
    assert "paper (tt-dq)" in head and row.split()[1:3] == ["1.000", "4.0"]
    # without the paper's numbers (a user's own scenario) there is no paper column
    assert format_metrics({"theta_err_max_deg": 1.0}).splitlines()[0].split() == ["metric", "bench"]


def test_the_api_and_the_command_line_give_the_same_warning_lines() -> None:
    """``bench.Run.warnings`` holds every line ``bench run`` prints (run_warnings, one home):
    a real-time run that did not keep time, the exit status's lines, and the periods
    without a row, which the API once left out (a run that a trip ended early)."""
    from bench.runs._results import run_warnings

    m = {"steps": 3001, "plant_periods": 3000, "late_duty_periods": 500, "deadline_misses": 0,
         "jitter_us": {}, "steps_missing": 999}  # fmt: skip
    lines = run_warnings(m, {"mode": "realtime"}, ["warning: the status's line"])
    assert [ln.split(":")[1].strip()[:9] for ln in lines] == ["real time", "the statu", "999 perio"]
    lockstep = run_warnings(m, {"mode": "lockstep"}, [])
    assert len(lockstep) == 1 and "999 periods of the run have no row" in lockstep[0]
    assert (
        run_warnings({**m, "steps_missing": 0}, {"mode": "lockstep", "interrupted": True}, []) == []
    )
