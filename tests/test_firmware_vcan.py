"""The reference C controller closes a sensored FOC loop under ``bench run --controller external``.

Two processes on one SocketCAN bus: ``firmware/ref_controller`` (C, raw
AF_CAN sockets with CAN FD, built from the C code `bench codegen` generates)
and ``bench run SCENARIO --controller external``, which starts the plant,
paces the scenario's commands, records every frame and scores the run, as a
user puts a real controller under test (docs/HARDWARE.md, "Connect a real
drive controller").
"""

from __future__ import annotations

import json
import select
import subprocess
import sys
import time
from pathlib import Path

import can
import numpy as np
import pytest

from bench.runs._analysis import analyze_frames
from bench.runs._run import build_native_libraries
from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import get_preset, n_steps, sample_period
from bench.wire._codec import Codec
from tests.conftest import require_vcan
from tests.test_external_controller import LSB_DEG, encoder_err_bound_deg
from tests.test_firmware import CC, MAKE, build_firmware

pytestmark = [
    pytest.mark.socketcan,
    pytest.mark.skipif(CC is None or MAKE is None, reason="needs a C compiler and make"),
]

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = Path(__file__).parent / "data" / "firmware-100rpm.toml"
#: Upper bound of the whole closed-loop run [s]; UML closes about 1000 periods/s.
RUN_TIMEOUT_S = 240.0
READY_TIMEOUT_S = 120.0


def _wait_ready(proc: subprocess.Popen[str], what: str) -> None:
    assert proc.stdout is not None
    deadline = time.monotonic() + READY_TIMEOUT_S
    while time.monotonic() < deadline:
        readable, _, _ = select.select([proc.stdout], [], [], 1.0)
        if readable:
            line = proc.stdout.readline()
            if line.strip() == "READY":
                return
            if line == "" and proc.poll() is not None:
                pytest.fail(f"{what} exited before it was ready (exit {proc.returncode})")
    pytest.fail(f"{what} not ready within {READY_TIMEOUT_S} s")


