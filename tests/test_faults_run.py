"""Fault timelines in runs: the schema's one-line errors, the bus faults' lockstep
semantics, the scoring in metrics.json and the exit status of an expectation."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import can
import numpy as np
import pytest

import bench
from bench._errors import EXIT_FAULT_EXPECTATION, ScenarioError
from bench.nodes._loops import WATCHDOG_MIN_S, WATCHDOG_PERIODS, run_inprocess
from bench.scenarios._faults import KINDS
from bench.scenarios._schema import load_scenario
from tests.trace_helpers import CODEC, assert_same_trace, trace

T_S = 1e-3  # xue-fig13: 1 kHz


def _scenario(tmp_path: Path, faults: list[dict[str, Any]], duration: float = 1.3) -> str:
    lines = ['extends = "xue-fig13"', f"duration = {duration}"]
    for f in faults:
        lines.append("[[faults]]")
        for k, v in f.items():
            lines.append(f"{k} = {v!r}".replace("'", '"'))
    p = tmp_path / "f.toml"
    p.write_text("\n".join(lines) + "\n")
    return str(p)


@pytest.mark.parametrize(
    ("fault", "field", "words"),
    [
        ({"at_s": 1.0, "kind": "open_door"}, "faults[0].kind", "unknown kind"),
        ({"kind": "current_lost", "phase": "a"}, "faults[0].at_s", "required"),
        ({"at_s": 1.0, "kind": "current_lost"}, "faults[0].phase", "required"),
        ({"at_s": 1.0, "kind": "current_lost", "phase": "d"}, "faults[0].phase", '"a", "b"'),
        ({"at_s": 1.0, "kind": "current_lost", "phase": "a", "a": 1.0}, "faults[0].a", "unknown key"),
        ({"at_s": 9.0, "kind": "current_lost", "phase": "a"}, "faults[0].at_s", "within the run"),
        ({"at_s": 1.0, "duration_s": 0.0, "kind": "silence"}, "faults[0].duration_s", "> 0"),
        ({"at_s": 1.0, "kind": "demagnetisation", "psi_f_factor": 1.2}, "faults[0].psi_f_factor", "(0, 1]"),
        ({"at_s": 1.0, "kind": "drop", "message": "PlantTruth", "prob": 1.0}, "faults[0].message", "one of"),
        ({"at_s": 1.0, "kind": "drop", "message": "PwmDuty", "prob": 2.0}, "faults[0].prob", "[0, 1]"),
        ({"at_s": 1.0, "kind": "delay", "message": "PwmDuty"}, "faults[0].steps", "steps"),
        ({"at_s": 1.0, "kind": "babble", "rate_hz": 5000.0}, "faults[0].rate_hz", "one foreign"),
        ({"at_s": 1.0, "kind": "silence", "expect": "survive"}, "faults[0].expect", "one of"),
        ({"at_s": 1.0, "kind": "open_phase"}, "faults[0].phase", "required"),
        ({"at_s": 1.0, "kind": "open_switch", "phase": "b", "device": "top"}, "faults[0].device",
         '"upper" or "lower"'),
        ({"at_s": 1.0, "kind": "open_switch", "phase": "b"}, "faults[0].device", "required"),
    ],
)  # fmt: skip
def test_a_wrong_fault_entry_is_one_line_naming_file_field_and_reason(
    tmp_path: Path, fault: dict[str, Any], field: str, words: str
) -> None:
    src = _scenario(tmp_path, [fault])
    with pytest.raises(ScenarioError) as info:
        load_scenario(src)
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith(src) and f"'{field}'" in msg and words in msg, msg


def test_the_timeline_round_trips_through_the_effective_scenario(tmp_path: Path) -> None:
    from bench.scenarios._schema import scenario_from_dict

    scn = load_scenario(
        _scenario(
            tmp_path,
            [
                {"at_s": 1.0, "kind": "delay", "message": "PwmDuty", "steps": 3},
                {"at_s": 1.1, "duration_s": 0.1, "kind": "current_gain", "phase": "c",
                 "factor": 0.5, "expect": "ride_through"},
            ],
        )
    )  # fmt: skip
    assert [f.kind for f in scn.faults] == ["delay", "current_gain"]
    assert scenario_from_dict(scn.to_dict(), "x").faults == scn.faults
    assert scn.faults[1].periods(T_S) == (1100, 1200)


def test_bench_faults_lists_every_kind_with_its_parameters(
    capsys: pytest.CaptureFixture[str],
) -> None:
    from bench.cli import main

    assert main(["faults"]) == 0
    out = capsys.readouterr().out
    for k in KINDS.values():
        assert f"  {k.name}(" in out
        for p in k.params:
            assert f"      {p.name}: " in out


def test_a_lost_duty_burst_trips_the_lockstep_watchdog_after_the_real_time_periods(
    tmp_path: Path,
) -> None:
    """drop PwmDuty prob 1.0 for 50 ms from t = 1.0 s: the last duty (for period 999)
    arrived in period 998; the watchdog trips W = max(10, 20 ms / T) periods later,
    as the real-time plant's, and the expected trip makes the run exit 0."""
    src = _scenario(
        tmp_path,
        [{"at_s": 1.0, "duration_s": 0.05, "kind": "drop", "message": "PwmDuty", "prob": 1.0,
          "expect": "trip"}],
    )  # fmt: skip
    run = bench.run(src, estimator="sensored", out=tmp_path / "run")
    W = max(WATCHDOG_PERIODS, math.ceil(WATCHDOG_MIN_S / T_S - 1e-9))
    assert run.metrics["plant_fault"] == "watchdog"
    assert run.metrics["plant_fault_step"] == 998 + W
    (f,) = run.metrics["faults"]
    assert f["detected_by"] == "watchdog"
    assert f["reaction_ms"] == pytest.approx((998 + W - 1000) * T_S * 1e3)
    assert f["expect"] == "trip" and f["met"] is True
    assert run.exit_status == 0


