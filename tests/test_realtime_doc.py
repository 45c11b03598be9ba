"""docs/REALTIME.md's native block is ``bench perf``'s rendering of docs/perf/perf.json.

The block names each issue-29 target of the native nodes with its figure,
verdict and, where missed, the limit the same run measured.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import pytest

from bench.studies._perf import (
    NATIVE_DOC_BEGIN,
    NATIVE_DOC_END,
    NATIVE_NOTE,
    NATIVE_TARGET_LIST,
    native_verdicts,
    recorder_frames_lost,
    render_realtime_native,
    update_realtime_doc,
)

ROOT = Path(__file__).resolve().parents[1]


def _committed() -> dict[str, Any]:
    return json.loads((ROOT / "docs" / "perf" / "perf.json").read_text())


def test_the_committed_page_is_the_rendering_of_the_committed_json() -> None:
    doc = (ROOT / "docs" / "REALTIME.md").read_text()
    assert doc.count(NATIVE_DOC_BEGIN) == 1 and doc.count(NATIVE_DOC_END) == 1
    assert update_realtime_doc(doc, _committed()) == doc


def _measured(missed_10k: float, frames_lost: float) -> dict[str, Any]:
    """The committed perf.json with native figures: the SCHED_FIFO rows as the native ones."""
    res = copy.deepcopy(_committed())
    nat = {
        k: {**v, "note": NATIVE_NOTE, "recorder_frames_lost": 0.0}
        for k, v in copy.deepcopy(res["realtime_fifo"]).items()
    }
    nat["10kHz"].update(
        missed_pct=missed_10k,
        late_outside_stalls_pct=0.5,
        periods_skipped=300.0,
        host_stalls=4.0,
        busy_us_median=8.0,
        recorder_frames_lost=frames_lost,
    )
    nat["4kHz"].update(missed_pct=0.5)
    res["realtime_native"] = {**nat, "recorder_frames_lost": recorder_frames_lost(nat)}
    res["lockstep_native"] = {**res["lockstep"], "steps_per_s": 25000.0, "note": NATIVE_NOTE}
    res.pop("realtime_native_score", None)  # the rates' runs alone (the score: below)
    return res


def test_each_target_has_its_verdict_and_a_missed_one_its_limit() -> None:
    res = _measured(missed_10k=18.2, frames_lost=12.0)
    v = native_verdicts(res)
    assert v is not None and set(v) == {t.key for t in NATIVE_TARGET_LIST}
    assert v["native_busy_us_p50_10khz"]["met"] and v["native_missed_pct_4khz"]["met"]
    assert v["native_lockstep_periods_per_s"]["met"]
    assert not v["native_missed_pct_10khz"]["met"]
    assert "host stalls: 4 stalls" in v["native_missed_pct_10khz"]["limit"]
    assert "300 periods" in v["native_missed_pct_10khz"]["limit"]
    assert v["native_recorder_frames_lost"] == {**v["native_recorder_frames_lost"], "value": 12.0}
    assert not v["native_recorder_frames_lost"]["met"]
    text = render_realtime_native(res)
    rows = [ln for ln in text.splitlines() if ln.startswith("| ") and "missed" in ln]
    assert sum("**missed**" in ln for ln in rows) == 2
    assert "| 10kHz | " in text and "18.2 %" in text
    met = render_realtime_native(_measured(missed_10k=2.0, frames_lost=0.0))
    assert "**missed**" not in met


def test_a_transport_that_does_not_say_is_not_a_zero() -> None:
    """-1 (the transport does not report drops) makes the total unknown, never 0 frames."""
    res = _measured(missed_10k=2.0, frames_lost=-1.0)
    assert res["realtime_native"]["recorder_frames_lost"] == -1.0
    v = native_verdicts(res)
    assert v is not None and not v["native_recorder_frames_lost"]["met"]
    assert v["native_recorder_frames_lost"]["limit"] == "not said by the transport"


def _score(rt_rms: float, lost: bool = False) -> dict[str, Any]:
    run = {"theta_err_abs_max_deg": 0.7, "theta_err_mean_deg": 0.38, "lock_lost": False}
    return {
        "scenario": "wen-5.1",
        "estimator": "tt-dq",
        "duration_s": 4.0,
        "f_sw": 10000.0,
        "tolerance_deg": 0.24,
        "rms_diff_deg": abs(rt_rms - 0.40),
        "scores_like_lockstep": abs(rt_rms - 0.40) <= 0.24 and not lost,
        "lockstep": {**run, "theta_err_rms_deg": 0.40, "late_duty_pct": 0.0},
        "realtime": {**run, "theta_err_rms_deg": rt_rms, "lock_lost": lost, "late_duty_pct": 5.4},
    }


def test_the_sensorless_real_time_score_says_its_verdict_and_the_late_periods() -> None:
    res = _measured(missed_10k=1.0, frames_lost=0.0)
    res["realtime_native_score"] = _score(0.45)
    page = render_realtime_native(res)
    assert "0.450 deg in real time against 0.400 deg in lockstep" in page
    assert "it scores like it within 0.240 deg" in page and "late duty" not in page
    res["realtime_native_score"] = _score(5.02)
    page = render_realtime_native(res)
    assert "**does not score like it**" in page
    assert "5.40 % of its periods ran with a late duty" in page
    res["realtime_native_score"]["realtime"].update(
        host_stalls=46.0, host_stall_ms_total=1001.5, plant_fault="over_current",
        recorder_frames_lost=29881.0,
    )  # fmt: skip
    page = render_realtime_native(res)
    assert "46 host stalls (1,002 ms in all), plant trip: over_current" in page
    assert "frames the recorder lost: 29,881." in page


def test_the_score_is_the_run_of_median_rms_of_several_real_time_runs() -> None:
    """The real-time run moves from run to run by its late periods: the score names every
    run's rms and how many scored like lockstep, and its figures are the median run's,
    a failed run or a lost angle counting as the worst."""
    from bench.studies._perf import _failed_score_run, median_score_run

    def run(rms: float, lost: bool = False) -> dict[str, Any]:
        return {"theta_err_rms_deg": rms, "lock_lost": lost}

    pick, n = median_score_run([run(2.45), run(0.48), run(0.83)], 0.40, 0.24)
    assert pick["theta_err_rms_deg"] == 0.83 and n == 1
    pick, n = median_score_run([run(0.3, lost=True), run(0.5), _failed_score_run("x")], 0.4, 0.24)
    assert pick["lock_lost"] and n == 1  # the kept-angle run ranks first, the median is worse
    pick, n = median_score_run([run(0.45)], 0.40, 0.24)
    assert pick["theta_err_rms_deg"] == 0.45 and n == 1
    res = _measured(missed_10k=1.0, frames_lost=0.0)
    res["realtime_native_score"] = {
        **_score(0.83),
        "realtime_rms_runs": [2.45, 0.48, 0.83],
        "realtime_runs_within": 1,
    }
    page = render_realtime_native(res)
    assert "Real time 3 times, the run of median rms below (rms 2.45 deg, 0.480 deg, " in page
    assert "0.830 deg; 1 of 3 scored like lockstep)." in page
    assert "0.830 deg in real time against 0.400 deg in lockstep" in page


def test_the_score_says_the_commands_its_nodes_held_after_their_step() -> None:
    """A command held after its step applies a set-point later than in lockstep: the run
    differs with no late duty, and the score says so beside the late periods."""
    res = _measured(missed_10k=1.0, frames_lost=0.0)
    res["realtime_native_score"] = _score(2.77)
    assert "after their step" not in render_realtime_native(res)
    res["realtime_native_score"]["realtime"].update(late_commands=497.0, commands_sent=501.0)
    page = render_realtime_native(res)
    assert "its controller held 497 of the 501 bench commands only after their step" in page


def test_a_failed_real_time_score_run_is_said_with_its_line() -> None:
    from bench.studies._perf import _failed_score_run

    res = _measured(missed_10k=1.0, frames_lost=0.0)
    res["realtime_native_score"] = _score(0.45)
    line = "node process failed (controller: killed by SIGKILL); files in /tmp/x/realtime"
    res["realtime_native_score"]["realtime"] = _failed_score_run(line)
    res["realtime_native_score"]["scores_like_lockstep"] = False
    page = render_realtime_native(res)
    assert f"**The real-time run failed on this host**: {line}." in page
    assert "rms in lockstep 0.400 deg" in page and "scores like it" not in page


def test_the_score_tolerance_is_one_periods_angle_at_the_top_speed() -> None:
    from bench.scenarios._schema import load_scenario
    from bench.studies._perf import score_tolerance_deg

    # wen-5.1: 100 rpm, 4 pole pairs (wen2023), 10 kHz: 360 * 4 * 100 / 60 / 1e4 deg
    assert score_tolerance_deg(load_scenario("wen-5.1")) == pytest.approx(0.24)


def test_the_frames_the_recorder_lost_in_the_score_run_count_against_the_target() -> None:
    res = _measured(missed_10k=2.0, frames_lost=0.0)
    res["realtime_native_score"] = _score(0.45)
    v = native_verdicts(res)
    assert v is not None and v["native_recorder_frames_lost"]["met"]  # not measured there
    res["realtime_native_score"]["realtime"]["recorder_frames_lost"] = 5154.0
    v = native_verdicts(res)
    assert v is not None and v["native_recorder_frames_lost"]["value"] == 5154.0
    assert (
        "5,154 in the sensorless score's real-time run" in v["native_recorder_frames_lost"]["limit"]
    )
    res["realtime_native_score"]["realtime"]["recorder_frames_lost"] = -1.0
    v = native_verdicts(res)
    assert (
        v is not None and v["native_recorder_frames_lost"]["limit"] == "not said by the transport"
    )
