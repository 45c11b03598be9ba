"""The native plant node (``bench/nodes/native/bn_plant*.c``, ``--engine native``).

Its loop is C on the plant core instance the Python plant built; these tests
hold it to the Python node: the same lockstep frames as the in-process
reference (the Python node's), bit for bit, on udp_multicast and on vcan; a
real-time run that completes and reports its counters; the encoder's
arithmetic against :meth:`bench.wire._codec.Codec.encode`; and the fallback
line where the native loop cannot serve.
"""

from __future__ import annotations

import ctypes
import json
import math
import os
import random
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import can
import pytest

from bench.nodes._loops import run_inprocess
from bench.nodes.native import _native, _plant_native
from bench.runs._run import run_scenario
from bench.scenarios._schema import Scenario
from bench.wire._bus import BusSpec
from bench.wire._protocol import unwrap
from tests.ports import free_port
from tests.trace_helpers import CODEC, assert_same_trace, short, trace

ROOT = Path(__file__).resolve().parents[1]
GROUP = "239.74.163.2"
NATIVE = {"plant": ["--engine", "native"], "controller": []}
#: PwmDuty, PhaseSamples, PositionSensor, PlantTruth: one frame per step each.
PER_STEP = {0x10: "PwmDuty", 0x11: "PhaseSamples", 0x12: "PositionSensor", 0x100: "PlantTruth"}


@pytest.fixture(scope="module")
def lib() -> ctypes.CDLL:
    return _plant_native.load_plant_lib()


def _by_step(frames: Sequence[can.Message]) -> dict[tuple[int, int], bytes]:
    """Each per-step frame by (identifier, step unwrapped); PlantTruth without its run_id."""
    out: dict[tuple[int, int], bytes] = {}
    last: dict[int, int] = {}
    for m in frames:
        name = PER_STEP.get(m.arbitration_id)
        if name is None:
            continue
        d = CODEC.decode(m)
        assert d is not None and d.reason is None, (name, d)
        data = bytes(m.data)
        if name == "PlantTruth":  # the run's nonce differs between two runs
            s = dict(d.signals)
            s["run_id"] = 0
            data = bytes(CODEC.encode(name, s).data)
        bits = CODEC.step_bits(name)
        step = unwrap(int(d.signals["step"]), last.get(m.arbitration_id, 0), 1 << bits)
        last[m.arbitration_id] = step
        key = (m.arbitration_id, step)
        assert out.setdefault(key, data) == data, f"two {name} frames for step {key[1]}"
    return out


def _native_run(
    scn: Scenario, est: str, spec: BusSpec, out: Path
) -> tuple[list[can.Message], dict]:
    res = run_scenario(scn, est, spec=spec, out_dir=out, progress=False, node_args=NATIVE)
    meta = json.loads((out / "meta.json").read_text())
    return list(can.LogReader(str(res.capture))), meta


def _assert_native_equals_python(scn: Scenario, est: str, spec: BusSpec, out: Path) -> None:
    ref = run_inprocess(scn, est, CODEC)
    frames, meta = _native_run(scn, est, spec, out)
    assert meta["node_engines"]["plant"] == "native"
    assert meta["node_reports"]["plant"]["node_engine"] == "native"
    got, want = _by_step(frames), _by_step(ref)
    assert len(want) > 3 * 1000
    assert got.keys() == want.keys()
    diff = [k for k in want if got[k] != want[k]]
    assert not diff, f"{len(diff)} frames differ, the first {diff[:3]}"
    assert_same_trace(trace(ref, scn), trace(frames, scn))


def test_native_plant_gives_the_python_nodes_lockstep_frames_udp(tmp_path: Path) -> None:
    """tt-dq on wen-5.1: every PhaseSamples, PlantTruth and PwmDuty of the reference."""
    scn = short("wen-5.1", 0.12)
    spec = BusSpec("udp_multicast", GROUP, free_port())
    _assert_native_equals_python(scn, "tt-dq", spec, tmp_path / "run")


