"""The native plant node with what the Python node alone served before: sensor noise,
a load profile, the energy meter, and the scenario's fault timeline.

Each is held to the Python node: a lockstep run on udp_multicast with the native
plant gives the in-process reference's frames (the Python node's) bit for bit
(:func:`tests.test_native_plant._assert_native_equals_python`), and, with faults,
the ``faults`` entries of metrics.json equal.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import can
import pytest

from bench.nodes._loops import run_inprocess
from bench.runs._local import run_local
from bench.runs._run import run_scenario
from bench.scenarios._faults import Fault
from bench.scenarios._schema import Noise, Scenario, load_scenario
from bench.wire._bus import BusSpec
from bench.wire._protocol import unwrap
from tests.ports import free_port
from tests.test_native_plant import (
    GROUP,
    NATIVE,
    _assert_native_equals_python,
    native_realtime_run,
)
from tests.trace_helpers import CODEC, short


def test_sensor_noise_native_gives_the_python_nodes_frames(tmp_path: Path) -> None:
    """Current noise and ADC quantisation: the same draws, in the same order, in C."""
    scn = replace(short("wen-5.1", 0.12), noise=Noise(current_std_a=0.05, adc_bits=12))
    spec = BusSpec("udp_multicast", GROUP, free_port())
    _assert_native_equals_python(scn, "tt-dq", spec, tmp_path / "noise")


def test_a_plant_stepped_by_a_c_caller_reports_the_cores_energy_meter() -> None:
    """The meter integrates in the core whoever steps it; :meth:`Plant.adopt_core` reads it
    (the native node's path), equal to the Python-stepped plant's to the bit."""
    from plant_rt import Plant, preset

    pre = preset("wen2023")
    a = Plant(pre.motor, pre.inverter, 1.0 / pre.f_sw, meter=True)
    b = Plant(pre.motor, pre.inverter, 1.0 / pre.f_sw, meter=True)
    duties = [(0.5 + 0.3 * (k % 7) / 7, 0.5, 0.5 - 0.2 * (k % 5) / 5) for k in range(200)]
    for d in duties:
        a.step(*d)
    for k, d in enumerate(duties):  # as bn_plant.c does: the core alone
        b._core.step(*d, k * b.T_s)
    b.adopt_core(len(duties), -1)
    assert a.meter is not None and b.meter is not None
    assert a.meter.e_in != 0.0 and a.meter.e_cu > 0.0
    assert b.meter == a.meter


def test_noise_load_profile_and_meter_leave_the_native_plant_eligible() -> None:
    """The fallback line names none of them any more (a run with a step count)."""
    from bench.nodes._plant_node import PlantNode
    from bench.nodes.native import _plant_native
    from plant_rt import Plant, SensorPars, StepLoad, preset
    from tests.trace_helpers import CODEC

    pre = preset("wen2023")
    plant = Plant(
        pre.motor,
        pre.inverter,
        1.0 / pre.f_sw,
        sensors=SensorPars(noise_i=0.1, noise_u=0.5, seed=3),
        load=StepLoad(0.01, 1.0),
        meter=True,
    )
    node = PlantNode(CODEC, plant, n_steps=100)
    why = _plant_native.native_missing(node, "udp_multicast")
    assert why is None
    node.n_steps = 0  # until stopped: the noise is drawn before the loop, so not native
    why = _plant_native.native_missing(node, "udp_multicast")
    assert why is not None and "noise" in why


def test_noise_values_are_the_generators_calls_in_the_cores_order() -> None:
    """:func:`noise_values` against the core's own calls of the Python generator."""
    import itertools

    from bench.nodes.native._plant_native import noise_values
    from plant_rt import Plant, SensorPars, preset

    pre = preset("wen2023")
    sens = SensorPars(noise_i=0.1, noise_u=0.5, seed=11)
    a = Plant(pre.motor, pre.inverter, 1.0 / pre.f_sw, sensors=sens)
    b = Plant(pre.motor, pre.inverter, 1.0 / pre.f_sw, sensors=sens)
    ideal = Plant(pre.motor, pre.inverter, 1.0 / pre.f_sw)
    vals = list(itertools.islice(noise_values(b), 4 * 5))
    for j in range(5):
        s, t = a.sample(), ideal.sample()
        got = (s.i_a - t.i_a, s.i_b - t.i_b, s.i_c - t.i_c, s.u_dc - t.u_dc)
        want = vals[4 * j : 4 * j + 4]
        assert got[:3] == tuple(want[:3])  # ideal ADC: the currents' noise exactly
        assert abs(got[3] - want[3]) < 1e-12
        a.step(0.5, 0.5, 0.5)
        ideal.step(0.5, 0.5, 0.5)


#: Per-step frames compared, with PlantCurrents (DBC 2.4, sent in runs with faults).
_PER_STEP = {
    0x10: "PwmDuty",
    0x11: "PhaseSamples",
    0x12: "PositionSensor",
    0x100: "PlantTruth",
    0x102: "PlantCurrents",
}


def _frames_by_step(frames: Sequence[can.Message]) -> dict[tuple[int, int], bytes]:
    """Each per-step frame by (identifier, step unwrapped); the recorder frames without run_id;
    a frame the codec rejects (babble's) by (identifier, -1 - its payload's hash) (a set:
    a lockstep resend repeats it)."""
    out: dict[tuple[int, int], bytes] = {}
    last: dict[int, int] = {}
    for m in frames:
        name = _PER_STEP.get(m.arbitration_id)
        if name is None:
            continue
        d = CODEC.decode(m)
        assert d is not None, name
        if d.reason is not None:
            out[(m.arbitration_id, -1 - abs(hash(bytes(m.data))))] = bytes(m.data)
            continue
        data = bytes(m.data)
        if "run_id" in d.signals:  # the run's nonce differs between two runs
            s = dict(d.signals)
            s["run_id"] = 0
            data = bytes(CODEC.encode(name, s).data)
        step = unwrap(
            int(d.signals["step"]), last.get(m.arbitration_id, 0), 1 << CODEC.step_bits(name)
        )
        last[m.arbitration_id] = step
        assert out.setdefault((m.arbitration_id, step), data) == data, (name, step)
    return out


def _fault(i: int, kind: str, at_s: float, dur: float | None, **params: Any) -> Fault:
    return Fault(i, kind, at_s, dur, params, None)


def _assert_faults_native_equal_python(
    scn: Scenario, est: str, out: Path, *, oracle: str = "inprocess"
) -> dict[str, Any]:
    """The native plant's lockstep run against the Python node's: the in-process reference
    (``oracle="inprocess"``), or the Python plant node's process run on udp_multicast
    (``"process"``: its counters compared too)."""
    spec = BusSpec("udp_multicast", GROUP, free_port())
    res = run_scenario(scn, est, spec=spec, out_dir=out / "nat", progress=False, node_args=NATIVE)
    meta = json.loads((out / "nat" / "meta.json").read_text())
    assert meta["node_engines"]["plant"] == "native"
    got = _frames_by_step(list(can.LogReader(str(res.capture))))
    if oracle == "inprocess":
        ref = run_local(scn, est, out / "ref", plots=False)
        want = _frames_by_step(run_inprocess(scn, est, CODEC))
    else:
        py = {"plant": ["--engine", "python"], "controller": []}
        spec = BusSpec("udp_multicast", GROUP, free_port())
        ref = run_scenario(scn, est, spec=spec, out_dir=out / "py", progress=False, node_args=py)
        py_meta = json.loads((out / "py" / "meta.json").read_text())
        assert py_meta["node_engines"]["plant"] == "python"
        want = _frames_by_step(list(can.LogReader(str(ref.capture))))
        a, b = meta["node_reports"]["plant"], py_meta["node_reports"]["plant"]
        for key in ("faults", "late_duties", "duty_rejected", "trips", "steps"):
            assert a[key] == b[key], key
    assert any(k[0] == 0x102 for k in want)  # PlantCurrents compared too
    assert got.keys() == want.keys()
    diff = sorted(k for k in want if got[k] != want[k])
    assert not diff, f"{len(diff)} frames differ, the first {diff[:3]}"
    assert res.metrics["faults"] == ref.metrics["faults"]
    out_meta: dict[str, Any] = meta
    return out_meta


def test_plant_faults_native_give_the_python_nodes_frames(tmp_path: Path) -> None:
    """Every machine and leg kind, overlapping: the parameters and legs on the exact period."""
    scn = short("wen-5.1", 0.12)
    faults = (
        _fault(0, "resistance_drift", 0.02, 0.05, R_s_factor=1.5),
        _fault(1, "demagnetisation", 0.04, None, psi_f_factor=0.8),
        _fault(2, "resistance_drift", 0.05, 0.03, R_s_factor=1.2),
        _fault(3, "dc_link_step", 0.06, 0.02, u_dc_v=400.0),
        _fault(4, "open_switch", 0.07, 0.02, phase="a", device="upper"),
        _fault(5, "open_phase", 0.095, 0.01, phase="b"),
        _fault(6, "open_switch", 0.1, None, phase="c", device="lower"),
    )
    _assert_faults_native_equal_python(replace(scn, faults=faults), "tt-dq", tmp_path)


def test_sensor_faults_native_give_the_python_nodes_frames(tmp_path: Path) -> None:
    """Every sensor kind, overlapping in one phase (their order), with noise; the sensored
    baseline's encoder lost for a while (its frames not sent, counted in the report)."""
    from bench.scenarios._setup import with_position_sensor

    scn = with_position_sensor(short("wen-5.1", 0.1))
    scn = replace(scn, noise=Noise(current_std_a=0.02))
    faults = (
        _fault(0, "current_offset", 0.02, 0.04, phase="a", a=0.3),
        _fault(1, "current_gain", 0.03, 0.02, phase="a", factor=1.2),
        _fault(2, "current_stuck", 0.05, 0.01, phase="b"),
        _fault(3, "current_lost", 0.07, 0.01, phase="a"),
        _fault(4, "dc_voltage_offset", 0.04, None, v=-12.5),
        _fault(5, "position_sensor_lost", 0.08, 0.005),
        _fault(6, "current_stuck", 0.0, 0.01, phase="a"),
    )
    meta = _assert_faults_native_equal_python(replace(scn, faults=faults), "sensored", tmp_path)
    rep = meta["node_reports"]["plant"]
    k0, k1 = faults[5].periods(float(meta["T_s"]))
    assert k1 is not None and k1 - k0 > 10
    # NodeFaults.sends counts every instant of the window (the Python node's report)
    assert rep["faults"] == {
        "duties_lost": 0,
        "not_sent": {"PositionSensor": k1 - k0},
        "babbled": 0,
    }


def test_bus_faults_native_give_the_python_nodes_frames(tmp_path: Path) -> None:
    """The lockstep bus kinds: duties dropped at random and corrupted (the period runs with
    the last duty, counted late), a duty delay with its duty_age, foreign frames babbled;
    every draw NodeFaults' own, every count in the report the Python node's."""
    scn = short("wen-5.1", 0.12)
    faults = (
        _fault(0, "drop", 0.02, 0.02, message="PwmDuty", prob=0.3),
        _fault(1, "corrupt", 0.045, 0.002, message="PwmDuty"),
        _fault(2, "delay", 0.06, 0.02, message="PwmDuty", steps=3),
        _fault(3, "babble", 0.05, 0.04, rate_hz=500.0),
        _fault(4, "delay", 0.07, 0.005, message="PwmDuty", steps=1),
    )
    # a lost duty is held at the last one applied, never a later one already here, so
    # the in-process reference is the process runs' too (test_faults_run.py)
    meta = _assert_faults_native_equal_python(
        replace(scn, faults=faults), "tt-dq", tmp_path, oracle="inprocess"
    )
    rep = meta["node_reports"]["plant"]
    assert rep["faults"]["duties_lost"] > 10
    assert rep["faults"]["babbled"] == 2 * 20
    assert meta["node_engines"]["plant"] == "native"
    assert rep["late_duties"] > rep["faults"]["duties_lost"]
    assert rep["duty_rejected"]["bad_crc"] > 0


def test_silence_in_real_time_native_sends_nothing_either_way(tmp_path: Path) -> None:
    """Real time, 1 kHz: a 5-period silence: no PhaseSamples or PositionSensor of those
    instants, no duty taken (counted as the Python node counts them); what holds on a
    busy host (the counts are per instant, not per frame that arrived)."""
    scn = replace(short("wen-5.1", 0.3), f_sw=1000.0)
    scn = replace(scn, faults=(_fault(0, "silence", 0.15, 0.005),))
    _, meta = native_realtime_run(scn, tmp_path / "rt")
    rep = meta["node_reports"]["plant"]
    assert meta["node_engines"]["plant"] == "native"
    assert rep["steps"] == 300
    assert rep["faults"]["not_sent"] == {"PhaseSamples": 5, "PositionSensor": 5}
    assert rep["faults"]["babbled"] == 0


def _xue(tmp_path: Path, faults: list[dict[str, Any]], duration: float = 0.6) -> Scenario:
    """xue-fig13 (1 kHz, as tests/test_faults_run.py) with a fault timeline."""
    lines = ['extends = "xue-fig13"', f"duration = {duration}", f"score_from_s = {duration / 2}"]
    for f in faults:
        lines.append("[[faults]]")
        lines += [f"{k} = {v!r}".replace("'", '"') for k, v in f.items()]
    src = tmp_path / "f.toml"
    src.write_text("\n".join(lines) + "\n")
    return load_scenario(str(src))


#: xue-fig13's period (s) and the fault's first period.
_T_S, _K0 = 1e-3, 300


@pytest.mark.parametrize(
    ("fault", "last"),
    [
        ({"kind": "drop", "message": "PhaseSamples", "prob": 1.0}, _K0 - 1),
        ({"kind": "silence"}, _K0 - 2),
    ],
)
def test_a_lockstep_sample_burst_native_trips_as_the_python_node(
    tmp_path: Path, fault: dict[str, Any], last: int
) -> None:
    """50 ms of lost samples in lockstep (tests/test_faults_run.py's rules): each lost
    sample is sent again, in order, before the next that gets through, its late answer
    counted lost, the periods run with the last duty applied, and the watchdog trips W
    periods after the last duty in time (the answer to sample K0 - 1; silence loses the
    duties too, so one period earlier).  The native plant's frames are the Python node's
    bit for bit, and so are the faults' metrics."""
    from bench.nodes._loops import WATCHDOG_MIN_S, WATCHDOG_PERIODS

    at = {"at_s": _K0 * _T_S, "duration_s": 0.05, "expect": "trip"}
    scn = _xue(tmp_path, [{**at, **fault}])
    meta = _assert_faults_native_equal_python(scn, "sensored", tmp_path)
    rep = meta["node_reports"]["plant"]
    W = max(WATCHDOG_PERIODS, math.ceil(WATCHDOG_MIN_S / _T_S - 1e-9))
    assert rep["fault"] == "watchdog" and rep["fault_step"] == last + W
    assert rep["faults"]["not_sent"]["PhaseSamples"] == 50
    # the answers to the samples sent again come after their periods: none applied
    assert rep["faults"]["duties_lost"] + rep["duty_rejected"].get("stale_counter", 0) > 0


def test_a_short_lockstep_sample_loss_native_is_ridden_through_as_by_the_python_node(
    tmp_path: Path,
) -> None:
    """5 ms of lost samples: the periods K0 + 1 .. K0 + 5 run with duty K0, aging 1 .. 5,
    and the duties are fresh again once the samples sent again are answered; the native
    plant's frames (PlantTruth.duty_age among them) are the Python node's bit for bit."""
    fault = {"at_s": _K0 * _T_S, "duration_s": 0.005, "kind": "drop",
             "message": "PhaseSamples", "prob": 1.0, "expect": "ride_through"}  # fmt: skip
    scn = _xue(tmp_path, [fault])
    meta = _assert_faults_native_equal_python(scn, "sensored", tmp_path)
    rep = meta["node_reports"]["plant"]
    assert rep["fault"] == "none" and rep["faults"]["not_sent"] == {"PhaseSamples": 5}
    (capture,) = (tmp_path / "nat").glob("capture.*")
    frames = list(can.LogReader(str(capture)))
    ages: dict[int, int] = {}
    last = 0
    for m in frames:
        if m.arbitration_id == CODEC.frame_id("PlantTruth"):
            d = CODEC.decode(m)
            assert d is not None and d.reason is None
            last = unwrap(int(d.signals["step"]), last, 1 << CODEC.step_bits("PlantTruth"))
            ages[last] = int(d.signals["duty_age"])
    # PlantTruth of instant k: the age of the duty of period k - 1
    assert [ages[k] for k in range(_K0, _K0 + 9)] == [0, 0, 1, 2, 3, 4, 5, 0, 0]


def test_lockstep_sample_loss_and_real_time_us_delay_leave_the_native_plant_eligible() -> None:
    """The native unit holds NodeFaults' rules for them (the tests above and below), so the
    fallback line names none of them, in either mode."""
    from bench.nodes._fault_bus import NodeFaults
    from bench.nodes._plant_node import PlantNode
    from bench.nodes.native import _plant_native
    from plant_rt import Plant, preset

    pre = preset("wen2023")
    node = PlantNode(CODEC, Plant(pre.motor, pre.inverter, 1.0 / pre.f_sw), n_steps=100)
    for fault in (
        _fault(0, "drop", 0.001, 0.001, message="PhaseSamples", prob=1.0),
        _fault(0, "silence", 0.001, 0.001),
        _fault(0, "delay", 0.001, 0.002, message="PwmDuty", us=30.0),
        _fault(0, "delay", 0.001, 0.002, message="PwmDuty", steps=2),
    ):
        node.faults = NodeFaults([fault], node.plant, 0)
        for realtime in (False, True):
            node.realtime = realtime
            assert _plant_native.native_missing(node, "udp_multicast") is None, fault
    node.n_steps = 0  # the tables are made for the periods the run has
    why = _plant_native.native_missing(node, "udp_multicast")
    assert why is not None and "n_steps" in why


class _FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def _delay_realtime(
    tmp_path: Path, us: float | None, answer_s: float, *, native: bool
) -> tuple[list[int], list[list[bytes]], int]:
    """tests/test_fault_delay_realtime.py's drive of a real-time plant on a fake clock (the
    node's clock and the frames' receive stamps), through the Python node or the C unit
    (``bn_plant_on_duty``, ``bn_plant_advance``): each period's duty age, its frames, and
    the late duties counted."""
    import ctypes

    from bench.nodes._loops import command_frames, make_plant_node
    from bench.nodes.native import _plant_native as pn

    faults = [] if us is None else [
        {"at_s": _K0 * _T_S, "duration_s": 0.04, "kind": "delay", "message": "PwmDuty", "us": us}
    ]  # fmt: skip
    scn = _xue(tmp_path, faults, duration=0.5)
    node = make_plant_node(scn, CODEC)
    node.realtime = True
    clock = _FakeClock()
    node.clock = clock
    for _, m in command_frames(scn, CODEC):
        node.on_message(m)
    node.apply_commands()
    ages: list[int] = []
    out: list[list[bytes]] = []
    pending: list[can.Message] = []
    if native:
        dll = pn._lib()
        u = pn.Unit()
        keep = (pn.NoiseDraws(node, u), pn.NativeFaults(node, u))
        pn._fill_config(dll, node, u, True, False)
        sync = pn._Sync(node, u, dll.bn_plant_reject_names().decode().split(","))
        sync.push_all()
    for k in range(400):
        clock.t = 1000.0 + k * _T_S  # the period's start
        if native:
            for m in pending:
                f = pn.to_frame(m)
                f.t_ns = round(m.timestamp * 1e9)
                dll.bn_plant_on_duty(ctypes.byref(u), ctypes.byref(f))
            dll.bn_plant_advance(ctypes.byref(u))
            ages.append(int(u.duty_age))
            out.append([bytes(u.out[j].data[: u.out[j].len]) for j in range(u.n_out)])
            u.n_out = 0
        else:
            for m in pending:
                node.on_message(m)
            frames = node.advance_realtime()
            ages.append(node.duty_age)
            out.append([bytes(m.data) for m in frames])
        pending = []
        duty = CODEC.encode(
            "PwmDuty",
            {"duty_a": 0.5, "duty_b": 0.5, "duty_c": 0.5, "enable": 1, "step": (k + 1) % 1024},
        )
        duty.timestamp = clock.t + answer_s  # the answer to sample k
        pending.append(duty)
    if native:
        sync.pull()
        del keep
    return ages, out, node.counters.late_duties


@pytest.mark.parametrize(("us", "answer_s"), [(300.0, 0.5e-3), (300.0, 0.8e-3), (2500.0, 0.2e-3)])
def test_a_real_time_us_delay_native_gives_the_python_nodes_periods(
    tmp_path: Path, us: float, answer_s: float
) -> None:
    """A duty frame held ``us`` from its receive stamp, a period applying the newest duty
    released by its start (tests/test_fault_delay_realtime.py's cases): on the same fake
    clock the C unit gives the Python node's duty ages, frames and late duties, period
    for period; and the delay acts (ages above 0 in the window where it must)."""
    want = _delay_realtime(tmp_path, us, answer_s, native=False)
    got = _delay_realtime(tmp_path, us, answer_s, native=True)
    assert got[0] == want[0]
    assert got[2] == want[2]
    diff = [k for k in range(len(want[1])) if got[1][k] != want[1][k]]
    assert not diff, f"the frames of periods {diff[:5]} differ"
    ages = got[0][_K0 : _K0 + 40]
    if us * 1e-6 + answer_s < _T_S:
        assert set(ages) == {0}
    else:
        assert max(ages) >= 1 and set(got[0][_K0 + 40 :]) == {0}


def test_the_native_bus_stamps_a_frame_at_its_arrival_as_python_can_does() -> None:
    """A real-time ``us`` delay holds a duty from its receive stamp: the kernel's
    (SO_TIMESTAMPNS, python-can's), not the time the loop drained its socket, which
    in the native loop is the next period's start.  A frame received 50 ms after it
    arrived carries its arrival time: a stamp between the times before and after the
    send, not the drain's (a busy host only lengthens the waits, and a stall inside the
    send moves the time after it, not the rule)."""
    import time

    from bench.nodes.native._plant_native import open_native_bus

    spec = BusSpec("udp_multicast", GROUP, free_port())
    nat = open_native_bus(spec)
    py = spec.open()
    try:
        duty = CODEC.encode(
            "PwmDuty", {"duty_a": 0.5, "duty_b": 0.5, "duty_c": 0.5, "enable": 1, "step": 1}
        )
        # the kernel turns receive stamps on for the whole host from a work queue after
        # the first socket asks (net_enable_timestamp); a datagram that arrives before
        # that work ran is stamped when it is drained (__sock_recv_timestamp's race
        # branch), and a busy host delays the work.  Probe until a frame keeps its
        # arrival time, then measure.
        t_end = time.monotonic() + 10.0
        while time.monotonic() < t_end:
            py.send(duty)
            t_sent = time.time()
            time.sleep(0.02)
            probe = nat.recv(1.0)
            if probe is not None and probe.t_ns * 1e-9 <= t_sent + 0.01:
                break
        while nat.recv(0.05) is not None:  # nothing of the probes left queued
            pass
        t_before = time.time()
        py.send(duty)
        t_after = time.time()
        time.sleep(0.05)
        f = nat.recv(1.0)
        assert f is not None and f.id == duty.arbitration_id
        stamp = f.t_ns * 1e-9
        # the drain came 50 ms or more after t_after: a drain-time stamp is out of range
        assert t_before - 0.005 <= stamp <= t_after + 0.005
    finally:
        py.shutdown()
        nat.close()


def test_a_real_time_us_delay_is_served_by_the_native_plant(tmp_path: Path) -> None:
    """Real time, 1 kHz: a 300 us delay for 50 ms runs on the native loop (no fallback
    line), every period run; which periods it costs depends on when the answers arrive
    (the fake-clock test above holds the rule), so only what a busy host keeps is asserted."""
    scn = replace(short("wen-5.1", 0.3), f_sw=1000.0)
    scn = replace(scn, faults=(_fault(0, "delay", 0.15, 0.05, message="PwmDuty", us=300.0),))
    res, meta = native_realtime_run(scn, tmp_path / "rt")
    assert meta["node_engines"]["plant"] == "native"
    assert meta["node_reports"]["plant"]["steps"] == 300
    assert [f["kind"] for f in res.metrics["faults"]] == ["delay"]
