"""``bench analyze`` on captures converted to CSV and TRC by python-can's own writers.

The recorded run (``replay_helpers``) mixes classic CAN frames
(``PhaseSamples``, ``PwmDuty``, ``BenchCommand``, ``PlantStatus``: 8 bytes)
and CAN FD frames (``PlantTruth``: 16 bytes, ``CtrlTelemetry``: 12 bytes).

- CSV (``can.CSVWriter``): keeps every frame and its bytes (base64), drops
  the FD flag and the channel; the bench decodes by ID and length, so the
  analysis gives the live run's metrics exactly.
- TRC (``can.TRCWriter``, python-can 4.x, file version 2.1): does not write
  CAN FD frames; it skips each one with a logged warning ("Logging CAN FD is
  not implemented").  The TRC of a bench run therefore holds no truth and no
  telemetry, and no step can be scored: ``bench analyze`` must say so in
  one line (with the per-message counts, so the cause is visible) and exit
  2, without a traceback.  The classic frames it does hold are read in full
  (on channel 2: the writer numbers a frame's channel ``n`` as ``n + 1``, so
  the bench's bus tag does not survive TRC either).
"""

from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import can
import numpy as np
import pytest

from bench._errors import CaptureError
from bench.captures._read import (
    analyze_capture,
    read_capture,
)
from bench.cli import main
from bench.runs._analysis import read_csv
from bench.wire._codec import Codec
from tests.replay_helpers import POSITION_SPEED, recorded_run

CODEC = Codec()

STEPS = 2001  # 0.2 s at 10 kHz, steps 0 .. 2000


def quiet(_: str) -> None:
    pass


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return recorded_run(tmp_path_factory, "sensored")


def convert(run: Path, folder: Path, suffix: str) -> Path:
    """The run's capture written by python-can's writer for ``suffix``, with its meta.json."""
    folder.mkdir()
    shutil.copy(run / "meta.json", folder / "meta.json")
    out = folder / f"capture{suffix}"
    with can.LogReader(str(run / "capture.blf")) as r, can.Logger(str(out)) as w:
        for m in r:
            w.on_message_received(m)
    return out


def test_csv_capture_gives_the_live_runs_metrics(run: Path, tmp_path: Path) -> None:
    live = json.loads((run / "metrics.json").read_text())
    csv = convert(run, tmp_path / "csv", ".csv")
    frames, problem = read_capture(csv)
    assert problem is None
    blf = list(can.LogReader(str(run / "capture.blf")))
    assert len(frames) == len(blf)
    # the bytes survive; the FD flag does not (the CSV format has no column for it)
    assert [bytes(m.data) for m in frames] == [bytes(m.data) for m in blf]
    assert any(m.is_fd for m in blf) and not any(m.is_fd for m in frames)
    res = analyze_capture(csv, out_dir=tmp_path / "out", echo=quiet, plots=False)
    got = json.loads((tmp_path / "out" / "metrics.json").read_text())
    for key in POSITION_SPEED:
        assert got[key] == live[key], key
    assert res.metrics["steps"] == STEPS
    assert got["frames_recorded"] == live["frames_recorded"]
    assert got["frames_rejected"] == 0
    a, b = read_csv(str(run / "signals.csv")), read_csv(str(tmp_path / "out" / "signals.csv"))
    for col in ("theta_e", "theta_hat", "i_a", "d_a", "w_ref_rpm"):
        np.testing.assert_array_equal(a[col], b[col], err_msg=col)


def test_bench_analyze_cli_reads_csv(
    run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    live = json.loads((run / "metrics.json").read_text())
    csv = convert(run, tmp_path / "csv", ".csv")
    rc = main(["analyze", str(csv), "--out", str(tmp_path / "out"), "--no-plots"])
    assert rc == 0, capsys.readouterr()
    got = json.loads((tmp_path / "out" / "metrics.json").read_text())
    for key in POSITION_SPEED:
        assert got[key] == live[key], key


@pytest.fixture(scope="module")
def trc(run: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[str]]:
    """The TRC conversion and the warnings python-can's writer logged."""
    records: list[str] = []

    class Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            records.append(record.getMessage())

    log = logging.getLogger("can.io.trc")
    h = Keep(logging.WARNING)
    log.addHandler(h)
    try:
        path = convert(run, tmp_path_factory.mktemp("trc") / "c", ".trc")
    finally:
        log.removeHandler(h)
    return path, records


def test_trc_writer_drops_the_fd_frames(run: Path, trc: tuple[Path, list[str]]) -> None:
    path, warnings = trc
    blf = list(can.LogReader(str(run / "capture.blf")))
    fd = [m for m in blf if m.is_fd]
    # PlantTruth and CtrlTelemetry of every step (the controller sends its telemetry
    # again when its command acknowledgement moves: a few more)
    decoded = [(m.arbitration_id, CODEC.decode(m)) for m in fd]
    steps = {(i, d.signals["step"]) for i, d in decoded if d is not None}
    assert len(steps) == 2 * STEPS and len(fd) >= 2 * STEPS
    assert len(warnings) == len(fd)
    assert all("CAN FD is not implemented" in w for w in warnings)
    frames, problem = read_capture(path)
    assert problem is None  # a complete file: the frames were never written
    assert {m.channel for m in blf} == {1} and {m.channel for m in frames} == {2}
    classic = [m for m in blf if not m.is_fd]
    assert [(m.arbitration_id, bytes(m.data)) for m in frames] == [
        (m.arbitration_id, bytes(m.data)) for m in classic
    ]


def test_analyze_of_a_trc_without_fd_frames_reports_clearly(
    trc: tuple[Path, list[str]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path, _ = trc
    with pytest.raises(CaptureError) as exc:
        analyze_capture(path, out_dir=tmp_path / "api", echo=quiet, plots=False)
    msg = str(exc.value)
    assert str(path) in msg
    assert "no step has samples and truth together" in msg
    # the counts show what is missing: every sample and duty, no truth, no telemetry
    for part in ("PhaseSamples 2001", "PlantTruth 0", "CtrlTelemetry 0", "PwmDuty 2001"):
        assert part in msg, part
    # the CLI: one line naming the file, exit 2, no traceback, no half-written run
    capsys.readouterr()
    rc = main(["analyze", str(path), "--out", str(tmp_path / "cli"), "--no-plots"])
    err = capsys.readouterr().err
    assert rc == 2
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.startswith("bench: error:")]
    assert len(lines) == 1 and str(path) in lines[0] and "PlantTruth 0" in lines[0]
    assert not (tmp_path / "cli" / "metrics.json").exists()
