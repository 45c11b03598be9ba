"""A bus full of garbage cannot stall a run without a word (issue 26).

A flood of fuzzed frames beside a short lockstep ``bench run`` over
udp_multicast (:func:`bench.studies._reliability.flood_check`): random CAN FD
frames with the DBC's identifiers, corrupted copies, wrong lengths, unknown
identifiers, duplicates, replays and reordered bursts of the run's own frames,
and first replays of another (longer) run's commands, whose steps unwrap to
before this run's start: such a command once took the place of the start
command, and the plant waited for a start forever while ``bench run`` said
nothing.  A plant that cannot start (a forged command holds its start's step)
ends the run with a line naming it, within the start timeout; a command
forged for the start's step with another alive counter applies, and the
start after it (late) still starts the plant.
"""

from __future__ import annotations

import array
import fcntl
import json
import os
import signal
import subprocess
import sys
import termios
import time
from pathlib import Path

import can
import pytest

from bench.runs._run import START_TIMEOUT_S
from bench.studies._reliability import FLOOD_LIMIT_S, GROUP, flood_check, free_port
from bench.wire._codec import Codec
from bench.wire._protocol import CMD_START

ROOT = Path(__file__).resolve().parents[1]


def test_a_garbage_flood_beside_a_lockstep_run_gives_the_clean_trace(tmp_path: Path) -> None:
    res = flood_check(lambda _: None, seed=3, keep=tmp_path / "run")
    assert res["outcome"] == "identical", res
    assert res["seconds"] < FLOOD_LIMIT_S
    poured = res["frames_poured"]
    assert poured["old_command"] == 50 and poured["random_fd"] > 1000, poured
    # every garbage frame the nodes and the recorder saw is counted, by reason
    by = res["frames_rejected_by_reason"]
    assert by["bad_crc"] > 100 and by["bad_length"] > 1000, by
    assert res["steps"] == 3001
    m = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert m["frames_rejected_recorded"] > 1000 and m["steps_missing"] == 0


def _plant_pid(run: subprocess.Popen[str]) -> int | None:
    """The pid of ``bench run``'s plant process once it exists (its children: the
    controller, then the plant)."""
    kids = Path(f"/proc/{run.pid}/task/{run.pid}/children").read_text().split()
    for pid in kids:
        try:
            args = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if b"plant" in args and b"--plan" in args:
            return int(pid)
    return None


def _unread(pid: int) -> int:
    """Bytes written to process ``pid``'s stdout (a pipe) that its reader has not read."""
    fd = os.open(f"/proc/{pid}/fd/1", os.O_RDONLY | os.O_NONBLOCK)
    try:
        n = array.array("i", [0])
        fcntl.ioctl(fd, termios.FIONREAD, n)
        return n[0]
    finally:
        os.close(fd)


def _hold_at_plant_ready(run: subprocess.Popen[str], bus: can.BusABC, codec: Codec) -> None:
    """Stop ``bench run`` (SIGSTOP) as soon as its plant process exists, and return once
    the plant has said ``READY`` (its bus joined, waiting for its start): the line is
    unread in its pipe, so the held ``bench run`` has not sent the start yet."""
    t_end = time.monotonic() + 120.0
    while (pid := _plant_pid(run)) is None:
        assert run.poll() is None and time.monotonic() < t_end, "no plant process started"
        time.sleep(0.002)
    os.kill(run.pid, signal.SIGSTOP)
    while not _unread(pid):
        assert time.monotonic() < t_end, "the plant did not say READY"
        got = bus.recv(0.01)
        if got is not None and (d := codec.decode(got)) is not None:
            # a start already out: bench run read READY before it was held
            assert not (d.name == "BenchCommand" and d.signals["cmd"] == CMD_START), d


@pytest.mark.usefixtures("native_library")  # its first build is not in the wall time
def test_a_plant_that_cannot_start_ends_the_run_with_a_line(tmp_path: Path) -> None:
    """A valid command forged with the start's step and alive counter, sent before the
    start (the E2E check cannot tell it from a genuine one): the plant takes the genuine
    start for a repeat and never starts, and the run stops after the start timeout
    naming it and what the plant turned away.

    The forged command goes out while ``bench run`` is held between its plant's start and
    the plant's ``READY`` (:func:`_hold_at_plant_ready`), so it is in the plant's
    socket before the genuine start.  A forger that raced the start lost it on a loaded
    machine: the plant started, the controller (up first) took the forged copy and never
    enabled, and the run ended with exit 0 and no row scored.
    """
    codec = Codec()
    port = free_port()
    out = tmp_path / "run"
    bus = can.Bus(interface="udp_multicast", channel=GROUP, port=port, fd=True)
    proc = subprocess.Popen(
        [sys.executable, "-m", "bench", "run", "wen-5.1", "-e", "sensored", "--duration", "0.1",
         "-i", "udp_multicast", "--channel", GROUP, "--port", str(port), "--out", str(out), "-q"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        _hold_at_plant_ready(proc, bus, codec)
        msg = codec.encode(
            "BenchCommand", {"cmd": 0, "speed_ref": 0.0, "load_torque": 0.0, "seq": 0, "step": 0}
        )
        bus.send(msg)
        # multicast loops it back to this bus in the same delivery as to the plant's
        # socket: once it is back here, it is in the plant's queue ahead of the start
        while (got := bus.recv(5.0)) is not None and bytes(got.data) != bytes(msg.data):
            pass
        assert got is not None, "the forged command did not come back on the bus"
        os.kill(proc.pid, signal.SIGCONT)
        t0 = time.monotonic()  # the start goes out now
        _, err = proc.communicate(timeout=START_TIMEOUT_S + 90)
    finally:
        bus.shutdown()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    wall = time.monotonic() - t0
    last = err.strip().splitlines()[-1]
    assert proc.returncode == 2, err[-2000:]
    assert last.startswith("bench: error: the plant sent no sample 20 s after its start"), last
    assert "repeated_counter" in last, last
    assert "Traceback" not in err
    # it waited the start timeout, then stopped: the margin is for stopping the nodes
    # (their reports), scoring and the exit, which take tens of seconds on a loaded
    # 2-core host; the start-up before the start (imports, the nodes' READY) is not in it
    assert START_TIMEOUT_S <= wall < START_TIMEOUT_S + 60, wall
    assert (out / "error.txt").read_text().strip() == last.removeprefix("bench: error: ")
    assert json.loads((out / "metrics.json").read_text())["steps"] == 0


def test_the_command_queue_of_a_plant_waiting_for_its_start() -> None:
    """A replayed command of a longer run (a step before 0) is stale; a command that
    took the start's step first applies, and the start after it still comes due at the
    step the waiting plant asks for (it once went to step 1, which never came)."""
    from bench.nodes._counters import CommandQueue, NodeCounters

    q, c = CommandQueue(1 << 16), NodeCounters()

    def cmd(cmd: int, step: int, seq: int) -> dict[str, float]:
        return {"cmd": cmd, "speed_ref": 0.0, "load_torque": 0.0, "step": step, "seq": seq}

    assert q.add(cmd(0, 65000, 3), 0, c) is None  # step -536
    assert c.reject_reasons == {"stale_counter": 1}
    q.add(cmd(0, 0, 5), 0, c)
    assert [x.cmd for x in q.due(0)] == [0]
    q.add(cmd(1, 0, 0), 0, c)  # the genuine start, now late
    assert c.late_commands == 1
    assert [x.cmd for x in q.due(0)] == [1]
    q.add(cmd(1, 0, 0), 0, c)  # its second copy
    assert c.reject_reasons["repeated_counter"] == 1 and q.due(0) == []
