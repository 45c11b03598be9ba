"""The firmware built with the bench's controller gives the in-process run's trace on vcan.

``firmware/ref_controller`` built sensorless (``make SCENARIO=... ESTIMATOR=...``: the
core initialised by the ``bench_controller.h`` that ``bench codegen --estimator``
writes) runs as the controller under test of ``bench run SCENARIO --controller
external`` on vcan0, in lockstep, with the sensorless estimators of :data:`ON_VCAN`
(every one of :data:`tests.test_firmware_sensorless.SENSORLESS` is checked without CAN). The single estimators run
``firmware-sensorless.toml`` (the start-up and a ramp to 100 rpm, 3000 periods); the
hybrids run ``firmware-hybrid.toml`` (the same start-up, then a ramp to 1150 rpm, 4200
periods), whose speed crosses their whole transition band, injection below it and flux
observer above it, which the test asserts from the trace. Its run's table
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

import shutil
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import can
import numpy as np
import pytest

from bench.nodes._controller_node import controller_design
from bench.nodes._loops import SAMPLE_TIMEOUT_S, run_inprocess
from bench.runs._analysis import COLUMNS, analyze_frames
from bench.runs._run import build_native_libraries
from bench.scenarios._schema import Scenario, load_scenario
from bench.scenarios._setup import build_controller, get_preset, n_steps, sample_period
from bench.wire._codec import Codec
from controller import estimator_spec
from tests.conftest import require_vcan
from tests.test_firmware import CC, FIRMWARE, MAKE
from tests.test_firmware_sensorless import SENSORLESS
from tests.test_firmware_vcan import READY_TIMEOUT_S, RUN_TIMEOUT_S, _wait_ready

pytestmark = [
    pytest.mark.socketcan,
    pytest.mark.skipif(CC is None or MAKE is None, reason="needs a C compiler and make"),
]

ROOT = Path(__file__).resolve().parents[1]
#: the table's columns the bench's commands fill (from the capture's BenchCommand frames)
COMMAND_COLUMNS = ("w_ref_rpm", "load_ref_nm")
SCENARIO = Path(__file__).parent / "data" / "firmware-sensorless.toml"
#: the hybrids' run: the same start-up, then through their band (its header says why)
HYBRID_SCENARIO = Path(__file__).parent / "data" / "firmware-hybrid.toml"


def _scenario_of(estimator: str) -> Path:
    return HYBRID_SCENARIO if estimator_spec(estimator).speed_band else SCENARIO


@pytest.fixture(scope="module")
def build_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One BUILD for every estimator: the DBC's code and the core are compiled once
    (firmware/Makefile's objects), each build compiles only the program again."""
    return tmp_path_factory.mktemp("firmware")


