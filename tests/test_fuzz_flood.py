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

import json
import subprocess
import sys
import threading
import time
from pathlib import Path

import can

from bench.runs._run import START_TIMEOUT_S
from bench.studies._reliability import FLOOD_LIMIT_S, GROUP, flood_check, free_port
from bench.wire._codec import Codec

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


def test_a_plant_that_cannot_start_ends_the_run_with_a_line(tmp_path: Path) -> None:
    """A valid command forged with the start's step and alive counter, sent before the
    start (the E2E check cannot tell it from a genuine one): the plant takes the genuine
    start for a repeat and never starts, and the run stops after the start timeout
    naming it and what the plant turned away."""
    codec = Codec()
    port = free_port()
    out = tmp_path / "run"
    t0 = time.monotonic()
    proc = subprocess.Popen(
        [sys.executable, "-m", "bench", "run", "wen-5.1", "-e", "sensored", "--duration", "0.1",
         "-i", "udp_multicast", "--channel", GROUP, "--port", str(port), "--out", str(out), "-q"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    bus = can.Bus(interface="udp_multicast", channel=GROUP, port=port, fd=True)
    done = threading.Event()

    def forge() -> None:
        # from the nodes' start (after the listening window) until the genuine start
        # is on the bus: the plant has its copy first
        while not (out / "plant.log").exists() and not done.is_set():
            time.sleep(0.01)
        msg = codec.encode(
            "BenchCommand", {"cmd": 0, "speed_ref": 0.0, "load_torque": 0.0, "seq": 0, "step": 0}
        )
        while not done.is_set():
            bus.send(msg)
            got = bus.recv(0.005)
            while got is not None:
                d = codec.decode(got)
                ok = d is not None and d.name == "BenchCommand" and d.reason is None
                if ok and d is not None and int(d.signals["cmd"]) == 1:
                    return
                got = bus.recv(0.0)

    th = threading.Thread(target=forge, daemon=True)
    th.start()
    try:
        _, err = proc.communicate(timeout=START_TIMEOUT_S + 90)
    finally:
        done.set()
        th.join()
        bus.shutdown()
        if proc.poll() is None:
            proc.kill()
    wall = time.monotonic() - t0
    last = err.strip().splitlines()[-1]
    assert proc.returncode == 2, err[-2000:]
    assert last.startswith("bench: error: the plant sent no sample 20 s after its start"), last
    assert "repeated_counter" in last, last
    assert "Traceback" not in err
    assert wall < START_TIMEOUT_S + 60
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
