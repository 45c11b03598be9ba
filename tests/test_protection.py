"""Inverter protection: thresholds, fault codes, latch and reset; trips in the plant node."""

from __future__ import annotations

import math

import pytest

from bench.nodes._loops import make_plant_node
from bench.scenarios._schema import load_scenario
from bench.wire._codec import Codec
from bench.wire._protocol import CMD_RESET, STATE_FAULT
from plant_rt import (
    FAULT_NONE,
    FAULT_OVER_CURRENT,
    FAULT_OVER_SPEED,
    FAULT_OVER_VOLTAGE,
    Protection,
    ProtectionPars,
    preset,
)

CODEC = Codec()


def test_thresholds_from_preset_are_margins_over_the_ratings() -> None:
    p = preset("xue2022")
    pp = ProtectionPars.from_preset(p.motor, p.inverter, i_margin=1.25, u_margin=1.1, w_margin=2)
    assert pp.i_trip == pytest.approx(25.0)
    assert pp.u_dc_trip == pytest.approx(594.0)
    assert pp.w_m_trip == pytest.approx(2 * 1200 * 2 * math.pi / 60)
    with pytest.raises(ValueError):
        ProtectionPars(i_trip=0.0, u_dc_trip=1.0, w_m_trip=1.0)


@pytest.mark.parametrize(
    ("values", "code"),
    [
        ((10.01, 0.0, -10.01, 500.0, 0.0), FAULT_OVER_CURRENT),
        ((0.0, -10.01, 0.0, 500.0, 0.0), FAULT_OVER_CURRENT),
        ((9.99, -9.99, 0.0, 600.01, 0.0), FAULT_OVER_VOLTAGE),
        ((9.99, -9.99, 0.0, 600.0, -100.01), FAULT_OVER_SPEED),
        ((9.99, -9.99, 0.0, 600.0, 100.0), FAULT_NONE),
        ((math.nan, 0.0, 0.0, 500.0, 0.0), FAULT_OVER_CURRENT),
        ((0.0, 0.0, 0.0, 500.0, math.nan), FAULT_OVER_SPEED),
    ],
)
def test_each_comparator_trips_with_its_code(values: tuple, code: int) -> None:
    prot = Protection(ProtectionPars(i_trip=10.0, u_dc_trip=600.0, w_m_trip=100.0))
    assert prot.check(*values) == code
    assert prot.fault == code


def test_fault_is_latched_until_reset_and_first_fault_wins() -> None:
    prot = Protection(ProtectionPars(i_trip=10.0, u_dc_trip=600.0, w_m_trip=100.0))
    assert prot.check(0.0, 0.0, 0.0, 500.0, 150.0) == FAULT_OVER_SPEED
    # back in range, another violation: still the first fault
    assert prot.check(20.0, 0.0, 0.0, 500.0, 0.0) == FAULT_OVER_SPEED
    assert prot.reset() == FAULT_OVER_SPEED
    assert prot.check(0.0, 0.0, 0.0, 500.0, 0.0) == FAULT_NONE
    assert prot.trips == {FAULT_OVER_SPEED: 1}


def _started_node(protection: ProtectionPars | None = None):
    scn = load_scenario("wen-5.1").with_overrides(duration=1.0)
    node = make_plant_node(scn, CODEC, protection=protection)
    node.started = True
    return node


def test_plant_node_trips_on_over_current_and_opens_the_switches() -> None:
    node = _started_node()
    i_trip = node.protection.pars.i_trip
    assert i_trip == pytest.approx(1.5 * 8.0)  # wen2023: 1.5 i_max
    peak = 0.0
    trip_frames = []
    for _ in range(400):
        node.duties[node.needed_duty()] = (1.0, 0.0, 0.0, True)  # a faulty controller
        out = node.advance_lockstep()
        peak = max(peak, max(abs(x) for x in node.plant.currents_abc()))
        trip_frames += [m for m in out if m.arbitration_id == CODEC.frame_id("PlantStatus")]
        if node.fault:
            break
    assert node.fault == FAULT_OVER_CURRENT
    assert peak > i_trip
    assert len(trip_frames) == 1
    st = CODEC.decode(trip_frames[0])
    assert st is not None and st.ok
    assert st.signals["fault_code"] == FAULT_OVER_CURRENT and st.signals["state"] == STATE_FAULT
    # from now on the inverter is off: the current decays instead of rising
    i_at_trip = max(abs(x) for x in node.plant.currents_abc())
    for _ in range(100):
        node.duties[node.needed_duty()] = (1.0, 0.0, 0.0, True)
        node.advance_lockstep()
    assert max(abs(x) for x in node.plant.currents_abc()) < 0.2 * i_at_trip
    assert node.fault == FAULT_OVER_CURRENT  # latched
    samples = CODEC.decode(node.frames_now()[0])
    assert samples is not None and samples.signals["status"] == STATE_FAULT


def advance(node) -> None:
    node.duties[node.needed_duty()] = (0.5, 0.5, 0.5, True)
    node.advance_lockstep()


def test_plant_node_trips_on_over_speed_and_reset_rearms() -> None:
    node = _started_node()
    w_trip = node.protection.pars.w_m_trip
    node.plant.impose_speed(0.99 * w_trip)
    advance(node)
    assert node.fault == FAULT_NONE
    node.plant.impose_speed(1.01 * w_trip)
    advance(node)
    assert node.fault == FAULT_OVER_SPEED
    assert node.trips == {"over_speed": 1}
    # a reset while the machine is still too fast trips again at once
    cmd = CODEC.encode(
        "BenchCommand",
        {"cmd": CMD_RESET, "seq": 1, "step": node.plant.k, "speed_ref": 0.0, "load_torque": 0.0},
    )
    node.on_message(cmd)
    advance(node)  # the reset applies at the end of this period ...
    assert node.resets == 1 and node.fault == FAULT_NONE
    advance(node)  # ... and the next period's check trips again
    assert node.fault == FAULT_OVER_SPEED and node.trips == {"over_speed": 2}
    node.plant.impose_speed(0.5 * w_trip)
    cmd2 = CODEC.encode(
        "BenchCommand",
        {"cmd": CMD_RESET, "seq": 2, "step": node.plant.k, "speed_ref": 0.0, "load_torque": 0.0},
    )
    node.on_message(cmd2)
    advance(node)
    advance(node)
    assert node.fault == FAULT_NONE and node.resets == 2
