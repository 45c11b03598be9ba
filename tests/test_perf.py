"""``bench perf``: the quick run writes every figure, and the docs are renderings of perf.json.

No timing is asserted: the figures are benchmarks, judged in the page they
render, never in a test.
"""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path
from typing import Any

import pytest

from bench.cli import main
from bench.studies._perf import (
    _DOC_BUSLOAD,
    _DOC_DEFINITIONS,
    _DOC_HEAD,
    README_BEGIN,
    README_END,
    TARGET_LIST,
    late_figures,
    render_benchmarks,
    render_readme_block,
    render_realtime_native,
    update_readme,
    verdicts,
)
from controller import ESTIMATOR_NAMES
from controller._engine import COMPILED_ESTIMATORS
from plant_rt import compiled_engine_missing

ROOT = Path(__file__).resolve().parent.parent
RATES = ("1kHz", "4kHz", "10kHz")


def _numbers(x: object) -> list[float]:
    if isinstance(x, bool):
        return []
    if isinstance(x, int | float):
        return [float(x)]
    if isinstance(x, dict):
        return [v for val in x.values() for v in _numbers(val)]
    if isinstance(x, list):
        return [v for val in x for v in _numbers(val)]
    return []


def _committed() -> dict[str, Any]:
    return json.loads((ROOT / "docs" / "perf" / "perf.json").read_text())