def test_a_missed_expectation_exits_with_its_own_status(tmp_path: Path) -> None:
    src = _scenario(
        tmp_path,
        [{"at_s": 1.0, "duration_s": 0.2, "kind": "resistance_drift", "R_s_factor": 1.3,
          "expect": "trip"}],
    )  # fmt: skip
    run = bench.run(src, estimator="sensored", out=tmp_path / "run")
    (f,) = run.metrics["faults"]
    assert f["detected_by"] is None and f["met"] is False and f["lock_kept"] is True
    assert run.exit_status == EXIT_FAULT_EXPECTATION
    assert any("expected trip" in w for w in run.warnings)


def test_sensor_and_bus_faults_reach_the_controller_and_lockstep_stays_deterministic(
    tmp_path: Path,
) -> None:
    faults = [
        {"at_s": 1.0, "duration_s": 0.1, "kind": "current_offset", "phase": "a", "a": 0.5},
        {"at_s": 1.05, "duration_s": 0.05, "kind": "drop", "message": "PwmDuty", "prob": 0.3},
        {"at_s": 1.1, "duration_s": 0.01, "kind": "corrupt", "message": "PwmDuty"},
        {"at_s": 1.15, "duration_s": 0.05, "kind": "babble", "rate_hz": 200.0},
        {"at_s": 1.2, "duration_s": 0.05, "kind": "delay", "message": "PwmDuty", "steps": 1},
    ]
    src = _scenario(tmp_path, faults)
    runs = [bench.run(src, estimator="sensored", out=tmp_path / f"r{i}") for i in range(2)]
    a, b = (r.signals for r in runs)
    for col in ("i_a", "i_b", "theta_err_deg", "w_m_rpm", "duty_age"):
        np.testing.assert_array_equal(a[col], b[col])
    assert runs[0].metrics == {**runs[1].metrics, "wall_s": runs[0].metrics["wall_s"],
                               "realtime_factor": runs[0].metrics["realtime_factor"]}  # fmt: skip
    t = a["t"]
    base = bench.run(_scenario(tmp_path, []), estimator="sensored", out=tmp_path / "base").signals
    # no fault before 1.0 s: the same trace
    np.testing.assert_array_equal(a["i_a"][t < 1.0], base["i_a"][t < 1.0])
    # the offset is on the measured phase-a current (the controller reacts after it)
    k = int(round(1.0 / T_S))
    assert a["i_a"][k] - base["i_a"][k] == pytest.approx(0.5, abs=2e-3)  # wire LSB 1.95 mA
    assert runs[0].metrics["plant_fault"] == "none"
    # duties lost (drop 0.3, then 10 corrupt ones) are held: the applied duty ages
    lost = (t >= 1.05) & (t < 1.12)
    ages = a["duty_age"][lost]
    assert 0 < np.count_nonzero(ages > 0) < len(ages) and np.max(ages) >= 10
    assert np.all(a["duty_age"][(t < 1.05) & (t > 0.5)] == 0)
    # babble: 10 foreign PhaseSamples (200 Hz for 50 ms), rejected by their E2E CRC
    assert runs[0].metrics["frames_rejected_by_reason"] == {"bad_crc": 10}
    # the delay: duties 1 period older in the periods 1200 to 1249 (each row's duty_age
    # is the age of the duty of the period before it)
    kk = np.rint(t / T_S)
    assert set(a["duty_age"][(kk > 1200) & (kk <= 1250)]) == {1.0}
    assert set(a["duty_age"][(kk > 1250) & (t < 1.29)]) == {0.0}


