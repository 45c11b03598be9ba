"""Incomplete and unreadable captures, option mistakes, and a replay that falls behind.

python-can's readers stop silently at a truncated end: a BLF cut short
loses its tail without an error, a text log cut mid-line parses the cut
line into a frame with missing bytes.  The bench checks a capture against
what its format promises and says so (stderr and ``metrics.json``), keeping
every frame that was read in full.
"""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import can
import numpy as np
import pytest

from bench.captures._read import (
    analyze_capture,
    read_capture,
)
from bench.captures._replay import (
    ReplayResult,
    replay_frames,
)
from bench.captures._rerun import rerun_capture
from bench.cli import main
from bench.wire._codec import Codec
from tests.replay_helpers import recorded_run

CODEC = Codec()


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return recorded_run(tmp_path_factory, "tt-dq")


@pytest.fixture(scope="module")
def frames(run: Path) -> list[can.Message]:
    fr, problem = read_capture(run / "capture.blf")
    assert problem is None  # a complete capture is not flagged
    return fr


def same(a: list[can.Message], b: list[can.Message]) -> bool:
    return [(m.arbitration_id, bytes(m.data), m.timestamp) for m in a] == [
        (m.arbitration_id, bytes(m.data), m.timestamp) for m in b
    ]


def test_truncated_blf_is_reported_and_what_was_read_is_kept(
    run: Path, frames: list[can.Message], tmp_path: Path
) -> None:
    path = tmp_path / "capture.blf"
    path.write_bytes((run / "capture.blf").read_bytes()[:5000])
    shutil.copy(run / "meta.json", tmp_path / "meta.json")
    got, problem = read_capture(path)
    assert problem is not None and "truncated BLF: 5000 of the" in problem
    assert f"{len(got)} of its {len(frames)} frames read" in problem
    assert 0 < len(got) < len(frames) and same(got, frames[: len(got)])
    lines: list[str] = []
    res = analyze_capture(path, out_dir=tmp_path / "a", echo=lines.append, plots=False)
    warn = [s for s in lines if s.startswith("warning:")]
    assert len(warn) == 1 and "truncated BLF" in warn[0] and str(path) in warn[0]
    saved = json.loads((tmp_path / "a" / "metrics.json").read_text())
    assert saved["capture_truncated"] is True and saved["capture_read_error"] == problem
    assert res.metrics["frames_recorded"] == len(got)
    rr = rerun_capture(path, "tt-dq", out_dir=tmp_path / "r", echo=lines.append, plots=False)
    assert rr.metrics["capture_truncated"] is True
    assert json.loads((tmp_path / "r" / "metrics.json").read_text())["capture_truncated"] is True


def test_complete_capture_has_no_truncation_field(run: Path, tmp_path: Path) -> None:
    res = analyze_capture(run / "capture.blf", out_dir=tmp_path, echo=lambda _: None, plots=False)
    assert "capture_truncated" not in res.metrics
    assert "capture_truncated" not in json.loads((tmp_path / "metrics.json").read_text())


def test_blf_whose_writer_never_closed_it_is_flagged(run: Path, tmp_path: Path) -> None:
    """A run killed before its logger stopped leaves the header python-can wrote
    first: file size of the bare header and no object count."""
    from can.io.blf import FILE_HEADER_SIZE, FILE_HEADER_STRUCT

    data = bytearray((run / "capture.blf").read_bytes())
    header = list(FILE_HEADER_STRUCT.unpack_from(data))
    header[10], header[12] = FILE_HEADER_SIZE, 0
    FILE_HEADER_STRUCT.pack_into(data, 0, *header)
    path = tmp_path / "open.blf"
    path.write_bytes(bytes(data))
    got, problem = read_capture(path)
    assert problem is not None and "never completed" in problem
    assert len(got) > 1000


