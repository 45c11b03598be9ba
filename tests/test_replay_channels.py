"""``bench replay --channel-map``: each capture channel onto a bus of its own.

A small two- or three-channel capture is written with python-can's own
writer, replayed through ``bench.cli.main`` onto python-can ``virtual``
buses (in-process; channels are names) or udp_multicast buses on ports of
the test's own, and each receiving bus must get exactly the frames of the
channels mapped to it, in capture order, with their IDs and data.
"""

from __future__ import annotations

import gc
import logging
import os
from collections.abc import Iterator
from pathlib import Path

import can
import pytest
from can.interfaces import virtual

from bench._errors import BenchError, InterfaceError
from bench.captures._read import (
    read_capture,
)
from bench.captures._replay import (
    parse_channel_map,
    plan_replay,
    replay_frames,
    resolve_channel_map,
)
from bench.cli import main
from bench.wire._bus import BusSpec, udp_multicast_group
from tests.ports import free_port

#: Capture channel of each frame: interleaved, so that a replay that sends a
#: channel's frames in a block, or on the wrong bus, changes what a bus sees.
CHANNELS = [1, 2, 1, 1, 3, 2, 2, 1, 3, 2, 1, 2, 2, 3, 1, 1, 2, 3, 1, 2]


def _frames() -> list[can.Message]:
    return [
        can.Message(
            timestamp=50.0 + 0.001 * i,
            arbitration_id=0x100 + 7 * i + ch,
            is_extended_id=False,
            data=bytes([i, ch, 0xA5 ^ i]),
            channel=ch,
        )
        for i, ch in enumerate(CHANNELS)
    ]


def _write(path: Path, frames: list[can.Message]) -> Path:
    with can.Logger(str(path)) as w:
        for m in frames:
            w.on_message_received(m)
    return path


def _expect(channels: set[int]) -> list[tuple[int, bytes]]:
    return [(m.arbitration_id, bytes(m.data)) for m in _frames() if m.channel in channels]


def drain(bus: can.BusABC, timeout: float = 0.05) -> list[tuple[int, bytes]]:
    out = []
    while (m := bus.recv(timeout)) is not None:
        out.append((m.arbitration_id, bytes(m.data)))
    return out


def _name(tag: str) -> str:
    return f"{tag}{os.getpid()}"


@pytest.fixture
def receivers(request: pytest.FixtureRequest) -> Iterator[dict[str, can.BusABC]]:
    """Virtual buses ``a``, ``b`` and ``d`` (the default bus), named per test."""
    test = request.node.name.replace("[", "_").replace("]", "").replace(".", "")
    buses = {k: can.Bus(interface="virtual", channel=_name(f"{test}-{k}")) for k in "abd"}
    yield buses
    for b in buses.values():
        b.shutdown()


def _chan(bus: can.BusABC) -> str:
    """The channel name of a virtual bus."""
    assert isinstance(bus, virtual.VirtualBus)
    return str(bus.channel_id)


def _open_count(bus: can.BusABC) -> int:
    """How many bus objects are open on ``bus``'s virtual channel."""
    with virtual.channels_lock:
        return len(virtual.channels.get(_chan(bus), []))


@pytest.mark.parametrize(
    ("suffix", "ch1", "ch2"),
    [(".blf", "1", "2"), (".asc", "1", "can2"), (".log", "can1", "2")],
)
def test_each_channel_goes_to_its_bus(
    tmp_path: Path,
    receivers: dict[str, can.BusABC],
    capsys: pytest.CaptureFixture[str],
    suffix: str,
    ch1: str,
    ch2: str,
) -> None:
    """Channels 1 and 2 to buses a and b, channel 3 (not mapped) to the default bus d.

    ``.log`` reads channels back as ``can1``..``can3``, ``.blf``/``.asc`` as
    1..3: ``1`` and ``can1`` name the same channel in either.
    """
    path = _write(tmp_path / f"two{suffix}", _frames())
    name = {k: _chan(b) for k, b in receivers.items()}
    rc = main(
        [
            "replay",
            str(path),
            "--speed",
            "5",
            "--channel-map",
            f"{ch1}=virtual:{name['a']}",
            "--channel-map",
            f"{ch2}=virtual:{name['b']}",
            "--interface",
            "virtual",
            "--channel",
            name["d"],
        ]
    )
    out, err = capsys.readouterr()
    assert rc == 0, err
    got = {k: drain(b) for k, b in receivers.items()}
    assert got["a"] == _expect({1})
    assert got["b"] == _expect({2})
    assert got["d"] == _expect({3})
    n = {c: CHANNELS.count(c) for c in (1, 2, 3)}
    assert (
        f"frames per bus: virtual:{name['a']} {n[1]}, virtual:{name['b']} {n[2]}, "
        f"virtual:{name['d']} {n[3]}"
    ) in out
    assert f"virtual:{name['d']} (unmapped channels)" in err
    # every bus the replay opened is shut down: only the receivers remain
    assert all(_open_count(b) == 1 for b in receivers.values())


