"""A controller under test on the bus: ``bench run --controller external`` over udp_multicast.

The controller is ``tests/ext_controller.py``, written from the DBC and
docs/PROTOCOL.md with python-can and cantools only (no import of ``bench``,
``controller`` or ``plant_rt``: checked here).  It runs as a process of its
own beside ``bench run``, which starts only the plant, paces the commands,
records and scores.  Each mistake docs/PROTOCOL.md warns about gives its
named diagnostic and its documented exit status.
"""

from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bench.nodes._loops import STALL_S
from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import get_preset
from tests.ports import free_port

ROOT = Path(__file__).resolve().parents[1]
CONTROLLER = Path(__file__).parent / "ext_controller.py"
SCENARIO = Path(__file__).parent / "data" / "firmware-100rpm.toml"
N_P = get_preset(load_scenario(str(SCENARIO))).motor.n_p
GROUP = "239.74.163.2"
#: One LSB of the 16-bit angles (PositionSensor.theta_m, PlantTruth.theta_e,
#: CtrlTelemetry.theta_hat), deg.
LSB_DEG = 360.0 / 65536


def encoder_err_bound_deg(n_p: int) -> float:
    """Largest |theta_hat - theta_e| of the test controller, deg electrical.

    The plant's default sensor for a controller under test (65536 counts per
    revolution, every period, no delay: ``bench show``'s ``position_sensor``)
    floors the shaft's angle to a count ``q = 2 pi / 65536``; the controller adds
    ``q / 2``, so its mechanical angle is off by at most ``q / 2``: ``n_p q / 2``
    electrical, ``n_p / 2`` LSB.  ``theta_hat`` and the truth's ``theta_e`` are
    each rounded to an LSB on the wire: half an LSB each, one in all.
    """
    return (n_p / 2 + 1) * LSB_DEG


