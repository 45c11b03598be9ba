"""Watchdogs: the plant's safe state when duties stop, the controller's when samples stop."""

from __future__ import annotations

import os
import threading

import can

from bench.nodes._loops import (
    command_frames,
    controller_loop,
    make_controller_node,
    make_plant_node,
    plant_loop,
    watchdog_periods,
)
from bench.scenarios._schema import load_scenario
from bench.wire._codec import Codec
from bench.wire._protocol import CMD_RESET, STATE_FAULT
from plant_rt import FAULT_NONE, FAULT_WATCHDOG

CODEC = Codec()
STATUS = CODEC.frame_id("PlantStatus")


def duty(step: int) -> can.Message:
    return CODEC.encode(
        "PwmDuty", {"duty_a": 0.5, "duty_b": 0.5, "duty_c": 0.5, "enable": 1, "step": step}
    )


def reset(step: int, seq: int) -> can.Message:
    return CODEC.encode(
        "BenchCommand",
        {"cmd": CMD_RESET, "seq": seq, "step": step, "speed_ref": 0.0, "load_torque": 0.0},
    )


def test_default_watchdog_time() -> None:
    assert watchdog_periods(1e-3) == 20  # 10 periods, but not less than 20 ms
    assert watchdog_periods(1e-4) == 200
    assert watchdog_periods(1e-4, 0.001) == 10


def test_realtime_watchdog_trips_after_the_configured_periods_and_needs_a_reset() -> None:
    scn = load_scenario("xue-fig13").with_overrides(duration=10.0)
    n_wd = 7
    node = make_plant_node(scn, CODEC, watchdog_s=n_wd * 1e-3)
    assert node.watchdog_periods == n_wd
    node.realtime = True
    node.started = True
    applied: list[bool] = []
    step = node.plant.step

    def logged(a: float, b: float, c: float, en: bool = True) -> None:
        applied.append(en)
        step(a, b, c, en)

    node.plant.step = logged  # type: ignore[method-assign,assignment]
    for _ in range(30):  # duties every period: no trip
        node.on_message(duty(node.plant.k + 1))
        node.advance_realtime()
    assert node.fault == FAULT_NONE and all(applied[1:])
    last = node.plant.k
    status: list[can.Message] = []
    while node.fault == FAULT_NONE and node.plant.k < last + 100:
        status += [m for m in node.advance_realtime() if m.arbitration_id == STATUS]
    # the last duty came in period last - 1: the n_wd-th period after it runs in the safe state
    assert node.fault == FAULT_WATCHDOG
    assert node.fault_step == last - 1 + n_wd
    assert applied[-1] is False and all(applied[-n_wd:-1])
    assert len(status) == 1
    st = CODEC.decode(status[0])
    assert st is not None and st.ok
    assert (st.signals["state"], st.signals["fault_code"]) == (STATE_FAULT, FAULT_WATCHDOG)
    # duties again, but latched: the switches stay open
    for _ in range(10):
        node.on_message(duty(node.plant.k + 1))
        node.advance_realtime()
    assert node.fault == FAULT_WATCHDOG and not any(applied[-10:])
    node.on_message(reset(node.plant.k, 3))
    node.on_message(duty(node.plant.k + 1))
    node.advance_realtime()
    for _ in range(5):
        node.on_message(duty(node.plant.k + 1))
        node.advance_realtime()
    assert node.fault == FAULT_NONE and node.resets == 1 and all(applied[-5:])


def test_lockstep_watchdog_trips_after_the_configured_rounds_on_a_bus() -> None:
    scn = load_scenario("wen-5.1").with_overrides(duration=1.0)
    chan = f"wd{os.getpid()}"
    bus_p = can.Bus(interface="virtual", channel=chan)
    bus_r = can.Bus(interface="virtual", channel=chan)
    rounds = 3
    node = make_plant_node(scn, CODEC, watchdog_rounds=rounds)
    stop = threading.Event()
    t = threading.Thread(
        target=plant_loop, args=(bus_p, node), kwargs={"realtime": False, "stop": stop.is_set}
    )
    t.start()
    bus_r.send(command_frames(scn, CODEC)[0][1])  # start
    # one duty arms the watchdog (period 1 runs with it), then the controller is gone
    bus_r.send(duty(1))
    frames: list[can.Message] = []
    while not any(m.arbitration_id == STATUS for m in frames):
        m = bus_r.recv(5.0)
        assert m is not None, "no fault frame"
        frames.append(m)
    stop.set()
    t.join(5.0)
    for b in (bus_p, bus_r):
        b.shutdown()
    assert not t.is_alive()
    st = CODEC.decode(frames[-1])
    assert st is not None and st.signals["fault_code"] == FAULT_WATCHDOG
    # periods 0, 1 and 2 (period 0 needs no duty, period 1 has its duty), then all
    # three again in every retransmission round before the trip: the trip comes in
    # the round-th round
    n_samples = sum(m.arbitration_id == CODEC.frame_id("PhaseSamples") for m in frames)
    assert n_samples == 3 + 3 * (rounds - 1)
    assert node.fault == FAULT_WATCHDOG and node.plant.k == 2


def test_lockstep_watchdog_is_not_armed_before_the_first_duty() -> None:
    """A slow first answer (a loaded host) does not trip it: the stall error reports a missing one."""
    scn = load_scenario("wen-5.1").with_overrides(duration=1.0)
    node = make_plant_node(scn, CODEC, watchdog_rounds=3)
    node.on_message(command_frames(scn, CODEC)[0][1])
    node.apply_commands()
    node.frames_now()
    node.advance_lockstep()  # period 0 needs no duty
    for _ in range(10):
        node.on_duty_timeout()
    assert node.fault == FAULT_NONE and node.trips == {}
    node.on_message(duty(1))
    node.advance_lockstep()
    for _ in range(3):
        node.on_duty_timeout()
    assert node.fault == FAULT_WATCHDOG


def test_controller_disables_pwm_when_samples_stop_in_real_time() -> None:
    scn = load_scenario("wen-5.1").with_overrides(duration=1.0)
    chan = f"cwd{os.getpid()}"
    bus_c = can.Bus(interface="virtual", channel=chan)
    bus_r = can.Bus(interface="virtual", channel=chan)
    node = make_controller_node(scn, "sensored", CODEC)
    t = threading.Thread(
        target=controller_loop,
        args=(bus_c, node),
        kwargs={"realtime": True, "sample_timeout_s": 0.1, "idle_s": 1.0},
    )
    t.start()
    pn = make_plant_node(scn, CODEC)
    bus_r.send(command_frames(scn, CODEC)[0][1])
    for _ in range(20):
        for m in pn.frames_now():
            bus_r.send(m)
        while not pn.ready():
            got = bus_r.recv(2.0)
            assert got is not None
            pn.on_message(got)
        pn.advance_lockstep()
    # samples stop; the controller times out, then gets samples again
    t.join(3.0)
    assert not t.is_alive()  # idle_s ended it
    assert node.sample_timeouts == 1 and node.faulted
    out = [o for m in pn.frames_now() for o in node.on_message(m)]
    d = CODEC.decode(out[0])
    assert d is not None and d.name == "PwmDuty" and d.signals["enable"] == 0
    for b in (bus_c, bus_r):
        b.shutdown()