def test_truncated_text_logs_drop_the_cut_line_and_say_so(
    frames: list[can.Message], tmp_path: Path
) -> None:
    part = frames[:400]
    for suffix in (".log", ".asc"):
        full = tmp_path / f"c{suffix}"
        with can.Logger(str(full)) as w:
            for m in part:
                w.on_message_received(m)
        whole, problem = read_capture(full)
        assert problem is None and len(whole) == len(part)
        data = full.read_bytes()
        # cut in the middle of a frame line, inside its data bytes
        lines = data.split(b"\n")
        k = next(i for i in range(len(lines) // 2, len(lines)) if len(lines[i]) > 30)
        cut_at = sum(len(x) + 1 for x in lines[:k]) + len(lines[k]) - 5
        cut = tmp_path / f"cut{suffix}"
        cut.write_bytes(data[:cut_at])
        got, problem = read_capture(cut)
        assert problem is not None and "last line is cut short" in problem, suffix
        if suffix == ".asc":
            assert "End TriggerBlock" in problem
        # every frame read is a whole frame of the capture, in order; the cut one is gone
        assert 0 < len(got) < len(whole)
        for a, b in zip(got, whole, strict=False):
            assert (a.arbitration_id, bytes(a.data)) == (b.arbitration_id, bytes(b.data))
        # an ASC cut at a line end still lacks its footer
        if suffix == ".asc":
            at_line = tmp_path / "line.asc"
            at_line.write_bytes(data[: sum(len(x) + 1 for x in lines[:k])])
            got2, problem2 = read_capture(at_line)
            assert problem2 is not None and "End TriggerBlock" in problem2
            assert "cut short (no line end)" not in problem2
            assert len(got2) == len(got)


def test_cli_analyze_of_a_truncated_log_warns_and_exits_0(
    frames: list[can.Message], run: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    full = tmp_path / "c.log"
    with can.Logger(str(full)) as w:
        for m in frames:
            w.on_message_received(m)
    data = full.read_bytes()
    (tmp_path / "cut").mkdir()
    cut = tmp_path / "cut" / "capture.log"
    cut.write_bytes(data[: len(data) // 2 + 7])
    shutil.copy(run / "meta.json", tmp_path / "cut" / "meta.json")
    rc = main(["analyze", str(cut), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.splitlines()
    assert rc == 0
    warn = [s for s in err if s.startswith("warning:")]
    cut_short = [s for s in warn if "cut short" in s]
    assert len(cut_short) == 1 and "capture.log" in cut_short[0]
    # besides: the last periods before the cut have their samples and truth, not their
    # telemetry (the plant's next sample goes out before the controller's answer comes)
    assert all(s in cut_short or "have no CtrlTelemetry" in s for s in warn), warn
    saved = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert saved["capture_truncated"] is True
    # how many periods lack their telemetry depends on how the frames interleaved on the
    # bus (a busy host delays the controller's answer further): the cut capture must say
    # exactly what a complete capture of the frames it kept says
    kept, _ = read_capture(cut)
    (tmp_path / "prefix").mkdir()
    prefix = tmp_path / "prefix" / "capture.log"
    with can.Logger(str(prefix)) as w:
        for m in kept:
            w.on_message_received(m)
    shutil.copy(run / "meta.json", tmp_path / "prefix" / "meta.json")
    ref = analyze_capture(prefix, out_dir=tmp_path / "p", echo=lambda _: None, plots=False)
    assert "capture_truncated" not in ref.metrics
    assert saved["steps_without_telemetry"] == ref.metrics["steps_without_telemetry"]
    assert saved["frames_recorded"] == ref.metrics["frames_recorded"] == len(kept)


def test_garbage_blf_is_named_as_not_a_blf(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    short = tmp_path / "short.blf"
    short.write_bytes(b"garbage garbage\n")
    body = tmp_path / "body.blf"  # a valid header, then no BLF object
    src = tmp_path / "ok.blf"
    with can.Logger(str(src)) as w:
        w.on_message_received(can.Message(arbitration_id=1, data=b"\x01"))
    body.write_bytes(src.read_bytes()[:144] + b"\x00garbage" * 50)
    for path in (short, body):
        rc = main(["analyze", str(path), "--scenario", "wen-5.1"])
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 2 and len(err) == 1, err
        assert str(path) in err[0] and "not a readable BLF capture" in err[0], err
        assert "unpack requires" not in err[0]


def test_replay_option_mistakes_come_first_and_name_the_option(
    frames: list[can.Message], tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    missing = str(tmp_path / "missing.blf")
    # the options are checked before the capture is read (the file does not exist)
    for extra, word in (
        (["--speed", "0"], "--speed"),
        (["--speed", "nan"], "--speed"),
        (["--loop", "-1"], "--loop"),
        (["--max-gap", "0"], "--max-gap"),
        (["--map", "zz=0x10"], "--map zz=0x10"),
        (["--map", "0x10=0x2000000000"], "--map 0x10=0x2000000000"),
        (["--id", "0x10,what"], "--id"),
        (["--exclude-id", "what"], "--exclude-id"),
    ):
        rc = main(["replay", missing, "--interface", "virtual", *extra])
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 2 and len(err) == 1, (extra, err)
        assert err[0].startswith(f"bench: error: {word}"), (extra, err)
        assert "missing.blf" not in err[0]


class SlowBus(can.BusABC):
    """A bus whose every send takes at least 2 ms."""

    def __init__(self) -> None:
        super().__init__(channel="slow")
        self.sent = 0

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        time.sleep(0.002)
        self.sent += 1

    def _recv_internal(self, timeout: float | None) -> tuple[None, bool]:
        return None, False


def test_replay_that_falls_behind_says_so(frames: list[can.Message]) -> None:
    """200 frames 10 us apart on a bus that needs 2 ms a frame: frame i is at least
    i * 1.99 ms late, so the median lateness is at least 0.19 s."""
    msgs = [can.Message(timestamp=1e-5 * i, arbitration_id=0x11, data=bytes(8)) for i in range(200)]
    bus = SlowBus()
    res = replay_frames(bus, msgs)
    assert bus.sent == 200
    assert res.mean_gap_s == pytest.approx(1e-5)
    assert float(np.median(res.error_s)) > 0.19
    warn = res.lag_warning()
    assert warn is not None and "could not keep up" in warn
    assert "needs 100000 frames/s" in warn and "limit 1.000 ms" in warn


def _result(errors: list[float], mean_gap_s: float) -> ReplayResult:
    return ReplayResult(
        sent=len(errors),
        loops=1,
        clock="deadline",
        speed=1.0,
        span_s=mean_gap_s * (len(errors) - 1),
        wall_s=mean_gap_s * len(errors),
        error_s=np.asarray(errors),
        mean_gap_s=mean_gap_s,
    )


def test_lag_limit_is_1ms_or_a_tenth_of_the_mean_gap() -> None:
    on_time = [5e-6] * 1000
    assert _result(on_time, 25e-6).lag_warning() is None
    # median 2 ms behind on a 10 kHz capture: behind
    w = _result([2e-3] * 1000, 25e-6).lag_warning()
    assert w is not None and "could not keep up" in w and "median 2.000 ms" in w
    # 2 % of the frames 5 ms late, the median on time: stalls, caught up
    w = _result([0.0] * 980 + [5e-3] * 20, 25e-6).lag_warning()
    assert w is not None and "latest 1 %" in w and "p99 5.000 ms" in w
    # a sparse capture (one frame a second) tolerates 50 ms, not 150 ms
    assert _result([50e-3] * 100, 1.0).lag_warning() is None
    w = _result([150e-3] * 100, 1.0).lag_warning()
    assert w is not None and "limit 100.000 ms" in w