def test_a_lost_sample_burst_trips_the_lockstep_watchdog_as_in_real_time(
    tmp_path: Path,
) -> None:
    """drop PhaseSamples prob 1.0 for 50 ms from t = 1.0 s: samples 1000 to 1049 are lost
    on their first sending, so the controller never answers them in their periods: the
    last duty in time is 1000 (the answer to sample 999), one period after the last of a
    lost-duty burst, and the watchdog trips W periods after its period (999); silence
    loses the duties too, so it trips as the duty burst does."""
    W = max(WATCHDOG_PERIODS, math.ceil(WATCHDOG_MIN_S / T_S - 1e-9))
    for fault, last in (
        ({"kind": "drop", "message": "PhaseSamples", "prob": 1.0}, 999),
        ({"kind": "silence"}, 998),
    ):
        src = _scenario(tmp_path, [{"at_s": 1.0, "duration_s": 0.05, **fault, "expect": "trip"}])
        run = bench.run(src, estimator="sensored", out=tmp_path / f"run-{fault['kind']}")
        assert run.metrics["plant_fault"] == "watchdog", fault
        assert run.metrics["plant_fault_step"] == last + W, fault
        (f,) = run.metrics["faults"]
        assert f["detected_by"] == "watchdog" and f["met"] is True
        assert f["reaction_ms"] == pytest.approx((last + W - 1000) * T_S * 1e3)
        assert run.exit_status == 0


def test_a_short_sample_loss_is_ridden_through_and_lockstep_stays_deterministic(
    tmp_path: Path,
) -> None:
    """5 ms of lost samples (shorter than the watchdog): the periods 1001 to 1005 run
    with duty 1000, aging by one a period; the lost samples are sent again before
    sample 1005, so the controller, computing them in order, answers sample 1005 in
    time and the duties are fresh again from period 1006.  A 30 % loss gives the same
    trace twice."""
    src = _scenario(
        tmp_path,
        [{"at_s": 1.0, "duration_s": 0.005, "kind": "drop", "message": "PhaseSamples",
          "prob": 1.0, "expect": "ride_through"}],
    )  # fmt: skip
    run = bench.run(src, estimator="sensored", out=tmp_path / "short")
    assert run.metrics["plant_fault"] == "none" and run.exit_status == 0
    (f,) = run.metrics["faults"]
    assert f["detected_by"] is None and f["met"] is True
    a = run.signals
    kk = np.rint(a["t"] / T_S).astype(int)
    age = dict(zip(kk.tolist(), a["duty_age"].tolist(), strict=True))
    # each row's duty_age is that of the duty of the period before it
    assert [age[k] for k in range(1000, 1009)] == [0, 0, 1, 2, 3, 4, 5, 0, 0]
    src = _scenario(
        tmp_path,
        [{"at_s": 1.0, "duration_s": 0.05, "kind": "drop", "message": "PhaseSamples",
          "prob": 0.3}],
    )  # fmt: skip
    runs = [bench.run(src, estimator="sensored", out=tmp_path / f"p{i}") for i in range(2)]
    x, y = (r.signals for r in runs)
    for col in ("i_a", "theta_err_deg", "duty_age"):
        np.testing.assert_array_equal(x[col], y[col])
    lost = x["duty_age"][(x["t"] > 1.0) & (x["t"] <= 1.051)]
    assert 0 < np.count_nonzero(lost > 0) < len(lost)
    assert runs[0].metrics["plant_fault"] == "none"