def test_same_bus_named_twice_is_opened_once(
    tmp_path: Path,
    receivers: dict[str, can.BusABC],
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Channels 1 and 3 both to bus a, which is also the default bus (channel 2 unmapped)."""
    opened: list[BusSpec] = []
    real_open = BusSpec.open

    def counting_open(self: BusSpec) -> can.BusABC:
        opened.append(self)
        return real_open(self)

    monkeypatch.setattr(BusSpec, "open", counting_open)
    path = _write(tmp_path / "two.blf", _frames())
    a = _chan(receivers["a"])
    rc = main(
        [
            "replay",
            str(path),
            "--speed",
            "5",
            "--channel-map",
            f"1=virtual:{a}",
            "--channel-map",
            f"3=virtual:{a}",
            "-i",
            "virtual",
            "-c",
            a,
        ]
    )
    out, err = capsys.readouterr()
    assert rc == 0, err
    assert [(s.interface, s.channel) for s in opened] == [("virtual", a)]
    # one bus, so every frame once and in capture order
    assert drain(receivers["a"]) == _expect({1, 2, 3})
    assert f"frames per bus: virtual:{a} {len(CHANNELS)}" in out
    assert _open_count(receivers["a"]) == 1


def test_unmapped_channel_goes_to_default_bus_only_when_left(
    tmp_path: Path, receivers: dict[str, can.BusABC], capsys: pytest.CaptureFixture[str]
) -> None:
    """With --channel-filter 1,2 nothing is left for the default bus: it is not opened."""
    path = _write(tmp_path / "two.asc", _frames())
    a, b, d = (_chan(receivers[k]) for k in "abd")
    argv = ["replay", str(path), "--speed", "5", "--channel-filter", "1,2"]
    argv += ["--channel-map", f"1=virtual:{a}", "--channel-map", f"2=virtual:{b}"]
    assert main([*argv, "-i", "virtual", "-c", d]) == 0
    out = capsys.readouterr().out
    assert drain(receivers["a"]) == _expect({1})
    assert drain(receivers["b"]) == _expect({2})
    assert drain(receivers["d"]) == []
    assert f"virtual:{d}" not in out
    # the planner never asks for the default bus when every frame has one
    frames, _ = read_capture(path)

    def no_default() -> BusSpec:
        raise AssertionError("default bus asked for")

    maps = parse_channel_map([f"1=virtual:{a}", f"2=virtual:{b}", f"3=virtual:{a}"])
    plan = plan_replay(frames, default=no_default, channel_map=maps)
    assert [s.channel for s in plan.buses] == [a, b]
    assert plan.route == [{1: 0, 2: 1, 3: 0}[c] for c in CHANNELS]


@pytest.mark.parametrize("clock", ["deadline", "messagesync"])
def test_replay_frames_routes_on_one_time_line(clock: str) -> None:
    """Library level: two buses, two loops; frame i goes to bus route[i] in both loops."""
    frames = _frames()
    route = [0 if c == 2 else 1 for c in CHANNELS]
    names = [_name(f"route-{clock}-{k}") for k in "xy"]
    tx = [can.Bus(interface="virtual", channel=n) for n in names]
    rx = [can.Bus(interface="virtual", channel=n) for n in names]
    try:
        res = replay_frames(
            tx, frames, route=route, loops=2, speed=5.0, clock=clock, bus_names=names
        )
        got = [drain(b) for b in rx]
    finally:
        for bus in tx + rx:
            bus.shutdown()
    one = [(m.arbitration_id, bytes(m.data)) for m in frames]
    want = [[f for f, r in zip(one, route, strict=True) if r == k] * 2 for k in (0, 1)]
    assert got == want
    assert res.sent == 2 * len(frames) and res.loops == 2
    assert res.sent_per_bus == [2 * route.count(0), 2 * route.count(1)]
    with pytest.raises(ValueError):
        replay_frames(tx, frames, route=route[:-1])


def test_udp_multicast_buses_by_port(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Channel 1 and 2 onto two udp_multicast buses told apart by port; 3 to a third."""
    path = _write(tmp_path / "two.blf", _frames())
    group = "239.74.163.5"
    p1, p2, p3 = free_port(1), free_port(1), free_port(1)
    rx = [BusSpec("udp_multicast", group, p).open() for p in (p1, p2, p3)]
    try:
        argv = ["replay", str(path), "--speed", "5"]
        argv += ["--channel-map", f"1=udp_multicast:{group}:{p1}"]
        argv += ["--channel-map", f"can2=udp_multicast:{group}:{p2}"]
        rc = main([*argv, "-i", "udp_multicast", "-c", group, "--port", str(p3)])
        out, err = capsys.readouterr()
        got = [drain(b, 0.3) for b in rx]
    finally:
        for b in rx:
            b.shutdown()
    assert rc == 0, err
    assert got == [_expect({1}), _expect({2}), _expect({3})]
    assert f"udp_multicast:{group} port {p1} {CHANNELS.count(1)}" in out


def test_channel_map_forms() -> None:
    udp = parse_channel_map(
        [
            "1=udp_multicast:[ff15::1234]:43001",
            "2=udp_multicast:ff15::1234",
            "can3=udp_multicast::43002",
            "4=udp_multicast:239.1.2.3:43003",
            "5=virtual",
            "6 = virtual:x:y",
        ],
        bitrate=500_000,
    )
    got = [(m.channel, m.bus.interface, m.bus.channel, m.bus.port) for m in udp]
    assert got[0] == ("1", "udp_multicast", "ff15::1234", 43001)
    assert got[1] == ("2", "udp_multicast", "ff15::1234", None)
    assert got[2] == ("can3", "udp_multicast", udp_multicast_group(), 43002)
    assert got[3] == ("4", "udp_multicast", "239.1.2.3", 43003)
    assert got[4] == ("5", "virtual", "bench", None)
    assert got[5] == ("6", "virtual", "x:y", None)
    assert all(m.bus.bitrate == 500_000 for m in udp)


def test_channel_names_resolve_exactly_then_by_tag() -> None:
    frames = [
        can.Message(timestamp=0.001 * i, arbitration_id=i, channel=c)
        for i, c in enumerate(["can1", "vcan1", "can2", None])
    ]
    maps = parse_channel_map(["vcan1=virtual:a", "2=virtual:b"])
    assert resolve_channel_map(maps, frames) == {"vcan1": 0, "can2": 1}
    with pytest.raises(BenchError, match=r"--channel-map 1=virtual:a: channel 1 matches several"):
        resolve_channel_map(parse_channel_map(["1=virtual:a"]), frames)
    with pytest.raises(BenchError, match=r"channel 9 is not in the capture \(its channels: can1"):
        resolve_channel_map(parse_channel_map(["9=virtual:a"]), frames)


BAD = [
    (["1virtual:a"], "1virtual:a", "expected CH=INTERFACE:CHANNEL"),
    (["=virtual:a"], "=virtual:a", "expected CH=INTERFACE:CHANNEL"),
    (["1=nosuchbus:a"], "1=nosuchbus:a", "unknown"),
    (["1=virtual:a", "7=virtual:b"], "7=virtual:b", "channel 7 is not in the capture"),
    (["1=virtual:a", "can1=virtual:b"], "can1=virtual:b", "already mapped by"),
    (["1=udp_multicast:10.0.0.1:43000"], "10.0.0.1", "not a multicast group"),
    (["1=udp_multicast:239.1.1.1:99999"], "99999", "not a UDP port"),
    (["1=udp_multicast:[ff15::1]x"], "[ff15::1]x", "IPv6 group"),
    (["1=vector"], "1=vector", "needs a channel"),
    # a driver library the adapter needs and this host lacks comes first, named
    (["1=kvaser:0"], "1=kvaser", "its driver needs Kvaser's CANlib"),
]


@pytest.mark.parametrize(("maps", "value", "why"), BAD)
def test_bad_mapping_is_one_line_before_anything_is_sent(
    tmp_path: Path,
    receivers: dict[str, can.BusABC],
    capsys: pytest.CaptureFixture[str],
    maps: list[str],
    value: str,
    why: str,
) -> None:
    path = _write(tmp_path / "two.blf", _frames())
    a, b = (_chan(receivers[k]) for k in "ab")
    argv = ["replay", str(path), "-i", "virtual", "-c", a]
    for item in maps:
        item = item.replace("virtual:a", f"virtual:{a}").replace("virtual:b", f"virtual:{b}")
        argv += ["--channel-map", item]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("bench: error: --channel-map") and value in err[0] and why in err[0]
    assert drain(receivers["a"]) == [] and drain(receivers["b"]) == []


def test_bus_that_fails_to_open_closes_the_others(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
) -> None:
    """The second bus fails: the first, already open, is shut down; one line, exit 2."""
    real_open = BusSpec.open
    first = _name("opened-first")

    def failing_open(self: BusSpec) -> can.BusABC:
        if self.channel == "broken":
            raise InterfaceError("interface virtual channel broken: no such adapter")
        return real_open(self)

    monkeypatch.setattr(BusSpec, "open", failing_open)
    path = _write(tmp_path / "two.blf", _frames())
    argv = ["replay", str(path), "-i", "virtual", "-c", first]
    argv += ["--channel-map", f"2=virtual:{first}", "--channel-map", "1=virtual:broken"]
    with caplog.at_level(logging.WARNING, logger="can"):
        assert main(argv) == 2
        gc.collect()
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["bench: error: interface virtual channel broken: no such adapter"]
    with virtual.channels_lock:
        assert first not in virtual.channels
    assert "not properly shut down" not in caplog.text
