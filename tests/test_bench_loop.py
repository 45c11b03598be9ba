"""The CAN bench end to end: processes, transports, latency, recording.

The in-process loop passes the same DBC frames between the same node objects
without a bus; it is the reference trace.  A lockstep run over a real
transport must reproduce it exactly (the wire quantization is the same on
both sides), also with injected latency and lost frames.
"""

from __future__ import annotations

import json
import os
import threading
from dataclasses import replace
from pathlib import Path

import can
import numpy as np
import pytest

from bench.nodes._loops import (
    command_frames,
    controller_loop,
    make_controller_node,
    make_plant_node,
    plant_loop,
    run_inprocess,
)
from bench.runs._run import run_scenario
from bench.scenarios._schema import Latency, Scenario
from bench.wire._bus import BusSpec
from tests.ports import free_port
from tests.trace_helpers import CODEC, assert_same_trace, short, trace


def udp_spec(tmp_path: Path) -> BusSpec:
    # a port of its own per run: parallel runs on this host must not hear each other
    return BusSpec("udp_multicast", "239.74.163.2", free_port())


@pytest.fixture(scope="module")
def ref_sensored() -> tuple[Scenario, dict[str, np.ndarray]]:
    scn = short("wen-5.1", 0.25)
    return scn, trace(run_inprocess(scn, "sensored", CODEC), scn)


def test_inprocess_run_is_deterministic(ref_sensored: tuple[Scenario, dict]) -> None:
    scn, ref = ref_sensored
    again = trace(run_inprocess(scn, "sensored", CODEC), scn)
    assert_same_trace(ref, again)
    # and it is a real closed loop: the motor turns under sensored FOC
    assert ref["w_m_rpm"][-1] > 5.0
    assert np.max(np.abs(ref["theta_err_deg"])) < 1.0


def test_another_seed_gives_another_trace() -> None:
    scn = short("wen-5.1", 0.1)
    noisy = replace(scn, noise=replace(scn.noise, current_std_a=0.01))
    a = trace(run_inprocess(noisy, "sensored", CODEC), noisy)
    b = trace(run_inprocess(replace(noisy, seed=noisy.seed + 1), "sensored", CODEC), noisy)
    assert not np.allclose(a["i_a"], b["i_a"])


def test_two_processes_over_udp_multicast_equal_inprocess(
    tmp_path: Path, ref_sensored: tuple[Scenario, dict]
) -> None:
    scn, ref = ref_sensored
    res = run_scenario(
        scn, "sensored", spec=udp_spec(tmp_path), out_dir=tmp_path / "run", progress=False
    )
    frames = list(can.LogReader(str(res.capture)))
    assert_same_trace(ref, trace(frames, scn))
    m = json.loads((tmp_path / "run" / "metrics.json").read_text())
    for key in (
        "theta_err_max_deg",
        "theta_err_min_deg",
        "theta_err_mean_deg",
        "theta_err_abs_mean_deg",
        "theta_err_rms_deg",
        "speed_err_max_rpm",
        "steps",
        "sim_s",
        "wall_s",
        "deadline_misses",
        "frames_rejected",
    ):
        assert key in m
    assert m["steps"] == len(ref["step"])
    assert m["steps_missing"] == 0  # every period of the scenario has its row
    assert m["frames_rejected"] == 0
    # the per-reason counts add up to the total; the second copy of every
    # command (each is sent twice) is counted apart, not as a rejection
    assert sum(m["frames_rejected_by_reason"].values()) == m["frames_rejected"]
    n_cmd = len(command_frames(scn, CODEC))
    assert m["frames_repeated_ignored"] >= n_cmd  # at least one node saw every repeat
    for f in ("signals.csv", "meta.json", "run.png"):
        assert (tmp_path / "run" / f).is_file()


