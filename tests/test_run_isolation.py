"""Runs that cannot disturb each other, recorder frames that cannot lie (issue 17).

- Every frame the analysis trusts carries an E2E CRC (DBC 2.1 added it to
  ``PlantTruth`` and ``CtrlTelemetry``): a crafted or corrupted recorder frame
  is rejected, counted, and never moves the step unwrapping.
- The recorder frames carry the run's nonce (``run_id``): frames of another run
  are counted (``frames_foreign``) and never scored.
- Two runs on one named bus: each gives the result it gives alone, or refuses
  with one line (exit 2); never a result made of the other run's frames.
- A plant that sees another plant's truth on its bus says so, naming its run.
"""

from __future__ import annotations

import json
import random
import subprocess
import sys
import threading
import time
from pathlib import Path

import can
import numpy as np
import pytest

from bench.captures._read import analyze_capture, read_capture
from bench.nodes._loops import make_plant_node
from bench.scenarios._schema import load_scenario
from bench.wire._codec import Codec
from tests.ports import free_port
from tests.replay_helpers import recorded_run

CODEC = Codec()
ROOT = Path(__file__).resolve().parents[1]
GROUP = "239.74.163.2"


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return recorded_run(tmp_path_factory, "tt-dq")


def _write(frames: list[can.Message], path: Path) -> None:
    with can.Logger(str(path)) as log:
        for m in frames:
            log.on_message_received(m)


def _truth(step: int, run_id: int, *, good_crc: bool) -> bytes:
    msg = CODEC.encode(
        "PlantTruth",
        {"theta_e": 1.0, "w_m": 5.0, "tau_e": 0.0, "tau_L": 0.0, "duty_age": 1, "step": step,
         "run_id": run_id},
    )  # fmt: skip
    data = bytearray(msg.data)
    if not good_crc:
        data[0] ^= 0x5A  # any other byte fails the check
    return bytes(data)


def _with_crafted(run: Path, tmp_path: Path, data: bytes) -> tuple[dict, dict, list[str]]:
    """Metrics of the clean capture and of the same with one PlantTruth frame inserted."""
    frames, problem = read_capture(run / "capture.blf")
    assert problem is None
    clean = analyze_capture(
        run / "capture.blf", out_dir=tmp_path / "clean", echo=lambda _: None, plots=False
    ).metrics
    mid = len(frames) // 2
    t = frames[mid].timestamp
    crafted = can.Message(
        timestamp=t,
        arbitration_id=CODEC.frame_id("PlantTruth"),
        data=data,
        is_fd=True,
        is_extended_id=False,
    )
    path = tmp_path / "crafted" / "capture.blf"
    path.parent.mkdir()
    _write([*frames[:mid], crafted, *frames[mid:]], path)
    (path.parent / "meta.json").write_text((run / "meta.json").read_text())
    lines: list[str] = []
    got = analyze_capture(path, out_dir=path.parent, echo=lines.append, plots=False).metrics
    return clean, got, lines


def _same_scores(a: dict, b: dict) -> None:
    for k in ("steps", "steps_missing", "theta_err_max_deg", "theta_err_rms_deg"):
        assert a[k] == b[k], k


def test_a_crafted_plant_truth_frame_is_rejected_counted_and_moves_no_step(
    run: Path, tmp_path: Path
) -> None:
    """The issue's case: one PlantTruth with a far step (2**31) gave steps_missing 19,999."""
    clean, got, lines = _with_crafted(run, tmp_path, _truth(1 << 31, 7, good_crc=False))
    _same_scores(clean, got)
    assert got["frames_rejected_recorded"] == clean["frames_rejected_recorded"] + 1
    assert got["frames_rejected_by_reason"]["bad_crc"] == 1
    warn = [s for s in lines if "recorded frames failed their check" in s]
    assert len(warn) == 1 and warn[0].startswith("warning: 1 recorded frames"), lines


def test_a_recorder_frame_of_another_run_is_counted_foreign_and_not_scored(
    run: Path, tmp_path: Path
) -> None:
    """A valid frame (CRC right) with another run_id: counted, and no part of the table."""
    own = json.loads((run / "meta.json").read_text())["run_id"]
    other = 1 + (own % 0xFFFF)
    clean, got, lines = _with_crafted(run, tmp_path, _truth(1 << 31, other, good_crc=True))
    _same_scores(clean, got)
    assert clean["frames_foreign"] == 0 and clean["run_id"] == own
    assert got["frames_foreign"] == 1 and got["frames_foreign_by_message"] == {"PlantTruth": 1}
    assert any("1 recorder frames of another run (PlantTruth 1)" in s for s in lines), lines


def test_a_plant_that_sees_another_plant_says_so_once(capsys: pytest.CaptureFixture[str]) -> None:
    node = make_plant_node(load_scenario("wen-5.1"), CODEC)
    node.run_id = 0x1234
    for step in range(3):  # a few (random frames pass the CRC-8 once in 256): not a plant
        data = _truth(step, 0x0BAD, good_crc=True)
        node.on_message(
            can.Message(arbitration_id=CODEC.frame_id("PlantTruth"), data=data, is_fd=True,
                        is_extended_id=False)
        )  # fmt: skip
    assert capsys.readouterr().err == ""
    for step in range(3, 12):
        data = _truth(step, 0x0BAD, good_crc=True)
        node.on_message(
            can.Message(
                arbitration_id=CODEC.frame_id("PlantTruth"),
                data=data,
                is_fd=True,
                is_extended_id=False,
            )
        )
    own = _truth(0, 0x1234, good_crc=True)  # its own frame echoed back: not another plant
    node.on_message(
        can.Message(
            arbitration_id=CODEC.frame_id("PlantTruth"), data=own, is_fd=True, is_extended_id=False
        )
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "plant: a second plant is on this bus: PlantTruth of run 0x0bad (this plant is run "
        "0x1234); its samples reach this run's controller"
    ]
    assert node.report()["other_plants"] == {"0x0bad": 12}