def test_native_plant_with_latency_and_a_position_sensor(tmp_path: Path) -> None:
    """Injected latency (the duty ring, duty_age) and the sensored baseline's encoder frames."""
    from dataclasses import replace

    from bench.scenarios._schema import Latency
    from bench.scenarios._setup import with_position_sensor

    scn = with_position_sensor(short("wen-5.1", 0.08))
    scn = replace(scn, latency=Latency(sample_delay_steps=1, duty_delay_steps=2))
    spec = BusSpec("udp_multicast", GROUP, free_port())
    ref = run_inprocess(scn, "sensored", CODEC)
    frames, meta = _native_run(scn, "sensored", spec, tmp_path / "lat")
    assert meta["node_engines"]["plant"] == "native"
    got, want = _by_step(frames), _by_step(ref)
    assert any(k[0] == 0x12 for k in want)  # PositionSensor frames are compared too
    assert {k: v for k, v in got.items() if k in want} == want


@pytest.mark.socketcan
def test_native_plant_gives_the_python_nodes_lockstep_frames_vcan(tmp_path: Path) -> None:
    scn = short("wen-5.1", 0.12)
    _assert_native_equals_python(scn, "tt-dq", BusSpec("socketcan", "vcan0"), tmp_path / "vcan")


def native_realtime_run(scn: Scenario, out: Path) -> tuple[Any, dict[str, Any]]:
    """``scn`` (sensored) in real time over udp_multicast with the native nodes: the
    run's result and its ``meta.json``."""
    spec = BusSpec("udp_multicast", GROUP, free_port())
    res = run_scenario(
        scn, "sensored", spec=spec, out_dir=out, mode="realtime", progress=False, node_args=NATIVE
    )
    return res, json.loads((out / "meta.json").read_text())


def test_native_plant_in_real_time_completes_and_reports_its_counters(tmp_path: Path) -> None:
    """1 kHz real time: every period run and counted; what holds on a busy host."""
    scn = replace(short("wen-5.1", 0.2), f_sw=1000.0)
    res, meta = native_realtime_run(scn, tmp_path / "rt")
    rep = meta["node_reports"]["plant"]
    assert rep["node_engine"] == "native"
    n = round(0.2 * 1000)
    assert rep["steps"] == n
    jit = rep["jitter"]
    assert jit["n"] == n  # one clock period per plant period
    assert 0 <= rep["overruns"] <= n
    assert jit["busy_max"] >= jit["busy_p99"] >= jit["busy_median"] > 0
    # the busy time part by part (send, receive, step): each inside each period's busy time
    for part in ("send_median", "recv_median", "step_median"):
        assert 0 < jit[part] <= jit["busy_median"]
    assert jit["max"] >= jit["p99"] >= jit["median"] >= 0  # the Python node's statistics
    assert res.metrics["jitter_us"]["max"] == pytest.approx(jit["max"])
    # every valid duty frame ends in exactly one counter
    assert rep["frames_accepted"] > 0
    assert res.metrics["steps"] + res.metrics.get("steps_missing", 0) == n + 1


def test_native_plant_polls_python_between_periods_and_sends_each_sample_once(
    tmp_path: Path,
) -> None:
    """A real-time run over several of the loop's polls (every 0.2 s, taken in the slack
    after a period's step and before its wait): each period waited for once, each sample
    sent once, the steps contiguous; what holds on a busy host."""
    scn = replace(short("wen-5.1", 0.7), f_sw=2000.0)
    res, meta = native_realtime_run(scn, tmp_path / "rt")
    rep = meta["node_reports"]["plant"]
    assert rep["node_engine"] == "native"
    n = round(0.7 * 2000)
    assert rep["steps"] == rep["jitter"]["n"] == n
    steps: list[int] = []
    last = 0
    for m in can.LogReader(str(res.capture)):
        if m.arbitration_id != 0x11:  # PhaseSamples
            continue
        d = CODEC.decode(m)
        assert d is not None and d.reason is None
        last = unwrap(int(d.signals["step"]), last, 1 << CODEC.step_bits("PhaseSamples"))
        steps.append(last)
    assert steps == list(range(len(steps)))
    assert len(steps) == n + 1  # sample 0 and one after each period