def _build(build: Path, estimator: str, out: Path) -> Path:
    """``make SCENARIO=... ESTIMATOR=...`` into ``build``; the program copied to ``out``.
    ``SAMPLE_TIMEOUT_S`` is the value the Makefile asks the bench for, given here to spare
    it a Python start-up per build."""
    res = subprocess.run(
        [MAKE or "make", "-s", "-C", str(FIRMWARE), f"BUILD={build}", f"PYTHON={sys.executable}",
         f"SCENARIO={_scenario_of(estimator)}", f"ESTIMATOR={estimator}",
         f"SAMPLE_TIMEOUT_S={float(SAMPLE_TIMEOUT_S)!r}"],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    return Path(shutil.copy2(build / "ref_controller", out))


def _table(scn: Scenario, frames: Sequence[can.Message]) -> dict[str, np.ndarray]:
    cap = analyze_frames(frames, Codec(), T_s=sample_period(scn), n_p=get_preset(scn).motor.n_p)
    return cap.table


def _assert_crosses_band(scn: Scenario, estimator: str, table: dict[str, np.ndarray]) -> None:
    """The run's true speed, in the run mode, goes from below the hybrid's band on the
    true speed (:attr:`controller.TransitionBand.edges`: the injection estimator alone)
    to above it (the flux observer alone): the hand-over ran in the compared run."""
    edges = controller_design(build_controller(scn, estimator))["band_edges"]
    assert edges is not None
    lo, hi = edges  # electrical rad/s
    w_e = table["w_m_rpm"] * (2.0 * np.pi / 60.0) * get_preset(scn).motor.n_p
    run = np.flatnonzero(table["mode"] == 3.0)
    below = run[w_e[run] < lo]
    above = run[w_e[run] > hi]
    assert below.size and above.size, (lo, hi, np.nanmax(w_e))
    assert below[0] < above[0] and above[-1] == run[-1]  # and stays above to the end


#: The estimators run on vcan in CI: the papers' two (tt-dq, square-wave), the hybrids (the
#: hand-over band), and the two with a demodulation of their own outside tt-dq's family
#: (self-demod, epf). tt-ab, sfhf and square-wave-nocic passed here too (9 of 9 inside
#: User-Mode Linux, about a minute each there) and are left out of CI for its time; every
#: one of :data:`SENSORLESS` is checked without CAN, structs and 2500 periods, in
#: tests/test_firmware_sensorless.py.
ON_VCAN = [
    e
    for e in SENSORLESS
    if e in ("tt-dq", "square-wave", "self-demod", "epf") or estimator_spec(e).speed_band
]


@pytest.mark.parametrize("estimator", ON_VCAN)
def test_sensorless_firmware_gives_the_inprocess_trace(
    tmp_path: Path, build_dir: Path, estimator: str
) -> None:
    require_vcan("vcan0")
    scenario = _scenario_of(estimator)
    t0 = time.monotonic()
    exe = _build(build_dir, estimator, tmp_path / "ref_controller")
    t1 = time.monotonic()
    scn = load_scenario(str(scenario))
    ref = _table(scn, run_inprocess(scn, estimator, Codec()))
    # the bench's native libraries built now, not while the firmware waits for frames
    build_native_libraries()
    t2 = time.monotonic()
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
            [sys.executable, "-m", "bench", "run", str(scenario),
             "--controller", "external", "--dut-name", f"ref_controller-{estimator}",
             "--dut-timeout", str(READY_TIMEOUT_S), "--interface", "socketcan",
             "--channel", "vcan0", "--out", str(run_dir), "-q"],
            cwd=ROOT, capture_output=True, text=True, timeout=RUN_TIMEOUT_S,
        )  # fmt: skip
        assert run.returncode == 0, run.stderr[-3000:]
        ctrl_out, _ = ctrl.communicate(timeout=60)
        t3 = time.monotonic()
    finally:
        if ctrl.poll() is None:
            ctrl.kill()
            ctrl.wait()
    assert ctrl.returncode == 0, ctrl_out + (tmp_path / "ctrl.log").read_text()[-2000:]
    assert f"ref_controller: {estimator}, sensorless" in ctrl_out
    n = n_steps(scn)
    ext = _table(scn, list(can.LogReader(str(run_dir / "capture.blf"))))
    assert len(ext["step"]) == len(ref["step"]) == n + 1
    compared = [name for name, _ in COLUMNS if name not in COMMAND_COLUMNS]
    for name in compared:
        np.testing.assert_array_equal(ext[name], ref[name], err_msg=name)
    # the run is the sensorless start-up and the speed loop, not a trace of rest
    assert {1.0, 2.0, 3.0} <= set(ref["mode"][np.isfinite(ref["mode"])].tolist())
    assert np.nanmax(ref["w_m_rpm"]) > 50.0
    if estimator_spec(estimator).speed_band:
        _assert_crosses_band(scn, estimator, ext)
    print(  # shown by pytest -rP
        f"{estimator} on vcan: {n + 1} periods equal to the in-process run in "
        f"{len(compared)} columns; max |theta_err| {np.nanmax(np.abs(ext['theta_err_deg'])):.3f} deg; "
        f"firmware build {t1 - t0:.1f} s, in-process run {t2 - t1:.1f} s, vcan run {t3 - t2:.1f} s"
    )