def test_an_open_phase_in_a_lockstep_run_holds_its_current_at_zero_from_its_period(
    tmp_path: Path,
) -> None:
    """open_phase b at 1.0 s (sensored, xue-fig13 with 3 N m of load): the trace up to
    period 1000 is the healthy one; phase b carries current before, and from the opening
    its current freewheels to zero within the first period (L i / u_dc is far below 1 ms)
    and then reads zero (an ideal sensor, within the wire's LSB) while phases a and c
    carry i and -i, until the controller stops the switching; metrics.json scores it."""
    load = "load_nm = [[0.0, 0.0], [0.8, 3.0]]\n"  # 3 N m: i_q about 2.5 A

    def scenario(faults: list[dict[str, Any]], name: str) -> str:
        src = Path(_scenario(tmp_path, faults))
        text = src.read_text().replace("\n", "\n" + load, 1)
        out = tmp_path / name
        out.write_text(text)
        return str(out)

    fault = {"at_s": 1.0, "duration_s": 0.1, "kind": "open_phase", "phase": "b"}
    run = bench.run(scenario([fault], "f.toml"), estimator="sensored", out=tmp_path / "run")
    base = bench.run(scenario([], "b.toml"), estimator="sensored", out=tmp_path / "base")
    s, b = run.signals, base.signals
    kk = np.rint(s["t"] / T_S)
    np.testing.assert_array_equal(s["i_b"][kk <= 1000], b["i_b"][np.rint(b["t"] / T_S) <= 1000])
    assert np.max(np.abs(s["i_b"][(kk > 950) & (kk <= 1000)])) > 1.0
    (f,) = run.metrics["faults"]
    assert f["kind"] == "open_phase" and f["at_s"] == 1.0
    end = 1100 if f["detected_at_s"] is None else round(f["detected_at_s"] / T_S)
    on = (kk >= 1001) & (kk < end)
    lsb = 2.0**-9  # PhaseSamples current LSB, 1.95 mA
    assert np.count_nonzero(on) >= 5
    assert np.all(np.abs(s["i_b"][on]) <= lsb)
    assert np.max(np.abs(s["i_a"][on])) > 0.3
    # the true currents (PlantCurrents): phase b exactly zero from the first sample after
    # the opening while the fault lasts, a and c carry i and -i; the exact sensors of the
    # ideal plant read them to the bit
    open_ = (kk >= 1001) & (kk < 1100)
    assert np.all(s["i_b_true"][open_] == 0.0)
    np.testing.assert_array_equal(s["i_c_true"][open_], -s["i_a_true"][open_])
    np.testing.assert_array_equal(s["i_a_true"], s["i_a"])
    assert np.all(s["fault_active"][(kk >= 1000) & (kk < 1100)] == 1)


def test_a_pwmduty_drop_gives_one_trace_in_process_and_as_processes(tmp_path: Path) -> None:
    """A lost duty is held at the last duty the plant applied, never at a newer one
    already here.  In-process the controller answers sample ``k`` (duty ``k + 1``)
    before period ``k`` runs, as processes it seldom has: a plant that held the newest
    duty it had applied duty ``k + 1`` one period early in-process only, and the two
    modes parted from the first lost duty on.  wen-5.1 (10 kHz) with ``tt-dq``: 30 %
    of the duties of 100 ms to 120 ms lost, then every duty of 200 ms to 205 ms."""
    lines = ['extends = "wen-5.1"', "duration = 0.25", "score_from_s = 0.05"]
    for at, dur, prob in ((0.1, 0.02, 0.3), (0.2, 0.005, 1.0)):
        lines += ["[[faults]]", f"at_s = {at}", f"duration_s = {dur}", 'kind = "drop"',
                  'message = "PwmDuty"', f"prob = {prob}"]  # fmt: skip
    src = tmp_path / "drop.toml"
    src.write_text("\n".join(lines) + "\n")
    scn = load_scenario(str(src))
    ref = trace(run_inprocess(scn, "tt-dq", CODEC, loop="python"), scn)
    # the burst: periods 2000 to 2049 run with duty 1999, one period older each (each
    # row carries the age of the duty of the period before it)
    age = dict(zip(ref["step"].tolist(), ref["duty_age"].tolist(), strict=True))
    assert [age[k] for k in range(2000, 2053)] == [0, *range(1, 51), 0, 0]
    held = np.count_nonzero(ref["duty_age"][(ref["step"] >= 1000) & (ref["step"] < 1200)] > 0)
    assert 20 < held < 120  # 30 % of 200 periods lost, some in a row
    # the Python plant node (engine compiled) and the native one (auto), as bench run runs them
    for engine, node in (("compiled", "python"), ("auto", "native")):
        run = bench.run(
            src, estimator="tt-dq", engine=engine, transport="udp_multicast", out=tmp_path / engine
        )
        assert run.folder is not None and run.meta["node_engines"]["plant"] == node
        got = trace(list(can.LogReader(str(run.folder / "capture.blf"))), scn)
        assert_same_trace(ref, got)