def test_raw_values_are_the_codecs(lib: ctypes.CDLL) -> None:
    """``bn_plant_raw`` against :meth:`Codec.encode` on every signal the unit encodes,
    at random values, at the clip limits, on whole multiples of the scale and on exact
    half-LSB ties (half to even)."""
    lib.bn_plant_raw.argtypes = [ctypes.POINTER(_plant_native.Sig), ctypes.c_double]
    lib.bn_plant_raw.restype = ctypes.c_int64
    rng = random.Random(7)
    names = lib.bn_plant_signal_names().decode().split(",")
    checked = 0
    for full in names:
        msg, sig = full.split(".")
        lo, hi, scale, offset, mod, chk_lo, chk_hi = CODEC.signal_table(msg)[sig]
        s = _plant_native.Sig(lo, hi, scale, offset, int(mod), chk_lo, chk_hi)
        spec = CODEC.message(msg).get_signal_by_name(sig)
        values = [rng.uniform(lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo)) for _ in range(300)]
        values += [lo, hi, 0.0 if lo <= 0 <= hi else lo]
        values += [(math.floor(v / scale) + 0.5) * scale for v in values[:50]]  # ties
        # whole multiples of the scale: cantools' divmod has a remainder of 0 there
        values += [math.floor(v / scale) * scale for v in values[:50]]
        for v in values:
            want = {n: 0.0 for n in CODEC.signal_names(msg)}
            want[sig] = v
            m = CODEC.encode(msg, want)
            raw = int.from_bytes(m.data, "little") >> spec.start & ((1 << spec.length) - 1)
            got = lib.bn_plant_raw(ctypes.byref(s), v) & ((1 << spec.length) - 1)
            assert got == raw, (full, v)
            checked += 1
    assert checked > 20 * 300


def test_auto_says_why_the_python_node_serves(tmp_path: Path) -> None:
    """No C compiler and an empty library cache: auto takes the Python node with one
    line; native is refused. A scenario with [[faults]] of every group is native's
    (tests/test_native_faults.py): ``--engine native`` serves it with no line."""
    scn = tmp_path / "faulty.toml"
    scn.write_text(
        'extends = "xue-fig13"\nduration = 1.3\n[[faults]]\nat_s = 1.1\nkind = "current_lost"\n'
        'phase = "a"\n[[faults]]\nat_s = 1.2\nkind = "corrupt"\nmessage = "PwmDuty"\n'
    )
    base = [sys.executable, "-m", "bench", "plant", str(scn), "--interface", "udp_multicast",
            "--channel", GROUP, "--port", str(free_port())]  # fmt: skip
    # no compiler on PATH (the interpreter is named by its full path) and a fresh cache
    bare = {**os.environ, "PATH": str(tmp_path / "nobin"), "XDG_CACHE_HOME": str(tmp_path)}
    bare.pop("CC", None)
    res = subprocess.run(
        [*base, "--engine", "native"], cwd=ROOT, capture_output=True, text=True, timeout=60,
        env=bare,
    )  # fmt: skip
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert lines[-1].startswith("bench: error: --engine native: ")
    assert "no C compiler" in lines[-1]
    assert "Traceback" not in res.stderr
    for args, env, want in ((base, bare, 1), ([*base, "--engine", "native"], None, 0)):
        # auto: the one line, then the Python node serves (stopped here by the signal);
        # native with the faults: no line
        proc = subprocess.Popen(
            args, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env
        )
        try:
            assert proc.stdout is not None and proc.stdout.readline().strip() == "READY"
        finally:
            proc.terminate()
            _, err = proc.communicate(timeout=30)
        why = [ln for ln in err.splitlines() if "the Python node serves this run" in ln]
        assert len(why) == want, err
        assert all("no C compiler" in ln for ln in why)


def test_a_controller_under_test_is_served_by_the_native_node(tmp_path: Path) -> None:
    """``--controller external``: the native plant node serves it (its acknowledgements
    gate every lockstep period in C, and the end of its run resends the last sample until
    it answers), with no fallback line; every period run and scored, the last with the
    controller's answer."""
    import numpy as np

    from tests.test_external_controller import _run

    res, run_dir = _run(tmp_path)
    assert res.returncode == 0, res.stderr[-3000:]
    meta = json.loads((run_dir / "meta.json").read_text())
    m = json.loads((run_dir / "metrics.json").read_text())
    assert meta["node_engines"] == {"plant": "native"}
    assert m["steps"] == 3001 and m["steps_missing"] == 0
    assert m["steps_without_telemetry"] == 0
    tab = np.genfromtxt(run_dir / "signals.csv", delimiter=",", names=True)
    assert np.isfinite(tab["theta_hat"][-1])
    assert "the Python node serves this run" not in (run_dir / "plant.log").read_text()


