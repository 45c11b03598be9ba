"""The pytest plugin (``hil`` fixture) and ``bench.testing``, run as a user's test files are:
through pytest itself (``pytester``), with the plugin loaded from its ``pytest11`` entry point."""

from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bench._api import Run
from bench.testing import assert_lock_kept, assert_settles, assert_tracks, assert_within
from tests.test_external_controller import N_P, encoder_err_bound_deg

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "tests" / "data" / "firmware-100rpm.toml"
CONTROLLER = ROOT / "tests" / "ext_controller.py"

USER_TESTS = f"""
from bench.testing import assert_lock_kept, assert_settles, assert_within

SCENARIO = {str(SCENARIO)!r}

def test_speed_holds(hil):
    run = hil.run(SCENARIO)
    assert_lock_kept(run)
    assert_within(run, theta_err_abs_mean_deg=1.0, speed_err_max_rpm=20.0)
    assert_settles(run, "w_m_rpm", to=100.0, within=5.0, by_s=0.2)

def test_a_bound_too_tight(hil):
    run = hil.run(SCENARIO, duration=0.25)
    assert_within(run, speed_err_max_rpm=1e-6)
"""


def _properties(xml: Path) -> dict[str, dict[str, str]]:
    out: dict[str, dict[str, str]] = {}
    for case in ET.parse(xml).getroot().iter("testcase"):
        props = {p.get("name", ""): p.get("value", "") for p in case.iter("property")}
        out[case.get("name", "")] = props
    return out


