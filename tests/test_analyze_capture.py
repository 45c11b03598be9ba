"""``bench analyze``: a capture decoded into the files of a run, without running anything.

The recorded runs are real two-process runs (see ``replay_helpers``); the
analysis of their capture must give the live run's metrics exactly, also
after conversion to other python-can formats, and must survive captures cut
mid-run, with garbage, other traffic and a truncated end.
"""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import can
import numpy as np
import pytest

from bench.captures._read import (
    analyze_capture,
    read_capture,
)
from bench.cli import main
from bench.runs._analysis import analyze_frames, read_csv
from bench.wire._batch_decode import decode_batch
from bench.wire._codec import Codec
from tests.replay_helpers import POSITION_SPEED, recorded_run

CODEC = Codec()


def metrics(folder: Path) -> dict:
    return json.loads((folder / "metrics.json").read_text())


def quiet(_: str) -> None:
    pass


@pytest.fixture(scope="module", params=["sensored", "tt-dq"])
def both(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A recorded run of each estimator."""
    return recorded_run(tmp_path_factory, request.param)


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The recorded tt-dq run."""
    return recorded_run(tmp_path_factory, "tt-dq")


def test_analyze_gives_the_live_runs_metrics(both: Path, tmp_path: Path) -> None:
    run = both
    live = metrics(run)
    res = analyze_capture(run / "capture.blf", out_dir=tmp_path, echo=quiet, plots=False)
    got = metrics(tmp_path)
    for key in POSITION_SPEED:
        assert got[key] == live[key], key
    assert got == live  # counters, wall time (from meta.json) and all
    assert res.metrics["steps"] == 2001
    # the signal table too, value for value
    a, b = read_csv(str(run / "signals.csv")), read_csv(str(tmp_path / "signals.csv"))
    for col in ("theta_e", "theta_hat", "i_a", "d_a", "w_ref_rpm"):
        np.testing.assert_array_equal(a[col], b[col], err_msg=col)


def test_converted_captures_give_the_same_metrics(both: Path, tmp_path: Path) -> None:
    run = both
    live = metrics(run)
    folder = tmp_path / "conv"
    folder.mkdir()
    shutil.copy(run / "meta.json", folder / "meta.json")
    # python-can's own converter (for candump on one run, its reader/writer otherwise)
    if run.name.startswith("run-tt-dq"):
        subprocess.run(
            [
                sys.executable,
                "-m",
                "can.logconvert",
                str(run / "capture.blf"),
                str(folder / "c.log"),
            ],
            check=True,
            capture_output=True,
        )
    for name in ("c.log", "c.asc"):
        if (folder / name).exists():
            continue
        with can.LogReader(str(run / "capture.blf")) as r, can.Logger(str(folder / name)) as w:
            for m in r:
                w.on_message_received(m)
    for name in ("c.log", "c.asc"):
        out = tmp_path / name
        analyze_capture(folder / name, out_dir=out, echo=quiet, plots=False)
        got = metrics(out)
        for key in POSITION_SPEED:
            assert got[key] == live[key], (name, key)
        assert got["frames_recorded"] == live["frames_recorded"]
        assert got["frames_rejected"] == 0
    # the candump form keeps the bench's bus tag as a channel name
    first = next(iter(can.LogReader(str(folder / "c.log"))))
    assert first.channel == "can1"


def test_capture_starting_mid_run_lines_up_all_messages(run: Path, tmp_path: Path) -> None:
    """Cut after step ~1250: the 10-bit sample and duty counters must be placed by the
    32-bit truth and telemetry counters, not counted from zero."""
    frames, _ = read_capture(run / "capture.blf")
    cut = frames[len(frames) * 5 // 8 :]  # about step 1250 of 2001
    live = analyze_frames(frames, CODEC, T_s=1e-4, n_p=4).table
    cap = analyze_frames(cut, CODEC, T_s=1e-4, n_p=4)
    assert cap.first_step > 1024
    got = cap.table
    idx = np.searchsorted(live["step"], got["step"])
    np.testing.assert_array_equal(live["step"][idx], got["step"])
    for col in ("i_a", "theta_hat", "theta_e", "d_a"):
        np.testing.assert_array_equal(live[col][idx], got[col], err_msg=col)
    assert len(got["step"]) >= 2001 - cap.first_step - 1
    # the reference in force comes only from the commands the cut holds, by their apply
    # step: none applied by its first step (the schedule, and the copies the bench sends
    # again while the run goes on, are before the cut or not, by timing): no reference
    cid = CODEC.frame_id("BenchCommand")
    decoded = [CODEC.decode(m) for m in cut if m.arbitration_id == cid]
    applied = sorted(
        (d.signals["step"], d.signals["speed_ref"])
        for d in decoded
        if d is not None and d.signals["step"] <= got["step"][0]
    )
    if applied:
        assert got["w_ref_rpm"][0] == applied[-1][1]  # rpm on the wire and in the table
    else:
        assert np.isnan(got["w_ref_rpm"][0])
    # and through the files
    with can.Logger(str(tmp_path / "cut.blf")) as w:
        for m in cut:
            w.on_message_received(m)
    shutil.copy(run / "meta.json", tmp_path / "meta.json")
    res = analyze_capture(tmp_path / "cut.blf", out_dir=tmp_path / "out", echo=quiet, plots=False)
    assert res.metrics["steps"] == len(got["step"])
    assert math.isfinite(res.metrics["theta_err_rms_deg"])
    # the periods before the cut have no rows, and the metrics say how many
    n_run = 2000  # 0.2 s at 10 kHz
    assert res.metrics["steps_missing"] == n_run - int(np.sum(got["step"] < n_run))
    assert res.metrics["steps_missing"] >= cap.first_step


def garbage_capture(frames: list[can.Message]) -> tuple[list[can.Message], list[str]]:
    """The first two thirds of ``frames`` with bad frames mixed in, and the kind of each frame."""
    rng = np.random.default_rng(7)
    out: list[can.Message] = []
    kinds: list[str] = []

    def add(m: can.Message, kind: str) -> None:
        out.append(m)
        kinds.append(kind)

    ids_crc = [CODEC.frame_id(x) for x in ("PhaseSamples", "PwmDuty", "BenchCommand")]
    for i, m in enumerate(frames[: 2 * len(frames) // 3]):
        add(m, "run")
        t = m.timestamp + 1e-6
        if i % 50 == 7:  # random payload under a CRC-protected ID
            while True:
                g = can.Message(
                    timestamp=t,
                    arbitration_id=int(rng.choice(ids_crc)),
                    is_extended_id=False,
                    data=rng.integers(0, 256, 8, dtype=np.uint8).tobytes(),
                )
                d = CODEC.decode(g)
                if d is not None and d.reason == "bad_crc":
                    break
            add(g, "bad_crc")
        elif i % 50 == 17:  # a truth frame of the wrong length
            add(
                can.Message(
                    timestamp=t,
                    arbitration_id=0x100,
                    is_extended_id=False,
                    is_fd=True,
                    data=bytes(20),
                ),
                "bad_length",
            )
        elif i % 50 == 27:  # other traffic
            add(
                can.Message(
                    timestamp=t,
                    arbitration_id=0x7DF,
                    is_extended_id=False,
                    data=b"\x02\x01\x0c\0\0\0\0\0",
                ),
                "unknown",
            )
            add(
                can.Message(
                    timestamp=t, arbitration_id=0x18DAF110, is_extended_id=True, data=b"\x01"
                ),
                "unknown",
            )
        elif i % 50 == 37:
            add(can.Message(timestamp=t, is_error_frame=True), "error")
        elif i % 50 == 43:
            add(m, "dup")  # the same frame again
    return out, kinds


def test_batch_decode_equals_codec_frame_by_frame(run: Path) -> None:
    frames, _ = read_capture(run / "capture.blf")
    bad, _ = garbage_capture(frames)
    dec = decode_batch(bad, CODEC)
    rejected: dict[str, int] = {}
    per_msg: dict[str, list[tuple[int, dict]]] = {}
    unknown = 0
    for i, m in enumerate(bad):
        if m.is_error_frame or m.is_remote_frame:
            continue
        d = CODEC.decode(m)
        if d is None:
            unknown += 1
        elif d.reason is not None:
            rejected[d.reason] = rejected.get(d.reason, 0) + 1
        else:
            per_msg.setdefault(d.name, []).append((i, d.signals))
    assert dec.rejected == rejected and dec.unknown_ids == unknown
    assert set(dec.messages) == set(per_msg)
    for name, rows in per_msg.items():
        b = dec.messages[name]
        assert b.index.tolist() == [i for i, _ in rows]
        for sig in rows[0][1]:
            want = np.array([float(s[sig]) for _, s in rows])
            np.testing.assert_array_equal(b.signals[sig], want, err_msg=f"{name}.{sig}")


def test_garbage_other_traffic_and_truncated_end_are_counted(run: Path, tmp_path: Path) -> None:
    frames, _ = read_capture(run / "capture.blf")
    bad, kinds = garbage_capture(frames)
    path = tmp_path / "capture.blf"
    with can.Logger(str(path)) as w:
        for m in bad:
            w.on_message_received(m)
    size = path.stat().st_size
    with path.open("r+b") as f:  # cut the file in the middle of its last container
        f.truncate(size - 3000)
    shutil.copy(run / "meta.json", tmp_path / "meta.json")
    lines: list[str] = []
    res = analyze_capture(path, out_dir=tmp_path / "out", echo=lines.append, plots=False)
    mx = res.metrics
    kept, _ = read_capture(path)
    n = len(kept)
    assert n < len(bad)  # the truncated tail is gone, the rest is read in order
    assert [bytes(m.data) for m in kept] == [bytes(m.data) for m in bad[:n]]
    assert mx["frames_recorded"] == n
    # every injected frame before the cut is counted, by reason
    assert mx["frames_rejected_by_reason"]["bad_crc"] == kinds[:n].count("bad_crc")
    assert mx["frames_rejected_by_reason"]["bad_length"] == kinds[:n].count("bad_length")
    assert mx["frames_unknown_id"] == kinds[:n].count("unknown")
    base = analyze_frames(frames[: 2 * len(frames) // 3], CODEC, T_s=1e-4, n_p=4)
    # the injected frames are identical repeats: copies, not duplicates
    assert mx["frames_duplicate"] == 0
    assert mx["frames_copies"] >= kinds[:n].count("dup")
    assert mx["frames_copies"] <= kinds[:n].count("dup") + base.copies
    assert "rejected (bad_crc" in lines[0]
    # and the steps that survived carry exactly the live values
    live = read_csv(str(run / "signals.csv"))
    got = read_csv(str(tmp_path / "out" / "signals.csv"))
    idx = np.searchsorted(live["step"], got["step"])
    np.testing.assert_array_equal(live["step"][idx], got["step"])
    # a row per plant period: the telemetry of the last periods lies past the cut
    # (estimate NaN); how many depends on the order the recorder heard the last
    # frames in (a controller's telemetry for k can follow the plant's sample k + 1),
    # but they are the last rows only
    tel = np.isfinite(got["theta_hat"])
    missing = np.flatnonzero(~tel)
    assert len(missing) == mx["steps_without_telemetry"]
    np.testing.assert_array_equal(missing, np.arange(len(tel) - len(missing), len(tel)))
    assert len(missing) < 10
    np.testing.assert_array_equal(live["theta_hat"][idx][tel], got["theta_hat"][tel])
    np.testing.assert_array_equal(live["i_a"][idx], got["i_a"])
    assert 1100 < len(got["step"]) < 1334


def test_exact_counts_on_an_untruncated_garbage_capture(run: Path) -> None:
    frames, _ = read_capture(run / "capture.blf")
    bad, kinds = garbage_capture(frames)
    cap = analyze_frames(bad, CODEC, T_s=1e-4, n_p=4)
    assert cap.rejected == {
        "bad_crc": kinds.count("bad_crc"),
        "bad_length": kinds.count("bad_length"),
    }
    assert cap.unknown_ids == kinds.count("unknown")
    assert cap.frames == len(bad)
    base = analyze_frames(frames[: 2 * len(frames) // 3], CODEC, T_s=1e-4, n_p=4)
    assert cap.copies == base.copies + kinds.count("dup") and cap.duplicates == 0
    np.testing.assert_array_equal(cap.table["theta_hat"], base.table["theta_hat"])
    np.testing.assert_array_equal(cap.table["d_a"], base.table["d_a"])


def test_out_of_order_frames_are_counted_and_placed(run: Path) -> None:
    frames, _ = read_capture(run / "capture.blf")
    sid = CODEC.frame_id("PhaseSamples")
    pos = [i for i, m in enumerate(frames) if m.arbitration_id == sid]
    swapped = list(frames)
    a, b = pos[100], pos[101]  # samples of steps 100 and 101 swapped
    swapped[a], swapped[b] = swapped[b], swapped[a]
    cap = analyze_frames(swapped, CODEC, T_s=1e-4, n_p=4)
    ref = analyze_frames(frames, CODEC, T_s=1e-4, n_p=4)
    assert cap.out_of_order == ref.out_of_order + 1
    np.testing.assert_array_equal(cap.table["i_a"], ref.table["i_a"])


def test_capture_without_bench_commands_has_no_reference_but_metrics(
    run: Path, tmp_path: Path
) -> None:
    frames, _ = read_capture(run / "capture.blf")
    cid = CODEC.frame_id("BenchCommand")
    with can.Logger(str(tmp_path / "nocmd.blf")) as w:
        for m in frames:
            if m.arbitration_id != cid:
                w.on_message_received(m)
    shutil.copy(run / "meta.json", tmp_path / "meta.json")
    res = analyze_capture(tmp_path / "nocmd.blf", out_dir=tmp_path / "out", echo=quiet, plots=False)
    live = metrics(run)
    for key in ("theta_err_max_deg", "theta_err_rms_deg", "speed_err_max_rpm", "steps"):
        assert res.metrics[key] == live[key], key
    assert math.isnan(res.metrics["speed_track_err_max_rpm"])
    table = read_csv(str(tmp_path / "out" / "signals.csv"))
    assert np.all(np.isnan(table["w_ref_rpm"]))


def test_capture_without_telemetry_keeps_the_plant_side(run: Path) -> None:
    """A drive that sends no CtrlTelemetry: rows from samples and truth, estimate NaN."""
    frames, _ = read_capture(run / "capture.blf")
    tid = CODEC.frame_id("CtrlTelemetry")
    cap = analyze_frames([m for m in frames if m.arbitration_id != tid], CODEC, T_s=1e-4, n_p=4)
    assert len(cap.table["step"]) == 2001
    assert np.all(np.isnan(cap.table["theta_hat"]))
    assert np.all(np.isfinite(cap.table["theta_e"]))


def test_cli_missing_and_unreadable_captures(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    cases = [
        tmp_path / "missing.blf",
        tmp_path / "garbage.blf",
        tmp_path / "notes.xyz",
        tmp_path / "empty.asc",
    ]
    (tmp_path / "garbage.blf").write_bytes(b"\x00garbage" * 100)
    (tmp_path / "notes.xyz").write_text("hello\n")
    (tmp_path / "empty.asc").write_text("")
    for path in cases:
        rc = main(["analyze", str(path), "--scenario", "wen-5.1"])
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 2, path
        assert len(err) == 1 and err[0].startswith("bench: error: "), err
        assert path.name in err[0]
    rc = main(["analyze", str(tmp_path)])  # a folder without a capture
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("bench: error: "), err


def test_cli_analyze_of_a_run_folder(
    run: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    rc = main(["analyze", str(run), "--out", str(tmp_path)])
    out = capsys.readouterr()
    assert rc == 0
    assert "theta_err_rms_deg" in out.out
    assert "0 with IDs not in the DBC" in out.err
    assert metrics(tmp_path)["theta_err_rms_deg"] == metrics(run)["theta_err_rms_deg"]


def test_a_clean_run_has_no_duplicates_and_names_the_command_copies(
    run: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Every command is sent twice on purpose (and the stop once more): identical
    copies, counted apart; a clean run has no duplicate."""
    frames, _ = read_capture(run / "capture.blf")
    cap = analyze_frames(frames, CODEC, T_s=1e-4, n_p=4)
    cid = CODEC.frame_id("BenchCommand")
    commands = [bytes(m.data) for m in frames if m.arbitration_id == cid]
    assert len(commands) >= 2 * len(set(commands))  # each one at least twice
    # the copies, counted independently: a frame whose ID and bytes came before
    # (the step is in the bytes): the commands' and any lockstep retransmission's
    everything = [(m.arbitration_id, bytes(m.data)) for m in frames]
    # and the telemetry a controller sends again for its step when its command
    # acknowledgement moves (DBC 2.2): the same step, new bytes
    tid = CODEC.frame_id("CtrlTelemetry")
    tel = [CODEC.decode(m) for m in frames if m.arbitration_id == tid]
    tel_steps = [d.signals["step"] for d in tel if d is not None]
    tel_bytes = {bytes(m.data) for m in frames if m.arbitration_id == tid}
    ack_updates = (len(tel_steps) - len(set(tel_steps))) - (len(tel_steps) - len(tel_bytes))
    assert cap.duplicates == 0
    assert cap.copies == len(everything) - len(set(everything)) + ack_updates
    assert cap.copies >= len(commands) - len(set(commands)) > 0
    assert metrics(run)["frames_duplicate"] == 0
    assert metrics(run)["frames_copies"] == cap.copies
    assert (
        main(["analyze", str(run), "--out", str(run.parent / "clean-analyzed"), "--no-plots"]) == 0
    )
    line = capsys.readouterr().err.splitlines()[0]
    assert " 0 duplicates" in line and f"{cap.copies} identical copies" in line


def test_a_different_frame_for_a_step_already_seen_is_a_duplicate(run: Path) -> None:
    frames, _ = read_capture(run / "capture.blf")
    sid = CODEC.frame_id("PhaseSamples")
    i = [j for j, m in enumerate(frames) if m.arbitration_id == sid][200]
    d = CODEC.decode(frames[i])
    assert d is not None and d.reason is None
    other = CODEC.encode("PhaseSamples", dict(d.signals, i_a=d.signals["i_a"] + 1.0))
    other.timestamp = frames[i].timestamp + 1e-6
    base = analyze_frames(frames, CODEC, T_s=1e-4, n_p=4)
    twice = analyze_frames([*frames[: i + 1], other, *frames[i + 1 :]], CODEC, T_s=1e-4, n_p=4)
    assert twice.duplicates == base.duplicates + 1 and twice.copies == base.copies
    # the first frame of the step wins
    np.testing.assert_array_equal(twice.table["i_a"], base.table["i_a"])


def test_a_run_without_faults_sends_no_plant_currents_and_its_true_currents_are_nan(
    run: Path,
) -> None:
    """The recorded run has no ``[[faults]]``: its plant sends the 2.3 frames only (no
    ``PlantCurrents``, DBC 2.4), and ``i_a_true``, ``i_b_true``, ``i_c_true`` are NaN."""
    frames, _ = read_capture(run / "capture.blf")
    cur = CODEC.frame_id("PlantCurrents")
    assert not any(m.arbitration_id == cur for m in frames)
    table = analyze_frames(frames, CODEC, T_s=1e-4, n_p=4).table
    for c in ("i_a_true", "i_b_true", "i_c_true"):
        assert np.all(np.isnan(table[c]))
    assert np.all(np.isfinite(table["i_a"]))
