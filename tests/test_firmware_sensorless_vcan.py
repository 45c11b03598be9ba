"""The firmware built with the bench's controller gives the in-process run's trace on vcan.

``firmware/ref_controller`` built sensorless (``make SCENARIO=... ESTIMATOR=...``: the
core initialised by the ``bench_controller.h`` that ``bench codegen --estimator``
writes) runs as the controller under test of ``bench run SCENARIO --controller
external`` on vcan0, in lockstep, with tt-dq and with square-wave. Its run's table
(every column of :data:`bench.runs._analysis.COLUMNS`, decoded from the capture) is the
table of the bench's own controller run in process on the same scenario
(:func:`bench.nodes._loops.run_inprocess`), bit for bit: tolerance 0, as the same core
with the same initial values and the same samples computes the same doubles, and both
sides encode them with the bench codec's rule. Left out: the references in force
(``w_ref_rpm``, ``load_ref_nm``), which the table takes from the ``BenchCommand`` frames
in the capture, the bench's own frames, not the controller's (the external run's
capture on vcan has none; the controller's answer to them is in every other column).
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

import can
import numpy as np
import pytest

from bench.nodes._loops import run_inprocess
from bench.runs._analysis import COLUMNS, analyze_frames
from bench.runs._run import build_native_libraries
from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import get_preset, n_steps, sample_period
from bench.wire._codec import Codec
from tests.conftest import require_vcan
from tests.test_firmware import CC, FIRMWARE, MAKE
from tests.test_firmware_vcan import READY_TIMEOUT_S, RUN_TIMEOUT_S, _wait_ready

pytestmark = [
    pytest.mark.socketcan,
    pytest.mark.skipif(CC is None or MAKE is None, reason="needs a C compiler and make"),
]

ROOT = Path(__file__).resolve().parents[1]
#: the table's columns the bench's commands fill (from the capture's BenchCommand frames)
COMMAND_COLUMNS = ("w_ref_rpm", "load_ref_nm")
SCENARIO = Path(__file__).parent / "data" / "firmware-sensorless.toml"


def _build(out: Path, estimator: str) -> Path:
    res = subprocess.run(
        [MAKE or "make", "-s", "-C", str(FIRMWARE), f"BUILD={out}", f"PYTHON={sys.executable}",
         f"SCENARIO={SCENARIO}", f"ESTIMATOR={estimator}"],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    return out / "ref_controller"


def _table(frames: Sequence[can.Message]) -> dict[str, np.ndarray]:
    scn = load_scenario(str(SCENARIO))
    cap = analyze_frames(frames, Codec(), T_s=sample_period(scn), n_p=get_preset(scn).motor.n_p)
    return cap.table


@pytest.mark.parametrize("estimator", ["tt-dq", "square-wave"])
def test_sensorless_firmware_gives_the_inprocess_trace(tmp_path: Path, estimator: str) -> None:
    require_vcan("vcan0")
    exe = _build(tmp_path / "build", estimator)
    scn = load_scenario(str(SCENARIO))
    ref = _table(run_inprocess(scn, estimator, Codec()))
    # the bench's native libraries built now, not while the firmware waits for frames
    build_native_libraries()
    run_dir = tmp_path / "run"
    ctrl = subprocess.Popen(
        [str(exe), "-i", "vcan0", "-t", str(RUN_TIMEOUT_S)],
        stdout=subprocess.PIPE,
        stderr=(tmp_path / "ctrl.log").open("w"),
        text=True,
    )
    try:
        _wait_ready(ctrl, "ref_controller")
        run = subprocess.run(
            [sys.executable, "-m", "bench", "run", str(SCENARIO),
             "--controller", "external", "--dut-name", f"ref_controller-{estimator}",
             "--dut-timeout", str(READY_TIMEOUT_S), "--interface", "socketcan",
             "--channel", "vcan0", "--out", str(run_dir), "-q"],
            cwd=ROOT, capture_output=True, text=True, timeout=RUN_TIMEOUT_S,
        )  # fmt: skip
        assert run.returncode == 0, run.stderr[-3000:]
        ctrl_out, _ = ctrl.communicate(timeout=60)
    finally:
        if ctrl.poll() is None:
            ctrl.kill()
            ctrl.wait()
    assert ctrl.returncode == 0, ctrl_out + (tmp_path / "ctrl.log").read_text()[-2000:]
    assert f"ref_controller: {estimator}, sensorless" in ctrl_out
    n = n_steps(scn)
    ext = _table(list(can.LogReader(str(run_dir / "capture.blf"))))
    assert len(ext["step"]) == len(ref["step"]) == n + 1
    compared = [name for name, _ in COLUMNS if name not in COMMAND_COLUMNS]
    for name in compared:
        np.testing.assert_array_equal(ext[name], ref[name], err_msg=name)
    # the run is the sensorless start-up and the speed loop, not a trace of rest
    assert {1.0, 2.0, 3.0} <= set(ref["mode"][np.isfinite(ref["mode"])].tolist())
    assert np.nanmax(ref["w_m_rpm"]) > 50.0
    print(  # shown by pytest -rP
        f"{estimator} on vcan: {n + 1} periods equal to the in-process run in "
        f"{len(compared)} columns; max |theta_err| {np.nanmax(np.abs(ext['theta_err_deg'])):.3f} deg"
    )