def test_the_fixture_runs_records_and_fails_on_one_line(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(test_user=USER_TESTS)
    xml = pytester.path / "junit.xml"
    res = pytester.runpytest_subprocess(f"--junitxml={xml}", "-p", "no:cacheprovider", "-s")
    res.assert_outcomes(passed=1, failed=1)
    assert "record_property is incompatible" not in res.stdout.str()
    out = res.stdout.str()
    # where it ran is said (this kernel has no vcan: in-process)
    assert "hil: firmware-100rpm over in-process -> " in out
    props = _properties(xml)
    ok = props["test_speed_holds"]
    folder = Path(ok["hil.folder"])
    assert folder.is_relative_to(pytester.path) and folder.name == "hil-1-firmware-100rpm"
    import json

    metrics = json.loads((folder / "metrics.json").read_text())
    assert float(ok["hil.theta_err_abs_mean_deg"]) == pytest.approx(
        metrics["theta_err_abs_mean_deg"]
    )
    assert ok["hil.transport"] == "in-process" and ok["hil.exit_status"] == "0"
    assert ok["hil.steps"] == "3001"
    # a table is its JSON: the metric as metrics.json has it
    assert json.loads(ok["hil.faults"]) == metrics["faults"]
    assert json.loads(ok["hil.frames_rejected_by_reason"]) == metrics["frames_rejected_by_reason"]
    # the failure: metric, bound, value, time and folder on one line
    bad = props["test_a_bound_too_tight"]
    line = next(x for x in out.splitlines() if x.startswith("E ") and "speed_err_max_rpm" in x)
    assert "> 1e-06" in line and "scored t = 0.2 .. 0.25 s" in line
    # the failure is the user's line and that one, not the helper's body (__tracebackhide__)
    assert "raise _fail(" not in out and "def assert_within" not in out
    assert f"run {bad['hil.folder']}" in line
    measured = float(bad["hil.speed_err_max_rpm"])
    assert f"|{measured:.6g}|" in line


def test_an_external_controller_started_by_the_fixture(
    pytester: pytest.Pytester, tmp_path: Path
) -> None:
    show = tmp_path / "show.json"
    out = subprocess.run(
        [sys.executable, "-m", "bench", "show", str(SCENARIO), "--json"],
        cwd=ROOT, capture_output=True, text=True, check=True,
    )  # fmt: skip
    show.write_text(out.stdout)
    # the controller reads the plant's default encoder (PositionSensor): its bound
    bound = encoder_err_bound_deg(N_P)
    pytester.makepyfile(
        test_dut=f"""
import sys
from bench.testing import assert_lock_kept, assert_within

def test_my_controller(hil):
    run = hil.run(
        {str(SCENARIO)!r},
        controller="external",
        dut=[sys.executable, {str(CONTROLLER)!r}, "--show", {str(show)!r},
             "-i", "{{interface}}", "-c", "{{channel}}", "-p", "{{port}}", "--idle-s", "30"],
        dut_name="ext-py",
        dut_timeout=60.0,
    )
    assert run.meta["controller"] == "external" and run.meta["controller_name"] == "ext-py"
    assert (run.folder / "dut.log").is_file()
    assert_lock_kept(run)
    assert_within(run, theta_err_abs_max_deg={bound!r}, speed_err_max_rpm=5.0, frames_rejected=0)
    print("TRANSPORT", run.transport)
"""
    )
    res = pytester.runpytest_subprocess("-p", "no:cacheprovider", "-s")
    res.assert_outcomes(passed=1)
    # no vcan here: a controller under test needs a bus, so udp_multicast
    assert "hil: firmware-100rpm over udp_multicast -> " in res.stdout.str()
    assert "TRANSPORT udp_multicast:" in res.stdout.str()


def test_hil_options(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(
        test_opts="""
def test_bus(hil):
    assert hil.transport() == "udp_multicast:239.1.2.3" and hil.engine == "python"
"""
    )
    res = pytester.runpytest_subprocess(
        "--hil-interface", "udp_multicast", "--hil-channel", "239.1.2.3", "--hil-engine", "python"
    )
    res.assert_outcomes(passed=1)


# -- the helpers on a run made by hand ------------------------------------------------


def _run(**signals: Any) -> Run:
    t = np.arange(11) * 0.1
    sig = {"t": t, **{k: np.asarray(v, dtype=float) for k, v in signals.items()}}
    # sim_s is rows x T_s (10,001 rows at 0.1 ms: the last at t = 1 s)
    metrics = {"theta_err_abs_mean_deg": -2.5, "sim_s": 1.0001, "lock_lost": False, "thd": None}
    run = Run(metrics, 0, Path("/runs/x"), "in-process", meta={"scored_from_s": 0.5, "T_s": 1e-4})
    run._signals = sig
    return run


def test_assert_within_takes_the_magnitude() -> None:
    run = _run()
    assert_within(run, theta_err_abs_mean_deg=2.5)
    with pytest.raises(AssertionError) as e:
        assert_within(run, theta_err_abs_mean_deg=2.4)
    assert str(e.value) == (
        "theta_err_abs_mean_deg: |-2.5| > 2.4 (scored t = 0.5 .. 1 s); run /runs/x"
    )
    with pytest.raises(AssertionError, match=r"^thd: no value \(None; bound 1"):
        assert_within(run, thd=1.0)
    with pytest.raises(AssertionError, match=r"^nope: not a metric of this run"):
        assert_within(run, nope=1.0)


def test_assert_lock_kept_names_the_time() -> None:
    run = _run()
    assert_lock_kept(run)
    run.metrics.update(lock_lost=True, lock_lost_at_s=0.75, theta_err_abs_max_deg=170.0)
    with pytest.raises(AssertionError, match=r"^lock_lost: .* at t = 0\.7500 s .* run /runs/x$"):
        assert_lock_kept(run)


def test_assert_tracks_names_the_first_time_outside() -> None:
    ref = [100.0] * 11
    x = [0, 50, 90, 99, 100, 100, 100, 104, 100, 100, 100]
    run = _run(w=x, r=ref)
    assert_tracks(run, "w", "r", within=5.0, after_s=0.3)
    assert_tracks(run, "w", 100.0, within=5.0, after_s=0.3)
    with pytest.raises(AssertionError) as e:
        assert_tracks(run, "w", "r", within=3.0, after_s=0.3)
    assert str(e.value) == (
        "w: |w - r| = 4 > 3 at t = 0.7000 s (tracking from t = 0.3 s; w = 104, "
        "1 of 8 samples outside, worst 4); run /runs/x"
    )


def test_assert_settles_must_stay() -> None:
    run = _run(w=[0, 50, 90, 99, 100, 100, 100, 104, 100, 100, 100])
    assert_settles(run, "w", to=100.0, within=5.0, by_s=0.3)
    with pytest.raises(AssertionError, match=r"^w: .* > 2 at t = 0\.7000 s \(settled by 0\.3 s"):
        assert_settles(run, "w", to=100.0, within=2.0, by_s=0.3)
    with pytest.raises(AssertionError, match=r"^w: no sample at t >= 2 s \(the run ends at 1 s\)"):
        assert_settles(run, "w", to=100.0, within=2.0, by_s=2.0)
    with pytest.raises(AssertionError, match=r"^nope: not a signal of this run"):
        assert_settles(run, "nope", to=1.0, within=1.0, by_s=0.0)


def test_run_png_goes_into_the_html_report(pytester: pytest.Pytester) -> None:
    pytest.importorskip("pytest_html")
    pytester.makepyfile(
        test_html=f"""
def test_one(hil):
    run = hil.run({str(SCENARIO)!r}, duration=0.25)
    assert (run.folder / "run.png").is_file()
"""
    )
    res = pytester.runpytest_subprocess("--html=report.html", "--self-contained-html")
    res.assert_outcomes(passed=1)
    html = (pytester.path / "report.html").read_text()
    (png,) = pytester.path.rglob("hil-1-firmware-100rpm/run.png")  # this session's run
    import base64

    # the picture itself, base64 in the page (pytest-html escapes its data as JSON)
    head = base64.b64encode(png.read_bytes()).decode("ascii")[:200]
    assert head.replace("/", "\\/") in html or head in html