def test_a_burst_of_commands_in_real_time_is_applied_at_its_steps() -> None:
    """Real time, 2 kHz: a burst of 100 load commands (twice each, as the bench's pacer
    sends them) arrives while the loop runs; every frame the loop receives there is met
    while draining before a step and held to the slack after it (bn_plant_loop.c), but the
    copies of a command Python already took, dropped before the ring (bn_cmd_seen_t): 100
    to 200 held, whatever a full ring handed over at once.  None is lost or
    late: each load is in the PlantTruth of its step and after, up to the next."""
    import threading

    from bench.nodes._loops import RETRANSMIT_S, make_plant_node
    from bench.wire._protocol import CMD_NONE, CMD_START

    T, n_steps, n_cmds, first = 1 / 2000.0, 1000, 100, 400
    scn = replace(short("wen-5.1", n_steps * T), f_sw=1 / T)
    node = make_plant_node(scn, CODEC)
    spec = BusSpec("udp_multicast", GROUP, free_port())
    ready, errors = threading.Event(), []

    def serve() -> None:
        try:
            _plant_native.plant_loop_native(
                spec,
                node,
                realtime=True,
                on_ready=ready.set,
                watchdog_s=10.0,
                retransmit_s=RETRANSMIT_S,
            )
        except BaseException as e:  # the test thread reports it
            errors.append(e)

    def command(seq: int, step: int, cmd: int, load: float) -> can.Message:
        sig = {"cmd": cmd, "seq": seq % 16, "step": step, "speed_ref": 0.0, "load_torque": load}
        return CODEC.encode("BenchCommand", sig)

    loads = {first + 2 * j: 0.01 * j for j in range(1, n_cmds + 1)}
    truth: dict[int, float] = {}
    thread = threading.Thread(target=serve, daemon=True)
    with can.Bus(interface="udp_multicast", channel=GROUP, port=spec.port, fd=True) as bus:
        thread.start()
        assert ready.wait(60.0), errors
        bus.send(command(0, 0, CMD_START, 0.0))
        sent, last = False, 0
        while thread.is_alive() or not sent:
            m = bus.recv(0.05)
            if m is None or m.arbitration_id != 0x100:  # PlantTruth
                continue
            d = CODEC.decode(m)
            assert d is not None and d.reason is None
            last = unwrap(int(d.signals["step"]), last, 1 << CODEC.step_bits("PlantTruth"))
            truth[last] = float(d.signals["tau_L"])
            if not sent and last >= 100:  # the loop runs: the burst, 0.15 s ahead
                for j, (step, load) in enumerate(loads.items(), start=1):
                    bus.send(command(j, step, CMD_NONE, load))
                    bus.send(command(j, step, CMD_NONE, load))
                sent = True
        thread.join(10.0)
    assert not errors, errors
    assert node.counters.late_commands == 0
    assert not node.commands.pending and node.commands.applied_seq == n_cmds % 16
    jit = node.jitter
    assert jit is not None
    # a copy that comes after Python took its command is dropped before the ring
    # (bn_cmd_seen_t); every copy is counted among the duplicates, in C or by the queue
    assert n_cmds <= jit["commands_held"] <= 2 * n_cmds
    assert node.counters.duplicates == n_cmds
    assert 1 <= jit["commands_held_max"] <= _native.HELD
    steps = sorted(loads)
    seen = 0
    for k, tau in truth.items():
        if k < steps[0]:
            continue
        want = loads[max(s for s in steps if s <= k)]
        assert tau == pytest.approx(want, abs=1e-9), (k, tau, want)
        seen += 1
    assert seen > n_steps - steps[0] - 100  # most of the truth frames were received
