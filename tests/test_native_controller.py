"""The native controller node (bench/nodes/native/bn_ctl.c, controller_node.py).

- The transport-free unit against :class:`ControllerNode` on the same frames: every
  answer byte for byte, every counter, through repeats, a future sample, a bad CRC, a
  stale sample and the commands.
- ``bench controller --engine native`` against the Python node beside a Python plant
  (``bench run --controller external``) in lockstep: the same trace, row for row, on
  udp_multicast and (``socketcan``) on vcan; a supervision detection (a DC-link sag) at
  the same step with the same mode.
- ``bench run`` on its defaults runs a native pair (plant and controller nodes), and
  gives the trace of a Python pair (``--engine compiled``) row for row.
- The fallback: one line saying why the Python node runs.
"""

from __future__ import annotations

import csv
import json
import random
import subprocess
import sys
from pathlib import Path
from typing import Any

import can
import pytest

from bench import load_scenario
from bench.nodes._controller_node import ControllerNode
from bench.nodes._loops import make_controller_node
from bench.wire._codec import Codec
from bench.wire._protocol import CMD_START, CMD_STOP
from controller import Controller, compiled_controller_missing
from tests.conftest import require_vcan
from tests.native_helpers import native_answers
from tests.oracle import OracleController
from tests.ports import free_port

pytestmark = [
    pytest.mark.skipif(
        not any(__import__("shutil").which(c) for c in ("cc", "gcc")), reason="needs a C compiler"
    ),
    pytest.mark.skipif(
        compiled_controller_missing() is not None, reason="needs the compiled controller"
    ),
]

ROOT = Path(__file__).resolve().parents[1]
GROUP = "239.74.163.2"


@pytest.fixture(scope="module")
def native() -> Any:
    from bench.nodes.native import controller_node

    controller_node.native_library()
    return controller_node


# ---------------------------------------------------------------- the unit, no transport
def _frames(codec: Codec, n: int) -> list[can.Message]:
    """Samples of steps 0..n-1 with a start at 0, a speed step at 40 and a stop at n - 1,
    and on the way: a repeat, a future sample, a bad CRC, a stale sample."""
    rnd = random.Random(7)
    cmd = [
        (0, CMD_START, 300.0, 0),
        (40, CMD_START, 600.0, 1),
        (n - 1, CMD_STOP, 0.0, 2),
    ]
    out = [
        codec.encode(
            "BenchCommand",
            {"cmd": c, "seq": seq, "step": s, "speed_ref": v, "load_torque": 0.0},
        )
        for s, c, v, seq in cmd
    ]
    samples = [
        codec.encode(
            "PhaseSamples",
            {
                "i_a": rnd.uniform(-3, 3),
                "i_b": rnd.uniform(-3, 3),
                "u_dc": 540.0 + rnd.uniform(-1, 1),
                "status": 1,
                "step": k % 1024,
            },
        )
        for k in range(n)
    ]
    order = list(range(n))
    order[10], order[11] = order[11], order[10]  # step 11 before 10: held, then both run
    for k in order:
        out.append(samples[k])
        if k == 20:
            out.append(samples[18])  # a repeat answered from the cache
            out.append(samples[2])  # too old for the cache: stale
            bad = bytearray(samples[21].data)
            bad[0] ^= 0xFF
            out.append(can.Message(arbitration_id=0x11, data=bytes(bad), is_extended_id=False))
    return out


def test_the_unit_answers_as_the_python_node_byte_for_byte(native: Any) -> None:
    codec = Codec()
    scn = load_scenario("wen-5.1", {"controller.supervision": True})
    py = make_controller_node(scn, "tt-dq", codec)
    cn = make_controller_node(scn, "tt-dq", codec)
    assert py.ctrl.engine == cn.ctrl.engine == "compiled"
    py.run_id = cn.run_id = 4242
    frames = _frames(codec, 300)
    want = [(m.arbitration_id, bytes(m.data)) for msg in frames for m in py.on_message(msg)]
    got = native_answers(cn, frames)
    assert len(want) > 2 * 290 and got == want
    rep_py, rep_c = py.report(), cn.report()
    assert rep_c.pop("node_engine") == "native" and rep_py.pop("node_engine") == "python"
    assert rep_c == rep_py
    assert rep_py["reject_reasons"] == {"repeated_counter": 1, "stale_counter": 1, "bad_crc": 1}
    assert py.stopped and cn.stopped


def test_the_fallback_says_why_in_one_line(native: Any) -> None:
    codec = Codec()
    scn = load_scenario("wen-5.1")
    node = make_controller_node(scn, "tt-dq", codec)
    assert native.native_unavailable(node, "udp_multicast") is None
    assert native.native_unavailable(node, None) is None
    why = native.native_unavailable(node, "pcan")
    assert why is not None and "\n" not in why and "--interface pcan" in why
    # the controller always runs its core (engine="python" is a name of it); only the
    # tests' oracle, the step in Python, has none
    assert Controller(node.ctrl.pars, "python")._core is not None
    py = ControllerNode(codec, OracleController(node.ctrl.pars))
    why = native.native_unavailable(py, "udp_multicast")
    assert why is not None and "\n" not in why and "controller's core" in why