def test_perf_quick_writes_every_figure_and_renders_the_docs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    doc = tmp_path / "BENCHMARKS.md"
    readme = tmp_path / "README.md"
    readme.write_text(f"# x\n\n## Performance\n\n{README_BEGIN}\nold\n{README_END}\n\nafter\n")
    argv = ["perf", "--quick", "--out", str(tmp_path), "--doc", str(doc), "--readme", str(readme)]
    assert main(argv) == 0
    res = json.loads((tmp_path / "perf.json").read_text())
    # the keys scripts read
    assert res["inprocess"]["rtf_10khz_tt_dq"] > 0
    assert res["lockstep"]["steps_per_s"] > 0
    assert res["demo"]["wall_s"] > res["demo"]["run_s"] > res["demo"]["loop_s"] > 0
    for name in RATES:
        assert res["realtime_fifo"][name]["overrun_pct"] >= 0
        assert res["realtime_fifo"][name]["busy_us_median"] > 0
    # the native plant node beside the Python one, in the same run
    assert res["lockstep_native"]["steps_per_s"] > 0
    assert res["lockstep_native"]["node_engines"]["plant"] == "native"
    assert res["lockstep"]["node_engines"]["plant"] == "python"
    for name in RATES:
        r = res["realtime_native"][name]
        assert r["node_engines"]["plant"] == "native" and "controller" in r["note"]
        assert 0 <= r["missed_pct"] <= 100 and r["busy_us_median"] > 0
        # the busy time part by part: each part is inside each period's busy time
        for key in ("send_us_median", "recv_us_median", "step_us_median"):
            assert 0 < r[key] <= r["busy_us_median"]
    # a sensorless run at 10 kHz on the native pair, real time against lockstep (what holds
    # on a busy host: both ran native and were scored; the verdict is the host's, REALTIME.md)
    sc = res["realtime_native_score"]
    assert sc["f_sw"] == 10000.0 and sc["tolerance_deg"] == pytest.approx(0.24)
    rt = sc["realtime"]
    modes = ["lockstep"]
    if "error" in rt:  # the host failed the real-time run (a node killed at its stop): said
        assert rt["error"] and rt["lock_lost"] and not sc["scores_like_lockstep"]
    else:
        modes.append("realtime")
    for mode in modes:
        assert sc[mode]["node_engines"] == {"plant": "native", "controller": "native"}
        assert sc[mode]["theta_err_rms_deg"] >= 0
    assert sc["lockstep"]["late_duty_pct"] == 0.0 and not sc["lockstep"]["lock_lost"]
    assert sc["scores_like_lockstep"] == (
        sc["rms_diff_deg"] <= sc["tolerance_deg"] and not sc["realtime"]["lock_lost"]
    )
    # the in-process native pair: inside C, the whole loop, each unit's share
    nat = res["inprocess_native"]
    assert nat["wall_us_per_step_tt_dq"] >= nat["us_per_step_tt_dq"] > 0
    assert nat["plant_us"] > 0 and nat["controller_us"] > 0
    assert nat["python_loop_wall_us_per_step_tt_dq"] > 0
    assert 0 < nat["returns_per_1000_steps"] < 1000
    # the whole loop's split (medians over the runs): the frames' rows, Python at the returns
    assert 0 < nat["frames_us_per_step"] < nat["wall_us_per_step_tt_dq"]
    assert 0 < nat["returns_us_per_step"] < nat["wall_us_per_step_tt_dq"]
    assert (
        res["verdicts"]["inprocess_native_us_per_step_tt_dq"]["value"] == (nat["us_per_step_tt_dq"])
    )
    assert res["codec"]["analyze_frames"] >= 20_000
    assert res["codec"]["analyze_frames_per_s"] > 0
    # both engines (the compiled one where it is built), in the same run
    eng = res["engines"]["measured"]
    assert eng == ["python"] + ([] if compiled_engine_missing() else ["compiled"])
    inp = res["inprocess"]
    for key in ("tt_dq_10khz", "switching_10khz"):
        for e in eng:
            assert inp[key][e]["us_per_step"] > 0 and inp[key][e]["rtf"] > 0
        if "compiled" in eng:
            ratio = inp[key]["python"]["us_per_step"] / inp[key]["compiled"]["us_per_step"]
            assert inp[key]["compiled_over_python"] == pytest.approx(ratio)
    for model in ("average", "switching"):
        a = inp["alone_us_per_period"][model]
        assert all(a[e] > 0 for e in eng)
    # the controller has one engine, its core: one figure, no ratio of the core to itself
    ctrl = inp["alone_us_per_period"]["controller_tt_dq"]
    assert set(ctrl) == {"compiled"} and ctrl["compiled"] > 0
    for est in ESTIMATOR_NAMES:
        # every estimator the compiled core covers on it where it is built, the rest in Python
        want = eng[-1] if est in COMPILED_ESTIMATORS else "python"
        assert inp[est]["controller_engine"] == want
    for e in eng:
        n = inp["plant_node_10khz"][e]
        assert n["us_p99"] >= n["us_p50"] > 0
    for est in ("sfhf", "tt-ab", "tt-dq", "square-wave", "square-wave-nocic", "sensored"):
        assert inp[est]["us_per_step"] > 0
    nums = [
        v
        for s in ("inprocess", "lockstep", "codec", "busload", "transport_send_us")
        for v in _numbers(res[s])
    ]
    assert all(math.isfinite(v) and v > 0 for v in nums)
    assert len(res["busload"]) >= 4
    # real time: the stall figures beside the late periods, and the sum they make
    for sec in ("realtime", "realtime_fifo"):
        assert set(res[sec]) == set(RATES)
        for name in RATES:
            r = res[sec][name]
            assert (
                r["steps"] > 0
                and r["jitter_us_max"] >= r["jitter_us_median"]
                and r["busy_us_p99"] >= r["busy_us_median"] > 0
            )
            assert r["policy"] in ("normal", "fifo")
            for k in ("host_stalls", "host_stall_ms_total", "host_stall_ms_max", "periods_skipped"):
                assert r[k] >= 0
            assert r["host_stall_ms_total"] >= r["host_stall_ms_max"]
            assert (
                r["missed_pct"]
                >= r["overrun_pct"] * r["steps"] / (r["steps"] + r["periods_skipped"]) - 1e-9
            )
    assert all(r["policy"] == "normal" for r in res["realtime"].values())
    assert set(res["verdicts"]) == {t.key for t in TARGET_LIST}
    for v in res["verdicts"].values():
        assert v["config"] and isinstance(v["met"], bool)
    out = capsys.readouterr().out
    assert "targets:" in out and "perf.json" in out
    # the page and the README block are the renderings of that perf.json
    page = doc.read_text()
    assert page == render_benchmarks(res)
    for t in TARGET_LIST:
        assert t.figure in page
    text = readme.read_text()
    assert "old" not in text and text.endswith("after\n")
    assert render_readme_block(res) in text
    # --from-json renders the same page without measuring
    doc2 = tmp_path / "again.md"
    assert main(["perf", "--from-json", str(tmp_path / "perf.json"), "--doc", str(doc2)]) == 0
    assert doc2.read_text() == page