def _show(tmp: Path, scenario: Path) -> Path:
    """``bench show SCENARIO --json`` into a file (what the controller reads)."""
    tmp.mkdir(parents=True, exist_ok=True)
    show = tmp / f"show-{scenario.stem}.json"
    if not show.exists():
        out = subprocess.run(
            [sys.executable, "-m", "bench", "show", str(scenario), "--json"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            check=True,
        )
        show.write_text(out.stdout)
    return show


def _controller(
    show: Path, port: str, mistake: str | None = None, extra_ctrl: tuple[str, ...] = ()
) -> subprocess.Popen[str]:
    """The test controller on ``port``, once it listens.

    The native libraries are built first: ``bench run`` builds them before its
    plant starts, and a first build on a loaded host takes longer than the
    controller's ``--idle-s`` (it would give up before the first sample)."""
    from bench.runs._run import build_native_libraries

    build_native_libraries()
    ctrl = subprocess.Popen(
        [sys.executable, str(CONTROLLER), "--show", str(show), "-c", GROUP, "-p", port,
         "--idle-s", "30", *(["--mistake", mistake] if mistake else []), *extra_ctrl],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert ctrl.stdout is not None and ctrl.stdout.readline().strip() == "READY"
    return ctrl


def _bench_run(
    scenario: Path, port: str, run_dir: Path, dut_timeout: float, *extra: str
) -> list[str]:
    return [sys.executable, "-m", "bench", "run", str(scenario), "--controller", "external",
            "--interface", "udp_multicast", "--channel", GROUP, "--port", port,
            "--dut-timeout", repr(dut_timeout), "--dut-name", "ext-py", "--out", str(run_dir),
            *extra]  # fmt: skip


def _run(
    tmp: Path,
    *extra: str,
    mistake: str | None = None,
    dut_timeout: float = 60.0,
    scenario: Path = SCENARIO,
    quiet: bool = True,
    controller: bool = True,
    extra_ctrl: tuple[str, ...] = (),
) -> tuple[subprocess.CompletedProcess[str], Path]:
    """``bench run --controller external`` with the test controller beside it (or none).

    The native libraries are built first: the tests' cache starts empty
    (tests/conftest.py), and ``bench run``'s first build (over a minute on a loaded
    host) would otherwise outlast the test controller's 30 s without a frame."""
    from bench.runs._run import build_native_libraries

    build_native_libraries()
    port = str(free_port())
    show = _show(tmp, scenario)
    run_dir = tmp / f"run-{scenario.stem}-{mistake or 'ok'}"
    ctrl = _controller(show, port, mistake, extra_ctrl) if controller else None
    try:
        res = subprocess.run(
            _bench_run(scenario, port, run_dir, dut_timeout, *(["-q"] if quiet else []), *extra),
            cwd=ROOT, capture_output=True, text=True, timeout=240,
        )  # fmt: skip
    finally:
        if ctrl is not None:
            ctrl.kill()
            ctrl.wait()
    return res, run_dir


def test_the_controller_imports_nothing_of_the_bench() -> None:
    tree = ast.parse(CONTROLLER.read_text())
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module.split(".")[0])
    assert names and not names & {"bench", "controller", "plant_rt", "tests", "dbc"}


def _code_strings(path: Path) -> set[str]:
    """The string constants of a Python file's code (docstrings left out)."""
    tree = ast.parse(path.read_text())
    docs = {
        id(n.body[0].value)
        for n in ast.walk(tree)
        if isinstance(n, ast.Module | ast.ClassDef | ast.FunctionDef)
        and n.body
        and isinstance(n.body[0], ast.Expr)
        and isinstance(n.body[0].value, ast.Constant)
    }
    return {
        n.value
        for n in ast.walk(tree)
        if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docs
    }


def test_the_controller_reads_no_plant_truth() -> None:
    """A sensored controller reads PositionSensor; PlantTruth is the recorder's (DBC 2.2):
    neither the frame nor any signal of its own is named in the test controller's code."""
    from bench.wire._codec import Codec

    codec = Codec()
    shared = {sg.name for sg in codec.message("CtrlTelemetry").signals}  # crc, step, run_id
    truth = {"PlantTruth"} | {sg.name for sg in codec.message("PlantTruth").signals} - shared
    strings = _code_strings(CONTROLLER)
    assert "PositionSensor" in strings and "theta_m" in strings
    assert not strings & truth, strings & truth


def test_the_controller_runs_where_the_truth_comes_every_tenth_period(tmp_path: Path) -> None:
    """The plant sends PlantTruth every 10th period only (``--truth-every 10``, docs/HARDWARE.md's
    real bus): a controller that waited for the truth of each period would stall (a
    lockstep watchdog trip); the test controller, which reads PositionSensor, answers
    every period, and its angle stays within the encoder's bound."""
    from bench.runs._run import EXTERNAL, run_scenario
    from bench.wire._bus import BusSpec

    port = free_port()
    ctrl = _controller(_show(tmp_path, SCENARIO), str(port))
    try:
        res = run_scenario(
            load_scenario(str(SCENARIO)),
            EXTERNAL,
            spec=BusSpec("udp_multicast", GROUP, port),
            out_dir=tmp_path / "run",
            progress=False,
            controller=EXTERNAL,
            dut_timeout=60.0,
            dut_name="ext-py",
            node_args={"plant": ["--truth-every", "10"]},
        )
        _, err = ctrl.communicate(timeout=30)  # it ends on the stop command
    finally:
        if ctrl.poll() is None:
            ctrl.kill()
            ctrl.wait()
    m = res.metrics
    # the plant ran every period; the recorder scores those with truth (every tenth)
    assert m["plant_fault"] == "none" and m["steps"] + m["steps_missing"] == 3001, m
    assert json.loads((tmp_path / "run" / "plant.json").read_text())["steps"] == 3000
    assert "3001 periods" in err, err[-2000:]
    tab = np.genfromtxt(tmp_path / "run" / "signals.csv", delimiter=",", names=True)
    e = tab["theta_err_deg"][np.isfinite(tab["theta_err_deg"])]
    assert len(e) >= 300 and np.max(np.abs(e)) <= encoder_err_bound_deg(N_P) + 1e-9


@pytest.fixture(scope="module")
def good_run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    tmp = tmp_path_factory.mktemp("ext")
    res, run_dir = _run(tmp)
    return {"res": res, "dir": run_dir, "tmp": tmp}


def test_external_controller_is_run_and_scored(good_run: dict[str, Any]) -> None:
    res, run_dir = good_run["res"], good_run["dir"]
    assert res.returncode == 0, res.stderr[-3000:]
    assert "first valid PwmDuty" in res.stderr
    m = json.loads((run_dir / "metrics.json").read_text())
    meta = json.loads((run_dir / "meta.json").read_text())
    assert m["steps"] == 3001 and m["steps_missing"] == 0
    assert m["frames_rejected"] == 0 and m["plant_fault"] == "none"
    # sensored from PositionSensor: the encoder's error and no more; and more than the
    # wire's rounding alone (one LSB), which is all a controller reading the truth shows
    err = max(abs(m["theta_err_max_deg"]), abs(m["theta_err_min_deg"]))
    assert 1.5 * LSB_DEG < err <= encoder_err_bound_deg(N_P) + 1e-9
    # the IMC-tuned speed loop holds the 100 rpm reference after the 50 ms ramp
    assert m["speed_err_max_rpm"] < 5.0
    assert meta["controller"] == "external" and meta["controller_name"] == "ext-py"
    assert meta["node_engines"] == {"plant": "native"}  # the native loop serves it
    assert meta["controller_gains"] == {} and meta["dbc_version"] == "2.4"
    assert (run_dir / "run.png").is_file() and not (run_dir / "controller.log").exists()
    # PlantStatus every 100 ms of plant time (0.3 s: at 1000 and 2000) and at the end
    assert json.loads((run_dir / "plant.json").read_text())["late_frames"] == 0


def test_the_speed_estimate_has_the_encoders_noise(good_run: dict[str, Any]) -> None:
    """The test controller's speed, from the encoder's differences through its filter, is
    off the truth by the quantisation noise its design states (ext_controller.py): rms
    within 30 % of the prediction, never beyond the largest (plus the truth's LSB,
    0.01 rad/s, rounded)."""
    from tests.ext_controller import Foc

    foc = Foc(json.loads(_show(good_run["tmp"], SCENARIO).read_text()))
    rms, top = foc.speed.quantisation_noise(65536)
    tab = np.genfromtxt(good_run["dir"] / "signals.csv", delimiter=",", names=True)
    steady = tab["t"] >= load_scenario(str(SCENARIO)).score_from_s
    e = (tab["w_hat_rpm"] - tab["w_m_rpm"])[steady] * np.pi / 30.0
    print(
        f"speed estimate error: rms {np.std(e):.4f} rad/s (predicted {rms:.4f}), max {np.max(np.abs(e)):.4f} (bound {top:.4f})"
    )
    assert np.std(e) == pytest.approx(rms, rel=0.3)
    assert np.max(np.abs(e)) <= top + 0.005


def test_analyze_of_the_capture_gives_the_same_metrics(good_run: dict[str, Any]) -> None:
    run_dir = good_run["dir"]
    out = good_run["tmp"] / "analyzed"
    res = subprocess.run(
        [sys.executable, "-m", "bench", "analyze", str(run_dir / "capture.blf"), "--out",
         str(out), "--no-plots"],
        cwd=ROOT, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    live = json.loads((run_dir / "metrics.json").read_text())
    again = json.loads((out / "metrics.json").read_text())
    node_only = {"wall_s", "realtime_factor", "retransmits", "deadline_misses", "late_commands",
                 "frames_repeated_ignored", "late_duty_periods"}  # fmt: skip
    for k, v in live.items():
        if k in node_only or isinstance(v, dict):
            continue
        assert again[k] == v, k
    assert "external controller ext-py" in res.stdout or "ext-py" in (out / "meta.json").read_text()


def test_analyze_duration_warning_status_counters_and_name(
    good_run: dict[str, Any], tmp_path: Path
) -> None:
    """A 0.3 s run analysed against a 0.5 s scenario: the missing periods are said, and
    ``--duration`` says the run was that long; the PlantStatus counters are read; the
    controller's name goes into meta.json."""
    longer = tmp_path / "longer.toml"
    longer.write_text(SCENARIO.read_text().replace("duration = 0.3", "duration = 0.5"))
    cap = good_run["dir"] / "capture.blf"

    def analyze(*extra: str) -> tuple[subprocess.CompletedProcess[str], dict[str, Any]]:
        out = tmp_path / f"a{len(extra)}"
        res = subprocess.run(
            [sys.executable, "-m", "bench", "analyze", str(cap), "--scenario", str(longer),
             "--out", str(out), "--no-plots", *extra],
            cwd=ROOT, capture_output=True, text=True, timeout=120,
        )  # fmt: skip
        assert res.returncode == 0, res.stderr
        return res, json.loads((out / "metrics.json").read_text())

    res, m = analyze()
    assert m["steps_missing"] == 5000 - 3001 and "give --duration" in res.stderr
    res, m = analyze("--duration", "0.3", "--dut-name", "fw-1.2")
    assert m["steps_missing"] == 0 and "give --duration" not in res.stderr
    assert m["plant_status_late_frames"] == 0 and m["plant_status_overruns"] == 0
    assert "external controller fw-1.2" in res.stdout
    meta = json.loads((tmp_path / "a4" / "meta.json").read_text())
    assert meta["controller_name"] == "fw-1.2" and meta["dbc_version"] == "2.4"


def test_external_controller_in_real_time(tmp_path: Path) -> None:
    """Real time at 1 kHz: the plant's clock starts at the controller's first answer.

    What holds on a busy host too: a Python controller may then miss its
    deadlines for longer than the watchdog (20 ms), and the plant may skip
    periods in a host stall; the run says so (exit 3 and the trip's line, the
    real-time warning) and every period the plant ran is a row.
    """
    scn = tmp_path / "rt-1khz.toml"
    scn.write_text(SCENARIO.read_text() + "f_sw = 1000.0\n")
    res, run_dir = _run(tmp_path, "--mode", "realtime", scenario=scn)
    m = json.loads((run_dir / "metrics.json").read_text())
    meta = json.loads((run_dir / "meta.json").read_text())
    assert meta["mode"] == "realtime" and meta["controller"] == "external"
    assert meta["node_engines"] == {"plant": "native"}
    assert "Traceback" not in res.stderr
    # the status is the trip's, and the trip is named; a controller that a loaded host
    # held back past a command's step is told so (exit 5), as a drive that applied a
    # set-point late would be
    tripped = m["plant_fault"] != "none"
    late_cmds = meta["commands"]["commands_late"] > 0
    want = 3 if tripped else (5 if late_cmds else 0)
    assert res.returncode == want, res.stderr[-3000:]
    assert late_cmds == ("only after their step" in res.stderr) or tripped
    assert m["plant_fault"] in ("none", "watchdog")
    assert tripped == ("tripped its watchdog protection" in res.stderr)
    late = max(m["late_duty_periods"], m["deadline_misses"]) > 0.01 * m["plant_periods"]
    assert late == ("warning: real time not kept" in res.stderr), res.stderr[-3000:]
    # a row for every period the plant ran: the 301 but those a host stall skipped or
    # the recording lost, and each is counted
    assert m["steps"] + m["steps_missing"] == 301 and m["steps"] > 150
    assert m["steps_missing"] == 0 or "no row in signals.csv" in res.stderr
    tab = np.genfromtxt(run_dir / "signals.csv", delimiter=",", names=True)
    # sensored from PositionSensor: wherever an estimate came, within the encoder's error
    err = tab["theta_err_deg"][np.isfinite(tab["theta_err_deg"])]
    # (how many periods carry one depends on the host: a loaded one trips the watchdog
    # early; every row without one is counted)
    assert len(err) > 0 and np.max(np.abs(err)) <= encoder_err_bound_deg(N_P) + 1e-9
    assert np.count_nonzero(np.isnan(tab["theta_hat"])) == m["steps_without_telemetry"]
    assert len(err) == m["steps"] - m["steps_without_telemetry"]


@pytest.mark.parametrize(
    ("mistake", "status", "diagnostic"),
    [
        ("crc-no-id", 2, "PwmDuty: "),
        ("step-k", 3, "wrong_step"),
        ("out-of-range", 2, "rejected (out_of_range)"),
        ("every-other", 3, "skipped sample"),
    ],
)
def test_each_controller_mistake_is_named(
    tmp_path: Path, mistake: str, status: int, diagnostic: str
) -> None:
    # The first answer comes 4-8 s after the plant starts on a loaded 2-core host
    # (measured), and none had come 15 s after it at load 17 (the clock of --dut-timeout
    # also runs through the plant's start-up, 4 s then): a mistake the plant trips on
    # (status 3) gets the default grace, so the trip and not the timeout ends it; one
    # whose every duty is rejected (status 2) ends at the timeout, long enough that
    # duties came and were rejected first.
    res, run_dir = _run(tmp_path, mistake=mistake, dut_timeout=40.0 if status == 2 else 60.0)
    assert res.returncode == status, res.stderr[-3000:]
    assert diagnostic in res.stderr + (run_dir / "plant.log").read_text(), res.stderr[-3000:]
    assert "Traceback" not in res.stderr
    if mistake == "crc-no-id":
        assert "rejected (bad_crc)" in res.stderr
    if status == 3:
        m = json.loads((run_dir / "metrics.json").read_text())
        assert m["plant_fault"] == {"step-k": "wrong_step", "every-other": "watchdog"}[mistake]
    if mistake == "every-other":
        # the trip's line gives the time the plant waited for the skipped duty, which
        # the trip cut short: never the limit it would have given up at (STALL_S)
        log = (run_dir / "plant.log").read_text()
        waited = re.findall(
            r"no valid PwmDuty for step \d+ \(the answer to sample \d+\) in (\d+) (m?s)\b", log
        )
        assert waited, log[-2000:]
        n, unit = waited[-1]
        assert int(n) * (1e-3 if unit == "ms" else 1.0) < STALL_S, log[-2000:]


@pytest.mark.parametrize(
    ("mode", "mistake"),
    [("lockstep", "crc-no-id"), ("realtime", "crc-no-id"), ("lockstep", None), ("realtime", None)],
)
def test_no_valid_duty_within_the_timeout_is_one_line_exit_2_and_error_txt(
    tmp_path: Path, mode: str, mistake: str | None
) -> None:
    """A controller whose every duty fails its CRC, or none at all (one started after the
    timeout), with the progress lines on (not ``-q``): exit 2, one line naming the cause,
    ``error.txt`` holding it beside whatever was recorded."""
    res, run_dir = _run(
        tmp_path, "--mode", mode, mistake=mistake, dut_timeout=3.0, quiet=False,
        controller=mistake is not None,
    )  # fmt: skip
    assert res.returncode == 2, res.stderr[-3000:]
    assert "Traceback" not in res.stderr
    last = res.stderr.strip().splitlines()[-1]
    assert last.startswith("bench: error: no valid PwmDuty from ext-py in 3 s"), last
    assert ("rejected (bad_crc)" if mistake else "no PwmDuty at all") in last, last
    assert (run_dir / "error.txt").read_text().startswith("no valid PwmDuty from ext-py in 3 s")


def test_a_controller_killed_in_real_time_before_the_scoring_start_is_a_trip(
    tmp_path: Path,
) -> None:
    """kill -9 of the controller 0.3 s into a 1 s real-time run scored from 0.6 s: the
    plant trips its watchdog and runs on in its safe state; every plant period is a row
    (the estimate empty after the death), the coasting rotor is in the tracking error,
    the angle metrics are null with the reason, and the run exits 3 with its files."""
    scn = tmp_path / "rt-kill.toml"
    scn.write_text(
        SCENARIO.read_text().replace("duration = 0.3", "duration = 1.0")
        .replace("score_from_s = 0.2", "score_from_s = 0.6") + "f_sw = 1000.0\n"
    )  # fmt: skip
    port = str(free_port())
    ctrl = _controller(_show(tmp_path, scn), port)
    run_dir = tmp_path / "killed"
    bench = subprocess.Popen(
        _bench_run(scn, port, run_dir, 60.0, "-q", "--mode", "realtime"),
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert bench.stderr is not None
        for line in bench.stderr:  # the plant's clock starts at the first answer
            if "first valid PwmDuty" in line:
                break
        time.sleep(0.3)
        ctrl.kill()
        _, err = bench.communicate(timeout=120)
    finally:
        ctrl.kill()
        ctrl.wait()
        if bench.poll() is None:
            bench.kill()
    assert bench.returncode == 3, err[-3000:]
    assert "Traceback" not in err and "tripped its watchdog protection" in err
    m = json.loads((run_dir / "metrics.json").read_text())
    assert (run_dir / "meta.json").is_file() and m["plant_fault"] == "watchdog"
    assert json.loads((run_dir / "meta.json").read_text())["node_engines"] == {"plant": "native"}
    # the plant's periods go on after the death: rows without telemetry, at least the
    # scored 0.4 s (a busy host may skip periods: steps_missing says how many)
    assert m["steps_without_telemetry"] >= 400 - m["steps_missing"] > 0
    assert m["steps"] + m["steps_missing"] == 1001
    assert m["theta_err_max_deg"] is None and "no CtrlTelemetry" in m["unscored_reason"]
    # the safe state lets the rotor coast: far from the 100 rpm reference
    assert m["speed_track_err_max_rpm"] > 20.0
    tab = np.genfromtxt(run_dir / "signals.csv", delimiter=",", names=True)
    assert np.isnan(tab["theta_hat"][-1]) and np.isfinite(tab["w_m_rpm"][-1])