# ---------------------------------------------------------------- beside a Python plant
SAG = """extends = "wen-5.1"
duration = 0.5
score_from_s = 0.25

[[faults]]
at_s = 0.3
kind = "dc_link_step"
u_dc_v = 324.0
"""


def _pair(
    tmp: Path, scenario: str, engine: str | None, bus: list[str], tag: str
) -> tuple[list[list[str]], dict[str, Any], str]:
    """``bench controller`` (``engine``) and ``bench run --controller external`` on ``bus``:
    the run's signals.csv rows, the controller's report and its stderr."""
    report = tmp / f"ctl-{tag}.json"
    ctl = subprocess.Popen(
        [sys.executable, "-m", "bench", "controller", scenario, "-e", "tt-dq", *bus,
         "--report", str(report), *(["--engine", engine] if engine else [])],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert ctl.stdout is not None and ctl.stdout.readline().strip() == "READY"
        out = tmp / f"run-{tag}"
        res = subprocess.run(
            [sys.executable, "-m", "bench", "run", scenario, "--controller", "external",
             *bus, "--duration", "0.5", "--out", str(out), "-q"],
            cwd=ROOT, capture_output=True, text=True, timeout=300,
        )  # fmt: skip
        assert res.returncode in (0, 4), res.stderr
        _, err = ctl.communicate(timeout=60)
    finally:
        ctl.kill()
        ctl.wait()
    with (out / "signals.csv").open() as f:
        rows = list(csv.reader(f))
    return rows, json.loads(report.read_text()), err


def _same_trace(tmp: Path, scenario: str, bus: list[str]) -> list[list[str]]:
    rows_n, rep_n, err_n = _pair(tmp, scenario, "native", bus, "native")
    rows_p, rep_p, _ = _pair(tmp, scenario, "compiled", bus, "python")
    assert rep_n["node_engine"] == "native" and rep_p["node_engine"] == "python", err_n
    assert rep_n["engine"] == "compiled" and rep_n["steps"] == rep_p["steps"] > 4000
    assert len(rows_n) == len(rows_p) > 4000
    assert rows_n == rows_p  # every column of every period
    return rows_n


def test_the_same_lockstep_trace_on_udp_multicast(tmp_path: Path) -> None:
    bus = ["--interface", "udp_multicast", "--channel", GROUP, "--port", str(free_port())]
    _same_trace(tmp_path, "wen-5.1", bus)


def test_a_dc_link_sag_is_detected_at_the_same_step(tmp_path: Path) -> None:
    scn = tmp_path / "sag.toml"
    scn.write_text(SAG)
    bus = ["--interface", "udp_multicast", "--channel", GROUP, "--port", str(free_port())]
    rows = _same_trace(tmp_path, str(scn), bus)
    head = rows[0]
    mode = [int(float(r[head.index("mode")])) for r in rows[1:]]
    t = [float(r[head.index("t")]) for r in rows[1:]]
    first = mode.index(7)  # dc_undervoltage (controller/_supervision.py)
    assert 0.3 < t[first] < 0.3 + 5e-3 and all(m == 7 for m in mode[first:])


def test_bench_run_defaults_to_a_native_pair_with_the_python_pairs_trace(
    tmp_path: Path,
) -> None:
    """The default engine (auto) puts both nodes of ``bench run`` on the native loop where
    they can serve, and the pair gives the Python pair's lockstep trace, every column of
    every period (the same cores stepped, the same codec, the same order)."""
    bus = ["--interface", "udp_multicast", "--channel", GROUP]
    rows: dict[str, list[list[str]]] = {}
    metas: dict[str, dict[str, Any]] = {}
    for engine in ("auto", "compiled"):
        out = tmp_path / engine
        res = subprocess.run(
            [sys.executable, "-m", "bench", "run", "wen-5.1", "-e", "tt-dq", *bus,
             "--port", str(free_port()), "--duration", "0.5", "--engine", engine,
             "--out", str(out), "-q"],
            cwd=ROOT, capture_output=True, text=True, timeout=300,
        )  # fmt: skip
        assert res.returncode == 0, res.stderr
        metas[engine] = json.loads((out / "meta.json").read_text())
        with (out / "signals.csv").open() as f:
            rows[engine] = list(csv.reader(f))
    assert metas["auto"]["node_engines"] == {"plant": "native", "controller": "native"}
    assert metas["compiled"]["node_engines"] == {"plant": "python", "controller": "python"}
    assert len(rows["auto"]) > 4000 and rows["auto"] == rows["compiled"]


@pytest.mark.socketcan
def test_the_same_lockstep_trace_on_vcan(tmp_path: Path) -> None:
    require_vcan("vcan0")
    _same_trace(tmp_path, "wen-5.1", ["--interface", "socketcan", "--channel", "vcan0"])


def test_a_real_time_controller_whose_samples_stopped_still_stops_when_asked(
    native: Any,
) -> None:
    """Without samples every ``bn_ctl_serve`` call in real time ends in a sample timeout
    (none in a poll); the node must still see its stop flag (a SIGTERM's): it stopped
    only at the stop command or SIGKILL before."""
    import threading
    import time

    from bench.wire._bus import BusSpec

    codec = Codec()
    node = make_controller_node(load_scenario("wen-5.1"), "tt-dq", codec)
    spec = BusSpec("udp_multicast", GROUP, free_port())
    stop, ready, ended = threading.Event(), threading.Event(), threading.Event()

    def serve() -> None:
        try:
            native.native_controller_loop(
                spec,
                node,
                realtime=True,
                on_ready=ready.set,
                stop=stop.is_set,
                sample_timeout_s=0.02,
            )
        finally:
            ended.set()

    threading.Thread(target=serve, daemon=True).start()
    assert ready.wait(60.0)
    with can.Bus(interface="udp_multicast", channel=GROUP, port=spec.port, fd=True) as bus:
        for k in range(30):  # samples for a while, then none: sample timeouts from then on
            sample = {"i_a": 0.0, "i_b": 0.0, "u_dc": 540.0, "status": 1, "step": k}
            bus.send(codec.encode("PhaseSamples", sample))
            time.sleep(0.01)
    assert not ended.wait(0.5)  # it serves on through the timeouts
    stop.set()
    assert ended.wait(10.0), "the node did not see its stop flag"
    assert node.samples_accepted > 0  # it had samples, so it was in the timeouts


def test_a_real_time_controller_answers_samples_queued_behind_commands_and_applies_them(
    native: Any,
) -> None:
    """Real time: a command frame (twice, as the bench's pacer sends it) queued just
    before a sample is held until that sample's duty is out (bn_ctl_serve), then handed
    to Python; every command frame the loop receives goes through the ring but the copies
    of a command Python already took.  Each sample
    is answered with its duty, and every command is applied at its step, none late, the
    last one (a stop) ending the loop."""
    import threading
    import time

    from bench.wire._bus import BusSpec
    from bench.wire._protocol import CMD_NONE

    codec = Codec()
    node = make_controller_node(load_scenario("wen-5.1"), "tt-dq", codec)
    spec = BusSpec("udp_multicast", GROUP, free_port())
    ready, ended, errors = threading.Event(), threading.Event(), []

    def serve() -> None:
        try:
            native.native_controller_loop(spec, node, realtime=True, on_ready=ready.set)
        except BaseException as e:  # the test thread reports it
            errors.append(e)
        finally:
            ended.set()

    def command(seq: int, step: int, cmd: int, rpm: float) -> can.Message:
        sig = {"cmd": cmd, "seq": seq % 16, "step": step, "speed_ref": rpm, "load_torque": 0.0}
        return codec.encode("BenchCommand", sig)

    n, stop_at = 200, 210
    frames = [command(0, 0, CMD_START, 0.0)]
    duties: set[int] = set()
    threading.Thread(target=serve, daemon=True).start()
    assert ready.wait(60.0), errors
    with can.Bus(interface="udp_multicast", channel=GROUP, port=spec.port, fd=True) as bus:
        bus.send(frames[0])
        time.sleep(0.02)  # the start ahead of sample 0, as the bench sends it
        seq = 0
        for k in range(stop_at + 1):
            if k % 10 == 5 and k + 20 < stop_at:
                seq += 1
                frames += [command(seq, k + 20, CMD_NONE, 10.0 * seq)] * 2
                bus.send(frames[-1])
                bus.send(frames[-1])
            if k == n:
                frames.append(command(seq + 1, stop_at, CMD_STOP, 0.0))
                bus.send(frames[-1])
            sample = {"i_a": 0.0, "i_b": 0.0, "u_dc": 540.0, "status": 1, "step": k}
            bus.send(codec.encode("PhaseSamples", sample))
            t_end = time.monotonic() + 1e-3
            while (m := bus.recv(max(0.0, t_end - time.monotonic()))) is not None:
                if m.arbitration_id == 0x10:  # PwmDuty
                    d = codec.decode(m)
                    assert d is not None and d.reason is None
                    duties.add(int(d.signals["step"]))
        assert ended.wait(10.0), "the stop command did not end the loop"
    assert not errors, errors
    assert node.counters.late_commands == 0
    assert node.stopped and not node.commands.pending
    assert node.commands.applied_seq == (seq + 1) % 16
    assert node.commands_held is not None
    # a copy that comes after Python took its command is dropped in C before the ring
    # (bn_cmd_seen_t), one that comes before it is held and dropped at hand-over; either
    # way it is counted among the duplicates, as the queue counts the copies it sees
    copies = len(frames) - len({bytes(m.data) for m in frames})
    assert copies == 19 and node.counters.duplicates == copies
    assert len(frames) - copies <= node.commands_held["held"] <= len(frames)
    assert duties >= set(range(1, stop_at + 1))  # the duty of each sample k is tagged k + 1