@pytest.fixture(scope="module")
def firmware_run(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """One closed-loop run of the C controller; returns the capture's table and reports."""
    require_vcan("vcan0")
    out = tmp_path_factory.mktemp("fwrun")
    exe = build_firmware(out / "build")
    # the bench's native libraries built now, not while the controller waits for frames
    # (a first build inside User-Mode Linux can outlast its idle timeout)
    build_native_libraries()
    codec = Codec()
    scn = load_scenario(str(SCENARIO))
    n = n_steps(scn)
    run_dir = out / "run"
    ctrl = subprocess.Popen(
        [str(exe), "-i", "vcan0", "-t", str(RUN_TIMEOUT_S)],
        stdout=subprocess.PIPE,
        stderr=(out / "ctrl.log").open("w"),
        text=True,
    )
    try:
        _wait_ready(ctrl, "ref_controller")
        run = subprocess.run(
            [sys.executable, "-m", "bench", "run", str(SCENARIO), "--controller", "external",
             "--dut-name", "ref_controller", "--dut-timeout", str(READY_TIMEOUT_S),
             "--interface", "socketcan", "--channel", "vcan0", "--out", str(run_dir), "-q"],
            cwd=ROOT, capture_output=True, text=True, timeout=RUN_TIMEOUT_S,
        )  # fmt: skip
        ctrl_out, _ = ctrl.communicate(timeout=60)
    finally:
        if ctrl.poll() is None:
            ctrl.kill()
            ctrl.wait()
    assert run.returncode == 0, run.stderr[-3000:]
    assert ctrl.returncode == 0, ctrl_out + (out / "ctrl.log").read_text()[-2000:]
    frames = list(can.LogReader(str(run_dir / "capture.blf")))
    cap = analyze_frames(frames, codec, T_s=sample_period(scn), n_p=get_preset(scn).motor.n_p)
    return {
        "scn": scn,
        "n": n,
        "cap": cap,
        "frames": frames,
        "plant": json.loads((run_dir / "plant.json").read_text()),
        "metrics": json.loads((run_dir / "metrics.json").read_text()),
        "meta": json.loads((run_dir / "meta.json").read_text()),
        "ctrl_summary": ctrl_out.strip().splitlines()[-1],
    }


def test_c_controller_reaches_the_commanded_speed(firmware_run: dict) -> None:
    t = firmware_run["cap"].table
    scn = firmware_run["scn"]
    assert len(t["step"]) == firmware_run["n"] + 1  # steps 0..n, none missing
    steady = t["t"] >= scn.score_from_s
    w = t["w_m_rpm"][steady]
    err = t["theta_err_deg"]
    print(  # shown by pytest -rP: the measured numbers
        f"C controller: speed {np.mean(w):.3f} rpm (min {np.min(w):.3f}, max {np.max(w):.3f}), "
        f"position error max |{np.max(np.abs(err)):.4f}| deg, i_d mean {np.mean(t['i_d'][steady]):.4f} A"
    )
    assert np.mean(w) == pytest.approx(100.0, abs=2.0)
    assert np.max(np.abs(w - 100.0)) < 5.0
    # field orientation: no d current, q current only for friction and the ramp
    assert abs(np.mean(t["i_d"][steady])) < 0.05
    assert np.max(np.abs(t["i_q"][steady])) < 0.5
    # the ramp needs torque: i_q positive while accelerating
    accel = (t["t"] > 0.005) & (t["t"] < 0.05)
    assert np.mean(t["i_q"][accel]) > 0.1
    # enabled from the start command (step 0) until the stop command (step n)
    assert np.all(t["enable"][:-1] == 1.0) and t["enable"][-1] == 0.0


def test_c_controller_logs_the_sensored_angle(firmware_run: dict) -> None:
    """theta_hat is the encoder's angle (PositionSensor), within its quantisation.

    The plant's default sensor for a controller under test: 65536 counts, every
    period, no delay; the controller adds half a count to the floored reading, so
    |theta_hat - theta_e| <= n_p q / 2 plus one LSB of the wire's two roundings
    (bound of tests/test_external_controller.py).  Above one LSB somewhere: it is
    not the truth (PlantTruth), which the controller does not read.
    """
    t = firmware_run["cap"].table
    n_p = get_preset(firmware_run["scn"]).motor.n_p
    err = np.max(np.abs(t["theta_err_deg"]))
    assert 1.5 * LSB_DEG < err <= encoder_err_bound_deg(n_p) + 1e-9
    assert np.all(t["mode"][:-1] == 3) and t["mode"][-1] == 0  # run, then stopped


def test_plant_accepted_every_c_frame(firmware_run: dict) -> None:
    """Every PwmDuty of the C controller passed the plant's CRC, length and range checks."""
    r = firmware_run["plant"]
    assert r["steps"] == firmware_run["n"]
    assert r["frames_rejected"] == 0, r["reject_reasons"]
    assert firmware_run["cap"].frames_rejected == 0
    duties = [f for f in firmware_run["frames"] if f.arbitration_id == 0x010]
    tele = [f for f in firmware_run["frames"] if f.arbitration_id == 0x101]
    assert len(duties) >= firmware_run["n"] and not any(f.is_fd for f in duties)
    assert len(tele) >= firmware_run["n"] and all(
        f.is_fd and len(f.data) == Codec().length("CtrlTelemetry") for f in tele
    )
    assert firmware_run["ctrl_summary"].startswith(f"ref_controller: {firmware_run['n'] + 1} steps")
    assert " 0 rejected" in firmware_run["ctrl_summary"]


def test_the_run_is_scored_as_an_external_controllers(firmware_run: dict) -> None:
    """bench run wrote the run's files, with the controller marked external and named."""
    m, meta = firmware_run["metrics"], firmware_run["meta"]
    assert meta["controller"] == "external" and meta["controller_name"] == "ref_controller"
    assert m["steps_missing"] == 0 and m["plant_fault"] == "none" and m["frames_rejected"] == 0
    assert (
        max(abs(m["theta_err_max_deg"]), abs(m["theta_err_min_deg"]))
        <= encoder_err_bound_deg(get_preset(firmware_run["scn"]).motor.n_p) + 1e-9
    )