def test_the_committed_benchmarks_page_is_the_committed_perf_json() -> None:
    res = _committed()
    assert (ROOT / "docs" / "BENCHMARKS.md").read_text() == render_benchmarks(res)


def test_the_readme_block_is_the_committed_perf_json() -> None:
    res = _committed()
    readme = (ROOT / "README.md").read_text()
    assert render_readme_block(res) in readme
    assert update_readme(readme, res) == readme


def test_the_committed_verdicts_follow_the_targets() -> None:
    res = _committed()
    assert res["verdicts"] == verdicts(res)
    assert res["targets"] == {t.key: t.value for t in TARGET_LIST}


def test_the_hand_written_text_holds_no_figure() -> None:
    for text in (_DOC_HEAD, _DOC_DEFINITIONS, _DOC_BUSLOAD):
        assert not any(ch.isdigit() for ch in text), text


def test_a_missed_target_is_explained_and_a_met_one_is_not() -> None:
    res = copy.deepcopy(_committed())
    fifo10 = res["realtime_fifo"]["10kHz"]
    fifo10.update(missed_pct=50.0, busy_us_median=150.0, host_stalls=3.0)
    res["verdicts"] = verdicts(res)
    assert not res["verdicts"]["realtime_missed_pct_10khz_fifo"]["met"]
    page = render_benchmarks(res)
    assert "**Real time, 10 kHz with `--rt-priority`.** 50.0 % of the periods" in page
    assert "exceeds the 100 us period" in page  # the computation, not the host
    fifo10.update(missed_pct=1.0)
    res["verdicts"] = verdicts(res)
    assert res["verdicts"]["realtime_missed_pct_10khz_fifo"]["met"]
    assert "**Real time, 10 kHz with `--rt-priority`.**" not in render_benchmarks(res)


def test_a_missed_native_pair_target_names_the_units_share() -> None:
    res = copy.deepcopy(_committed())
    nat = {
        "us_per_step_tt_dq": 1.5,
        "wall_us_per_step_tt_dq": 20.0,
        "returns_per_1000_steps": 50.0,
        "plant_us": 0.9,
        "controller_us": 0.4,
        "python_loop_wall_us_per_step_tt_dq": 300.0,
        "steps": 22000.0,
    }
    res["inprocess_native"] = nat
    res["verdicts"] = verdicts(res)
    v = res["verdicts"]["inprocess_native_us_per_step_tt_dq"]
    assert v["value"] == 1.5 and not v["met"]
    page = render_benchmarks(res)
    assert "**In-process native pair.** The pair spends 1.50 us per step" in page
    assert "the plant unit takes 0.900 us" in page and "controller unit 0.400 us" in page
    nat["us_per_step_tt_dq"] = 0.7
    res["verdicts"] = verdicts(res)
    assert res["verdicts"]["inprocess_native_us_per_step_tt_dq"]["met"]
    assert "**In-process native pair.**" not in render_benchmarks(res)


def test_late_figures_count_skipped_periods_as_missed() -> None:
    # 1,000 periods computed, 13 late of which 2 ended a host stall; the stalls skipped 40
    f = late_figures(1000, 13, 2, 40)
    assert f["overrun_pct"] == pytest.approx(1.3)
    assert f["missed_pct"] == pytest.approx(100.0 * 53 / 1040)
    assert f["late_outside_stalls_pct"] == pytest.approx(1.1)
    assert late_figures(500, 0, 0, 0)["missed_pct"] == 0.0