@pytest.mark.parametrize(("duty", "sample"), [(2, 0), (0, 3), (2, 1)])
def test_lockstep_latency_through_link_process(tmp_path: Path, duty: int, sample: int) -> None:
    scn = short("wen-5.1", 0.06, duty_delay_steps=duty, sample_delay_steps=sample)
    ref = trace(run_inprocess(scn, "sensored", CODEC), scn)
    res = run_scenario(
        scn, "sensored", spec=udp_spec(tmp_path), out_dir=tmp_path / "lat", progress=False
    )
    frames = list(can.LogReader(str(res.capture)))
    assert_same_trace(ref, trace(frames, scn))
    # the plant reports the age of every duty it applied: exactly the injected periods
    loop = res.metrics["loop_latency_steps"]
    assert loop["min"] == loop["max"] == duty + sample
    # both buses were recorded and the wall-clock latency per direction is measured
    lat = res.metrics["latency_measured"]
    assert lat["samples"]["us_median"] > 0 and lat["duties"]["us_median"] > 0
    # ... and in periods on the plant's clock, each direction exactly as injected
    assert lat["samples"]["steps"] == sample
    assert lat["duties"]["steps"] == duty
    assert res.metrics["latency_configured"]["duties_steps"] == duty
    # and the delay is real: the same run without it differs
    ref0 = trace(run_inprocess(replace(scn, latency=Latency()), "sensored", CODEC), scn)
    n = min(len(ref0["i_a"]), len(ref["i_a"]))
    assert not np.allclose(ref0["i_a"][:n], ref["i_a"][:n])


def test_loop_latency_is_zero_without_a_link(ref_sensored: tuple[Scenario, dict]) -> None:
    _, ref = ref_sensored
    age = ref["duty_age"]
    assert age[0] == 255  # no duty yet in period 0
    assert np.all(age[2:] == 0)


def test_lockstep_recovers_lost_frames_without_changing_the_trace(tmp_path: Path) -> None:
    scn = short("wen-5.1", 0.05, drop_prob=0.02)
    ref = trace(run_inprocess(replace(scn, latency=Latency()), "sensored", CODEC), scn)
    res = run_scenario(
        scn, "sensored", spec=udp_spec(tmp_path), out_dir=tmp_path / "drop", progress=False
    )
    frames = list(can.LogReader(str(res.capture)))
    got = trace(frames, scn)
    # the plant side (bus A) carries every period exactly once in the table
    assert_same_trace(ref, got)
    assert res.metrics["retransmits"] > 0


def test_virtual_bus_threads_equal_inprocess(ref_sensored: tuple[Scenario, dict]) -> None:
    scn, ref = ref_sensored
    chan = f"t{os.getpid()}"
    bus_p = can.Bus(interface="virtual", channel=chan)
    bus_c = can.Bus(interface="virtual", channel=chan)
    bus_r = can.Bus(interface="virtual", channel=chan)
    pn = make_plant_node(scn, CODEC)
    cn = make_controller_node(scn, "sensored", CODEC)
    tc = threading.Thread(target=controller_loop, args=(bus_c, cn), kwargs={"realtime": False})
    tc.start()
    for _, m in command_frames(scn, CODEC):
        bus_r.send(m)
    plant_loop(bus_p, pn, realtime=False)
    tc.join(10)
    # the recording bus object queued every frame the others sent; drain it
    frames = [*(m for _, m in command_frames(scn, CODEC))]
    while (got := bus_r.recv(0.2)) is not None:
        frames.append(got)
    for b in (bus_p, bus_c, bus_r):
        b.shutdown()
    assert not tc.is_alive()
    assert_same_trace(ref, trace(frames, scn))


def test_realtime_run_at_1khz_reports_deadlines(tmp_path: Path) -> None:
    scn = short("xue-fig13", 0.5)
    res = run_scenario(
        scn,
        "sensored",
        spec=udp_spec(tmp_path),
        out_dir=tmp_path / "rt",
        mode="realtime",
        progress=False,
    )
    m = res.metrics
    plant = res.meta["node_reports"]["plant"]
    assert plant["steps"] == 500  # the plant ran every period of the scenario
    # the table has a row per step whose frames the recorder got (all of them
    # unless the machine stalled the recorder longer than its buffer)
    assert 0.5 * 500 < m["steps"] <= 500 + 1  # instants 0 .. 500
    assert m["deadline_misses"] == plant["overruns"]
    assert m["jitter_us"]["max"] >= m["jitter_us"]["median"] >= 0.0
    # real time: wall time follows simulated time
    assert m["wall_s"] >= 0.9 * m["sim_s"]
