"""A user's mistakes and a run's accidents: one line, the right exit, nothing silently lost.

- ``--out`` that cannot be written: one line, exit 2, in ``bench run`` and ``bench analyze``.
- An unparsable line in a text capture costs that line, not the rest of the file.
- A run cut short is scored by the rule ``bench analyze`` applies to its capture.
- The controller killed in lockstep ends the run at once, naming the signal.
- ``CAN_INTERFACE``: the transport line names interface, channel and port.
- The safe state applies no duty: ``duty_age`` 255, as the DBC says.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import can
import numpy as np
import pytest

from bench.captures._read import analyze_capture, read_capture_counted
from bench.cli import build_parser, main
from bench.cli._common import bus_spec
from bench.nodes._loops import make_plant_node, run_inprocess
from bench.runs._results import run_metadata
from bench.runs._run import _score
from bench.scenarios._schema import load_scenario
from bench.wire._bus import BusSpec
from bench.wire._codec import Codec
from plant_rt import FAULT_WATCHDOG
from tests.ports import free_port

CODEC = Codec()
ROOT = Path(__file__).resolve().parents[1]
SCORED = ("theta_err_max_deg", "theta_err_mean_deg", "theta_err_rms_deg", "steps", "scored_steps")


def one_line_exit_2(argv: list[str], capsys: pytest.CaptureFixture[str], what: str) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("bench: error: --out ") and what in err[0], err


@pytest.mark.parametrize("where", ["under_a_file", "proc"])
def test_unwritable_out_is_one_line_in_run_and_analyze(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], where: str
) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    out = blocker / "sub" if where == "under_a_file" else Path("/proc/bench-out")
    if where == "proc" and not Path("/proc/self").exists():
        pytest.skip("no /proc")
    # no --interface: the transport would be announced first, were the folder not checked first
    one_line_exit_2(["run", "wen-5.1", "--duration", "0.01", "--out", str(out)], capsys, str(out))
    capture = tmp_path / "capture.asc"
    capture.write_text("")  # never read: the output folder is checked first
    one_line_exit_2(["analyze", str(capture), "--out", str(out)], capsys, str(out))


def text_capture(tmp_path: Path, bad_line_at: float | None) -> tuple[Path, int]:
    """An ASC capture of 0.05 s of wen-5.1; one line in it made unparsable at that fraction."""
    scn = load_scenario("wen-5.1").with_overrides(duration=0.05)
    frames = run_inprocess(scn, "sensored", CODEC)
    path = tmp_path / ("bad.asc" if bad_line_at is not None else "good.asc")
    w = can.ASCWriter(str(path))
    for i, m in enumerate(frames):
        m.timestamp = 1e-5 * i
        w.on_message_received(m)
    w.stop()
    lines = path.read_text().splitlines(keepends=True)
    bad = 0
    if bad_line_at is not None:
        bad = int(len(lines) * bad_line_at)
        while " d " not in lines[bad]:
            bad += 1
        head, _, tail = lines[bad].partition(" d ")
        lines[bad] = head + " d zz " + tail  # a DLC that is not hexadecimal
        path.write_text("".join(lines))
    return path, bad + 1


def test_an_unparsable_asc_line_is_skipped_and_counted(tmp_path: Path) -> None:
    good, _ = text_capture(tmp_path, None)
    bad, line_no = text_capture(tmp_path, 0.5)
    whole = read_capture_counted(good)
    got = read_capture_counted(bad)
    assert got.lines_skipped and got.lines_skipped[0][0] == line_no
    assert len(got.lines_skipped) == 1 and got.problem is None
    # every other frame is read, with its time: the rest of the file is not dropped
    assert len(got.frames) == len(whole.frames) - 1
    i = next(
        j for j, (a, b) in enumerate(zip(whole.frames, got.frames, strict=False)) if not a.equals(b)
    )
    assert all(a.equals(b) for a, b in zip(whole.frames[i + 1 :], got.frames[i:], strict=True))
    # bench analyze says so and counts it
    lines: list[str] = []
    res = analyze_capture(bad, scenario="wen-5.1", echo=lines.append, plots=False)
    assert res.metrics["capture_lines_skipped"] == 1
    assert any(f"line {line_no}" in s and "1 unparsable line skipped" in s for s in lines)
    assert "capture_truncated" not in res.metrics
    assert res.metrics["steps"] >= 499


def test_a_run_cut_short_scores_as_bench_analyze_scores_its_capture(tmp_path: Path) -> None:
    """An interrupted run (and a node that died) is scored over the second half of its steps."""
    scn = load_scenario("wen-5.1").with_overrides(duration=0.3)
    frames = run_inprocess(scn, "sensored", CODEC)
    cut = frames[: len(frames) // 3]  # about 0.1 s, before the scoring start (0.15 s)
    for i, m in enumerate(cut):
        m.timestamp = 1e-5 * i
    out = tmp_path / "run"
    out.mkdir()
    capture = out / "capture.blf"
    with can.Logger(str(capture)) as log:
        for m in cut:
            log.on_message_received(m)
    meta = run_metadata(scn, "sensored", mode="lockstep", transport="test", link=False)
    meta["interrupted"] = True
    live = _score(cut, CODEC, scn, out, meta, 1.0, capture, partial=True, plots=False).metrics
    assert "second half" in json.loads((out / "meta.json").read_text())["scoring"]
    again = analyze_capture(capture, out_dir=tmp_path / "again", echo=lambda s: None, plots=False)
    for key in SCORED:
        assert again.metrics[key] == pytest.approx(live[key], rel=1e-12), key
    assert 0 < live["scored_steps"] < live["steps"]


@pytest.mark.skipif(sys.platform != "linux", reason="uses /proc")
@pytest.mark.usefixtures("native_library")  # its first build: not in the 90 s
def test_controller_killed_in_lockstep_ends_the_run_at_once_naming_the_signal(
    tmp_path: Path,
) -> None:
    out = tmp_path / "kill"
    port = free_port()
    cmd = [sys.executable, "-m", "bench", "run", "wen-5.1", "-e", "sensored", "--duration",
           "30", "-i", "udp_multicast", "--channel", "239.74.163.2", "--port",
           str(port), "--out", str(out)]  # fmt: skip
    bus = BusSpec("udp_multicast", "239.74.163.2", port).open()
    proc = subprocess.Popen(cmd, cwd=ROOT, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL)
    said: list[tuple[float, str]] = []  # stderr's lines as they come, with their time

    def read_err() -> None:
        assert proc.stderr is not None
        for line in proc.stderr:
            said.append((time.monotonic(), line.decode()))

    reader = threading.Thread(target=read_err, daemon=True)
    reader.start()
    try:
        _wait_stepping(bus)
        pid = _controller_pid(out)
        assert pid is not None
        os.kill(pid, signal.SIGKILL)
        t_kill = time.monotonic()
        proc.wait(timeout=120)
        reader.join(timeout=30)
    finally:
        bus.shutdown()
        if proc.poll() is None:
            proc.kill()
    err = "".join(line for _, line in said)
    assert proc.returncode == 2, err
    assert "Traceback" not in err
    last = err.strip().splitlines()[-1]
    assert "controller process ended before the run did (killed by SIGKILL)" in last, err
    # said as soon as seen, before the nodes are stopped and the run scored
    seen = [t for t, line in said if "controller process ended (killed by SIGKILL) at step" in line]
    assert seen, err
    # seen by the bench, not by the plant's stall timeout (20 s) after it; timed to the
    # line that says so: the stop of the nodes and the scoring after it take tens of
    # seconds on a loaded 2-core host (16.6 s to the exit measured at load 15)
    took = seen[0] - t_kill
    assert took < 10.0, took
    assert json.loads((out / "metrics.json").read_text())["steps"] > 0


@pytest.mark.skipif(sys.platform != "linux", reason="uses /proc")
@pytest.mark.usefixtures("native_library")  # its first build: not in the 90 s
def test_an_interrupted_run_says_that_it_scores_what_was_recorded(tmp_path: Path) -> None:
    out = tmp_path / "int"
    port = free_port()
    cmd = [sys.executable, "-m", "bench", "run", "wen-5.1", "-e", "sensored", "--duration",
           "30", "-i", "udp_multicast", "--channel", "239.74.163.2", "--port",
           str(port), "--out", str(out)]  # fmt: skip
    bus = BusSpec("udp_multicast", "239.74.163.2", port).open()
    proc = subprocess.Popen(cmd, cwd=ROOT, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL)
    try:
        _wait_stepping(bus)
        proc.send_signal(signal.SIGINT)
        _, err_b = proc.communicate(timeout=60)
    finally:
        bus.shutdown()
        if proc.poll() is None:
            proc.kill()
    err = err_b.decode()
    assert proc.returncode == 130, err
    line = next(ln for ln in err.splitlines() if ln.startswith("interrupted at step"))
    assert "stopping the nodes and scoring what was recorded" in line, err
    assert err.strip().splitlines()[-1] == "bench: interrupted"


def _wait_stepping(bus: can.BusABC, samples: int = 300) -> None:
    """Until the run's plant has sent ``samples`` PhaseSamples: the run is stepping.

    The nodes start together, so neither the plant's log nor the controller's
    process says that the controller is ready; in lockstep the plant's samples
    after the first follow the controller's answers.
    """
    fid = Codec().frame_id("PhaseSamples")
    t0 = time.monotonic()
    n = 0
    while n < samples:
        assert time.monotonic() - t0 < 90, "the run did not start"
        m = bus.recv(1.0)
        if m is not None and m.arbitration_id == fid:
            n += 1


def _controller_pid(out: Path) -> int | None:
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            args = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if b"controller" in args and str(out / "controller.json").encode() in args:
            return int(pid)
    return None


def test_transport_line_from_can_interface_names_channel_and_port(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("CAN_INTERFACE", "udp_multicast")
    monkeypatch.delenv("CAN_CHANNEL", raising=False)
    args = build_parser().parse_args(["run", "wen-5.1"])
    spec = bus_spec(args, announce=True)
    line = capsys.readouterr().err.strip()
    assert spec.interface == "udp_multicast" and spec.channel
    assert line.startswith(f"transport: udp_multicast:{spec.channel} port 43113 ")
    assert "None" not in line and "python-can configuration" in line
    monkeypatch.setenv("CAN_CHANNEL", "239.74.163.2")
    monkeypatch.setenv("CAN_CONFIG", '{"port": 45001}')
    args = build_parser().parse_args(["run", "wen-5.1"])
    spec = bus_spec(args, announce=True)
    line = capsys.readouterr().err.strip()
    assert spec.port == 45001
    assert line.startswith("transport: udp_multicast:239.74.163.2 port 45001 (python-can")


@pytest.mark.parametrize("realtime", [True, False])
def test_duty_age_is_255_in_the_safe_state(realtime: bool) -> None:
    scn = load_scenario("wen-5.1").with_overrides(duration=1.0)
    node = make_plant_node(scn, CODEC, watchdog_s=2e-3, watchdog_rounds=2)
    node.realtime = realtime
    node.started = True
    age = []
    for k in range(40):
        if k < 10:
            node.on_message(
                CODEC.encode(
                    "PwmDuty",
                    {"duty_a": 0.5, "duty_b": 0.5, "duty_c": 0.5, "enable": 1, "step": k + 1},
                )
            )
        elif not realtime:
            for _ in range(2):
                node.on_duty_timeout()
            node.duties[node.needed_duty()] = (0.5, 0.5, 0.5, True)  # a late duty: still tripped
        frames = node.advance_realtime() if realtime else node.advance_lockstep()
        truth = [
            CODEC.decode(m) for m in frames if m.arbitration_id == CODEC.frame_id("PlantTruth")
        ]
        assert truth[0] is not None
        age.append(int(truth[0].signals["duty_age"]))
    assert node.fault == FAULT_WATCHDOG and 10 <= node.fault_step < 40
    # 255 before the first duty (period 0), the duty's age while duties come, 255 once tripped
    assert age[0] == 255 and max(age[2:10]) <= 1, age
    assert np.all(np.array(age[node.fault_step :]) == 255), age