def test_the_native_plant_figures_are_rendered_when_measured() -> None:
    """BENCHMARKS.md gains the native plant's rows from perf.json's ``realtime_native`` and
    ``lockstep_native``; a perf.json without them renders as before."""
    from bench.studies._perf import NATIVE_NOTE

    res = copy.deepcopy(_committed())
    res.pop("realtime_native", None)
    res.pop("lockstep_native", None)
    plain = render_benchmarks(res)
    assert "native plant" not in plain
    res["realtime_native"] = {
        k: {**v, "note": NATIVE_NOTE} for k, v in copy.deepcopy(res["realtime_fifo"]).items()
    }
    res["lockstep_native"] = {**res["lockstep"], "note": NATIVE_NOTE}
    text = render_benchmarks(res)
    rows = [ln for ln in text.splitlines() if "SCHED_FIFO, native plant" in ln]
    assert len(rows) == len(RATES)
    refused = sum(res["realtime_native"][r].get("policy") != "fifo" for r in RATES)
    assert sum("native plant refused" in ln for ln in rows) == refused
    assert f"Lockstep, {NATIVE_NOTE}:" in text
    # the Python node's rows have no split of the busy time: no line of parts
    assert "part by part" not in text
    for i, name in enumerate(RATES):
        r = res["realtime_native"][name]
        r.update(send_us_median=30.0 + i, recv_us_median=5.0, step_us_median=1.0)
    text = render_benchmarks(res)
    for i, name in enumerate(RATES):
        assert f"{name}: send (the instant's frames out) {30 + i:.1f} us" in text
    assert "part by part" in render_realtime_native(res)


def test_the_demo_section_is_rendered_against_the_issue_target_when_measured() -> None:
    """BENCHMARKS.md gains the ``make demo`` section from perf.json's ``demo``, judged against
    15 s / 5 with its largest share named; a perf.json without it renders as before."""
    from bench.studies._perf import DEMO_TARGET_S

    res = copy.deepcopy(_committed())
    res.pop("demo", None)
    plain = render_benchmarks(res)
    assert "make demo" not in plain
    assert DEMO_TARGET_S == 15.0 / 5.0
    demo = {
        "command": "bench run wen-5.1 --estimator tt-dq",
        "quick": False,
        "wall_s": 9.5,
        "run_s": 7.0,
        "loop_s": 6.0,
        "nodes_s": 1.0,
        "outside_run_s": 2.5,
        "steps": 40001,
        "loop_steps_per_s": 40001 / 6.0,
        "node_engines": {"controller": "native", "plant": "native"},
        "issue_s": 15.0,
        "target_s": 3.0,
        "met": False,
    }
    res["demo"] = demo
    text = render_benchmarks(res)
    assert "| `make demo`, the whole command (`demo.wall_s`) | 9.50 s | <= 3.00 s" in text
    assert "The largest share is the stepping loop (6.00 s of 9.50 s)" in text
    assert "it needs 13,334 periods/s" in text
    assert "one run (`demo.wall_s`" in text and "demo.cpu_s" not in text  # an older perf.json
    # the median of several runs, and the CPU the work needs on the machine's cores
    res["demo"] = {
        **demo,
        "wall_s_runs": [9.4, 9.5, 9.9],
        "cpu_s": 8.0,
        "cpu_floor_s": 4.0,
        "cpus": 2,
    }
    text = render_benchmarks(res)
    assert "the run of median wall time of 3 (9.40 s, 9.50 s, 9.90 s)" in text
    assert "| CPU time of the command and its node processes (`demo.cpu_s`), over 2 cores" in text
    assert "use 8.00 s of CPU, 4.00 s on each of the 2 cores" in text
    assert "more than the target, so no schedule of this work meets it" in text
    res["demo"] = {**res["demo"], "cpu_s": 5.0, "cpu_floor_s": 2.5}
    assert "within the target, so the rest is waiting" in render_benchmarks(res)
    res["demo"] = {**demo, "wall_s": 2.9, "loop_s": 1.5, "nodes_s": 0.5, "met": True}
    assert "The target is met in this run." in render_benchmarks(res)
