"""Fuzzing the nodes: random frames never crash a node, are all counted, never reach the inverter.

The oracle is independent of the codec: the raw CRC-8 of ``bench.wire._e2e`` and a
by-hand unpacking of the ``PwmDuty`` layout (``bench.studies._soak``).
"""

from __future__ import annotations

import can
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bench.nodes._loops import make_controller_node, make_plant_node
from bench.scenarios._schema import load_scenario
from bench.studies._soak import FrameFuzzer, FuzzResult, StepGuard, e2e_ok, fuzz_node, raw_duty
from bench.wire._bus import BusSpec
from bench.wire._codec import Codec
from tests.ports import free_port

CODEC = Codec()
FRAMES = 12_000


def scn(seed: int = 0):
    return load_scenario("wen-5.1").with_overrides(duration=1e4, seed=seed)


def check(res: FuzzResult) -> None:
    assert res.exceptions == []
    assert res.violations == []
    assert res.out_of_range_outputs == 0
    c = res.counters
    # every frame ends in exactly one counter
    assert c["frames_seen"] == res.frames
    # every corrupt frame addressed to the node is rejected for the oracle's reason
    assert c["reject_reasons"].get("bad_length", 0) == res.expected["bad_length"] > 0
    assert c["reject_reasons"].get("bad_crc", 0) == res.expected["bad_crc"] > 0
    assert c["frames_rejected"] == sum(
        v for k, v in c["reject_reasons"].items() if k != "repeated_counter"
    )
    assert c["frames_accepted"] > 0 and c["frames_unknown"] > 0 and c["frames_ignored"] > 0


def test_oracle_agrees_with_the_codec_on_own_frames() -> None:
    m = CODEC.encode(
        "PwmDuty", {"duty_a": 0.25, "duty_b": 0.5, "duty_c": 0.75, "enable": 1, "step": 3}
    )
    assert e2e_ok(CODEC, m)
    assert raw_duty(bytes(m.data)) == (0.25, 0.5, 0.75, True)
    bad = bytearray(m.data)
    bad[3] ^= 0x10
    assert not e2e_ok(CODEC, can.Message(arbitration_id=m.arbitration_id, data=bad))


def test_step_guard_catches_a_duty_from_a_rejected_frame() -> None:
    class P:
        def step(self, a: float, b: float, c: float, en: bool = True) -> None:
            pass

    p = P()
    g = StepGuard(p, {(0.5, 0.5, 0.5)})
    p.step(0.5, 0.5, 0.5, True)
    p.step(0.9, 0.1, 0.1, False)  # switches open: any duty in range is harmless
    assert g.violations == []
    p.step(0.9, 0.1, 0.1, True)
    p.step(1.5, 0.1, 0.1, False)
    assert len(g.violations) == 2


def test_fuzz_plant_node_real_time() -> None:
    res = fuzz_node(make_plant_node(scn(1), CODEC), FRAMES, seed=1, realtime=True)
    check(res)
    assert res.steps > FRAMES // 5 and res.enabled_steps > 0
    assert res.counters["reject_reasons"].get("stale_counter", 0) > 0
    assert res.counters["reject_reasons"].get("repeated_counter", 0) > 0


def test_fuzz_plant_node_lockstep() -> None:
    res = fuzz_node(make_plant_node(scn(2), CODEC, watchdog_rounds=5), FRAMES, seed=2)
    check(res)
    assert res.steps > 100 and res.enabled_steps > 0
    assert res.counters["reject_reasons"].get("future_counter", 0) > 0


def test_fuzz_controller_node() -> None:
    node = make_controller_node(scn(3), "sfhf", CODEC)
    res = fuzz_node(node, FRAMES, seed=3, realtime=True)
    check(res)
    assert node.next_k > 100  # the controller ran on the samples it accepted


frame_st = st.one_of(
    # anything at all under the bench's own identifiers and a few others
    st.builds(
        lambda fid, data: can.Message(arbitration_id=fid, data=data, is_fd=len(data) > 8),
        st.sampled_from([16, 17, 32, 240, 256, 257, 0, 0x7FF, 15, 33]),
        st.binary(min_size=0, max_size=16),
    ),
    # valid frames with one byte corrupted, or valid (step near the plant's present period)
    st.builds(
        lambda name, step, duty, flip, pos: _mutated(name, step, duty, flip, pos),
        st.sampled_from(["PwmDuty", "BenchCommand", "PhaseSamples"]),
        st.integers(0, 70),
        st.floats(0.0, 1.0),
        st.integers(0, 255),
        st.integers(0, 7),
    ),
)


def _mutated(name: str, step: int, duty: float, flip: int, pos: int) -> can.Message:
    sig = {s: 0.0 for s in CODEC.signal_names(name)}
    sig.update(step=step, duty_a=duty, duty_b=duty, duty_c=duty, enable=1, cmd=4)
    m = CODEC.encode(name, sig)
    data = bytearray(m.data)
    data[pos] ^= flip
    return can.Message(arbitration_id=m.arbitration_id, data=bytes(data))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(frames=st.lists(frame_st, min_size=1, max_size=80), realtime=st.booleans())
def test_hypothesis_frames_never_escape_the_plant_node(
    frames: list[can.Message], realtime: bool
) -> None:
    node = make_plant_node(scn(), CODEC, watchdog_rounds=2)
    node.realtime = realtime
    node.started = True
    allowed = {(0.5, 0.5, 0.5)}
    guard = StepGuard(node.plant, allowed)
    cn = make_controller_node(scn(), "sensored", CODEC)
    for m in frames:
        if m.arbitration_id == 16 and e2e_ok(CODEC, m):
            allowed.add(raw_duty(bytes(m.data))[:3])
        node.on_message(m)
        for out in cn.on_message(m):
            d = CODEC.decode(out)
            assert d is not None and d.ok
        if realtime:
            node.advance_realtime()
        elif node.ready():
            node.advance_lockstep()
        else:
            node.on_duty_timeout()
    assert guard.violations == []
    assert node.counters.frames_seen == len(frames)
    assert cn.counters.frames_seen == len(frames)


def test_fuzz_through_a_real_udp_bus() -> None:
    spec = BusSpec("udp_multicast", "239.74.163.2", free_port())
    tx, rx = spec.open(), spec.open()
    node = make_plant_node(scn(4), CODEC)
    node.started = True
    node.realtime = True
    fz = FrameFuzzer(CODEC, 4, names=("PwmDuty", "BenchCommand"), weights={"unknown_id": 0.0})
    sent = []
    try:
        for _ in range(300):
            m, _ = fz.one()
            if len(m.data) > 64 or (len(m.data) > 8 and len(m.data) not in (12, 16, 20, 24)):
                continue
            try:
                tx.send(m)
            except (can.CanError, ValueError):
                continue
            sent.append(m)
        got = 0
        while got < len(sent):
            r = rx.recv(2.0)
            if r is None:
                break
            got += 1
            node.on_message(r)
            if got % 4 == 0:
                node.advance_realtime()
    finally:
        tx.shutdown()
        rx.shutdown()
    assert got == len(sent) > 250
    c = node.counters
    assert c.frames_seen == got
    n_bad = sum(1 for m in sent if not e2e_ok(CODEC, m))
    assert (
        c.frames_rejected
        - c.reject_reasons.get("stale_counter", 0)
        - c.reject_reasons.get("future_counter", 0)
        - c.reject_reasons.get("out_of_range", 0)
        == n_bad
    )