# -- runs on a shared bus ----------------------------------------------------


def _cmd(port: int, out: Path) -> list[str]:
    return [sys.executable, "-m", "bench", "run", "wen-5.1", "-e", "sensored", "--duration",
            "0.2", "-i", "udp_multicast", "--channel", GROUP, "--port", str(port),
            "--out", str(out)]  # fmt: skip


def _rows(out: Path) -> np.ndarray:
    return np.loadtxt(out / "signals.csv", delimiter=",", skiprows=1)


@pytest.fixture(scope="module")
def alone(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("alone")
    subprocess.run(_cmd(free_port(), out), cwd=ROOT, check=True, capture_output=True)
    return out


def test_two_runs_started_together_on_one_port_give_their_result_or_refuse(
    alone: Path, tmp_path: Path
) -> None:
    port = free_port()
    outs = [tmp_path / "a", tmp_path / "b"]
    procs = [
        subprocess.Popen(_cmd(port, o), cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        for o in outs
    ]
    results = [p.communicate(timeout=300) for p in procs]
    ref = _rows(alone)
    for p, out, (_, err_b) in zip(procs, outs, results, strict=True):
        err = err_b.decode()
        assert "Traceback" not in err, err
        if p.returncode == 0:  # it ran undisturbed: the result it gives alone
            # (frames of the other run that came after this one's end are counted, not scored)
            assert np.array_equal(_rows(out), ref, equal_nan=True), err
        else:
            assert p.returncode == 2, err
            last = err.strip().splitlines()[-1]
            assert last.startswith("bench: error: another run"), err
            assert f"port {port}" in last or str(port) in last, last


def test_a_run_refuses_a_bus_that_carries_another_runs_frames(tmp_path: Path) -> None:
    port = free_port()
    bus = can.Bus(interface="udp_multicast", channel=GROUP, port=port, fd=True)
    stop = threading.Event()

    def chatter() -> None:  # another plant, already running
        k = 0
        while not stop.is_set():
            bus.send(can.Message(arbitration_id=CODEC.frame_id("PlantTruth"),
                                 data=_truth(k, 99, good_crc=True), is_fd=True, is_extended_id=False))  # fmt: skip
            k += 1
            time.sleep(0.01)

    th = threading.Thread(target=chatter, daemon=True)
    th.start()
    try:
        p = subprocess.run(_cmd(port, tmp_path / "r"), cwd=ROOT, capture_output=True, timeout=120)
    finally:
        stop.set()
        th.join()
        bus.shutdown()
    err = p.stderr.decode().strip().splitlines()
    assert p.returncode == 2, err
    assert err[-1].startswith("bench: error: another run is on this bus (udp_multicast"), err
    assert "refusing to share it" in err[-1]
    assert not (tmp_path / "r" / "plant.log").exists()  # no node was started


def test_random_fd_frames_with_the_dbc_ids_leave_the_scored_rows_unchanged(
    alone: Path, tmp_path: Path
) -> None:
    """Random FD frames with the DBC's identifiers poured at a running bench.

    Classic-frame identifiers get FD lengths above 8 (a length check rejects
    them; an 8-byte random frame would pass the 8-bit CRC once in 256, the
    CRC's known limit); the recorder frames get their own length, 16, so
    the E2E check and the run_id are what keep them out of the table.
    """
    port = free_port()
    out = tmp_path / "poured"
    proc = subprocess.Popen(_cmd(port, out), cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)  # fmt: skip
    bus = can.Bus(interface="udp_multicast", channel=GROUP, port=port, fd=True)
    rng = random.Random(17)
    ids = [CODEC.frame_id(n) for n in CODEC.names]
    recorder_ids = {CODEC.frame_id("PlantTruth"), CODEC.frame_id("CtrlTelemetry")}
    sent = 0
    try:
        t0 = time.monotonic()
        started = False
        while not started:  # pour only once the run is on (else it rightly refuses the bus)
            assert time.monotonic() - t0 < 120, "the run did not start"
            m = bus.recv(0.5)
            started = m is not None and m.arbitration_id == CODEC.frame_id("PhaseSamples")
        while proc.poll() is None:
            fid = rng.choice(ids)
            n = 16 if fid in recorder_ids else rng.choice((12, 16, 20, 24, 32, 48, 64))
            data = bytes(rng.getrandbits(8) for _ in range(n))
            bus.send(can.Message(arbitration_id=fid, data=data, is_fd=True, is_extended_id=False))
            sent += 1
            if sent % 20 == 0:
                time.sleep(0.001)
        _, err_b = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
        bus.shutdown()
    err = err_b.decode()
    assert proc.returncode == 0, err
    assert sent > 1000
    assert np.array_equal(_rows(out), _rows(alone), equal_nan=True)
    m = json.loads((out / "metrics.json").read_text())
    assert m["steps_missing"] == 0 and m["frames_out_of_order"] == 0
    assert m["frames_rejected_recorded"] > 0
    assert "recorded frames failed their check" in err
