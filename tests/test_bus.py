"""The bus factory: virtual, udp_multicast across processes, socketcan on vcan0, errors."""

from __future__ import annotations

import random
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import can
import pytest

import bench.wire._bus as busmod
from bench._errors import BenchError, InterfaceError
from bench.wire._bus import (
    UDP_GROUP_IPV4,
    default_channel,
    default_transport,
    open_bus,
    udp_multicast_group,
)
from bench.wire._codec import Codec

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def codec() -> Codec:
    return Codec()


@pytest.fixture
def no_python_can_config(monkeypatch, tmp_path):
    """Hide the user's python-can configuration (files and environment)."""
    monkeypatch.setenv("HOME", str(tmp_path))
    for var in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setattr(can, "rc", {})
    monkeypatch.setattr(busmod, "_SYS_NET", tmp_path / "net")


def _recv_until(bus: can.BusABC, codec: Codec, name: str, timeout: float):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        msg = bus.recv(0.1)
        if msg is None:
            continue
        decoded = codec.decode(msg)
        if decoded is not None and decoded.name == name:
            return msg, decoded
    return None, None


def test_virtual_send_receive(codec):
    channel = f"test-{random.getrandbits(32)}"
    a = open_bus("virtual", channel)
    b = open_bus("virtual", channel)
    try:
        sent = codec.encode(
            "PwmDuty", {"duty_a": 0.1, "duty_b": 0.2, "duty_c": 0.3, "enable": 1, "step": 9}
        )
        a.send(sent)
        msg, decoded = _recv_until(b, codec, "PwmDuty", 2.0)
        assert decoded is not None and decoded.ok
        assert decoded.signals["step"] == 9 and bytes(msg.data) == bytes(sent.data)
        assert a.recv(0.05) is None  # own frames are not echoed by default
    finally:
        a.shutdown()
        b.shutdown()


def test_virtual_receive_own_messages(codec):
    bus = open_bus("virtual", f"own-{random.getrandbits(32)}", receive_own_messages=True)
    try:
        bus.send(
            codec.encode(
                "BenchCommand", {"cmd": 1, "seq": 2, "step": 0, "speed_ref": 100, "load_torque": 0}
            )
        )
        _, decoded = _recv_until(bus, codec, "BenchCommand", 2.0)
        assert decoded is not None and decoded.signals["cmd"] == 1
    finally:
        bus.shutdown()


_CHILD = textwrap.dedent(
    """
    import sys, time
    from bench.wire._bus import open_bus
    from bench.wire._codec import Codec

    group, port = sys.argv[1], int(sys.argv[2])
    codec = Codec()
    bus = open_bus("udp_multicast", group, port=port)
    got = None
    try:
        deadline = time.monotonic() + 10.0
        while got is None and time.monotonic() < deadline:
            bus.send(codec.encode("PhaseSamples",
                     {"i_a": 1.5, "i_b": -0.25, "u_dc": 540.0, "status": 1, "step": 1234}))
            bus.send(codec.encode("PlantTruth",
                     {"theta_e": 1.0, "w_m": 10.0, "tau_e": 2.0, "tau_L": -1.0, "step": 1234, "duty_age": 0}))
            until = time.monotonic() + 0.2
            while time.monotonic() < until:
                msg = bus.recv(0.05)
                d = codec.decode(msg) if msg is not None else None
                if d is not None and d.name == "PwmDuty" and d.ok:
                    got = d
                    break
    finally:
        bus.shutdown()
    print(got.signals["step"] if got else "none", got.signals["duty_b"] if got else "")
    sys.exit(0 if got else 1)
    """
)


@pytest.mark.parametrize("group", sorted({udp_multicast_group(), UDP_GROUP_IPV4}))
def test_udp_multicast_two_processes(codec, group):
    port = random.randint(20000, 60000)  # keep away from other runs on the same host
    bus = open_bus("udp_multicast", group, port=port)
    child = subprocess.Popen(
        [sys.executable, "-c", _CHILD, group, str(port)],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        _, samples = _recv_until(bus, codec, "PhaseSamples", 15.0)
        assert samples is not None, "no PhaseSamples from the child process"
        assert samples.ok and samples.signals["step"] == 1234 % 1024
        assert samples.signals["i_a"] == 1.5 and samples.signals["i_c"] == -1.25
        _, truth = _recv_until(bus, codec, "PlantTruth", 5.0)
        assert truth is not None and truth.ok and truth.signals["step"] == 1234  # FD frame
        bus.send(
            codec.encode(
                "PwmDuty",
                {"duty_a": 0.5, "duty_b": 0.25, "duty_c": 0.75, "enable": 1, "step": 1234},
            )
        )
        out, err = child.communicate(timeout=20)
    finally:
        if child.poll() is None:
            child.kill()
            child.communicate()
        bus.shutdown()
    assert child.returncode == 0, err
    step, duty_b = out.split()
    assert int(step) == 1234 % 1024 and float(duty_b) == 0.25


def test_default_transport_without_vcan(no_python_can_config, tmp_path):
    interface, channel, reason = default_transport(tmp_path / "net")
    assert interface == "udp_multicast" and channel == udp_multicast_group()
    assert "no vcan0" in reason and "\n" not in reason


def test_default_transport_with_vcan(monkeypatch, tmp_path):
    net = tmp_path / "net"
    (net / "vcan0").mkdir(parents=True)
    (net / "vcan0" / "flags").write_text("0xc1\n")
    monkeypatch.setattr(busmod, "_af_can_works", lambda: True)
    assert default_transport(net)[:2] == ("socketcan", "vcan0")
    (net / "vcan0" / "flags").write_text("0x80\n")
    interface, _, reason = default_transport(net)
    assert interface == "udp_multicast" and "down" in reason
    monkeypatch.setattr(busmod, "_af_can_works", lambda: False)
    (net / "vcan0" / "flags").write_text("0xc1\n")
    interface, _, reason = default_transport(net)
    assert interface == "udp_multicast" and "AF_CAN" in reason


def test_default_channels():
    assert default_channel("socketcan") == "vcan0"
    assert default_channel("udp_multicast") == udp_multicast_group()
    assert default_channel("virtual") == "bench"
    assert default_channel("pcan") is None


def test_python_can_environment_honoured(no_python_can_config, monkeypatch):
    monkeypatch.setenv("CAN_INTERFACE", "virtual")
    monkeypatch.setenv("CAN_CHANNEL", "from-env")
    bus = open_bus(None, None)
    try:
        assert type(bus).__name__ == "VirtualBus" and "from-env" in bus.channel_info
    finally:
        bus.shutdown()


def test_python_can_config_file_honoured(no_python_can_config, tmp_path):
    (tmp_path / ".canrc").write_text("[default]\ninterface = virtual\nchannel = from-file\n")
    bus = open_bus(None, None)
    try:
        assert type(bus).__name__ == "VirtualBus" and "from-file" in bus.channel_info
    finally:
        bus.shutdown()


def test_no_config_uses_default_transport(no_python_can_config, monkeypatch):
    monkeypatch.setattr(busmod, "default_transport", lambda: ("virtual", "dflt", "why"))
    bus = open_bus(None, None)
    try:
        assert type(bus).__name__ == "VirtualBus" and "dflt" in bus.channel_info
    finally:
        bus.shutdown()


@pytest.mark.parametrize(
    ("interface", "channel", "kwargs", "match"),
    [
        ("nosuchbus", None, {}, r"interface 'nosuchbus': unknown"),
        # the driver's library is checked first (absent here), then the channel
        ("pcan", None, {}, r"interface pcan: (needs a channel|its driver needs PEAK's PCAN-Basic)"),
        # without AF_CAN in the kernel the bench says so before naming the channel
        (
            "socketcan",
            "nosuchcan9",
            {},
            r"interface socketcan(: this kernel has no SocketCAN| channel nosuchcan9: )",
        ),
        ("udp_multicast", None, {"receive_own_messages": True}, r"receive_own_messages"),
        ("udp_multicast", "not-an-address", {}, r"interface udp_multicast channel not-an-addr"),
    ],
)
def test_errors_are_one_line(interface, channel, kwargs, match):
    with pytest.raises(InterfaceError, match=match) as info:
        open_bus(interface, channel, **kwargs)
    assert "\n" not in str(info.value)
    assert isinstance(info.value, BenchError)


@pytest.mark.socketcan
@pytest.mark.usefixtures("vcan0")
@pytest.mark.parametrize("name", ["PwmDuty", "PlantTruth"])  # classic and FD
def test_socketcan_vcan0_send_receive(codec, name):
    a = open_bus("socketcan", "vcan0")
    b = open_bus("socketcan", "vcan0")
    try:
        signals = {
            "PwmDuty": {"duty_a": 0.1, "duty_b": 0.2, "duty_c": 0.3, "enable": 1, "step": 5},
            "PlantTruth": {
                "theta_e": 3.0,
                "w_m": -5.0,
                "tau_e": 1.0,
                "tau_L": 0.5,
                "step": 99,
                "duty_age": 0,
            },
        }[name]
        sent = codec.encode(name, signals)
        a.send(sent)
        msg, decoded = _recv_until(b, codec, name, 5.0)
        assert decoded is not None and decoded.ok
        assert msg.is_fd == sent.is_fd and bytes(msg.data) == bytes(sent.data)
        assert decoded.signals["step"] == signals["step"]
    finally:
        a.shutdown()
        b.shutdown()


@pytest.mark.socketcan
@pytest.mark.usefixtures("vcan0")
def test_socketcan_default_transport_is_vcan0():
    assert default_transport()[:2] == ("socketcan", "vcan0")


@pytest.mark.parametrize(
    ("interface", "needs"),
    [
        ("kvaser", "Kvaser's CANlib libcanlib.so"),
        ("pcan", "PEAK's PCAN-Basic library libpcanbasic.so"),
        ("slcan", "pip install 'can-hil-bench[slcan]'"),
    ],
)
def test_a_missing_driver_library_is_one_line_naming_what_to_install(
    interface: str, needs: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    import ctypes
    import ctypes.util
    import importlib.util

    from bench.cli import main

    def no_lib(name: str) -> None:
        raise OSError(f"{name}: cannot open shared object file")

    monkeypatch.setattr(ctypes.cdll, "LoadLibrary", no_lib)
    monkeypatch.setattr(ctypes.util, "find_library", lambda name: None)
    real_find_spec = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util,
        "find_spec",
        lambda name, *a: None if name == "serial" else real_find_spec(name, *a),
    )
    with pytest.raises(InterfaceError) as info:
        open_bus(interface, "0")
    assert "\n" not in str(info.value) and needs in str(info.value)
    # the command line: exit 2, before any process starts
    assert main(["plant", "xue-fig13", "-i", interface, "-c", "0"]) == 2


def test_slcan_gets_the_data_rate_as_a_bit_timing(monkeypatch: pytest.MonkeyPatch) -> None:
    """python-can's slcan ignores ``data_bitrate``; the bench passes a BitTimingFd, which
    its ``set_bitrate(nom, data)`` reads (the CANable's data-rate command)."""
    import can

    import bench.wire._bus as busmod

    seen: dict[str, object] = {}

    def fake_bus(**kw: object) -> None:
        seen.update(kw)
        raise can.CanInitializationError("no device")

    monkeypatch.setattr(busmod, "missing_driver", lambda name: None)
    monkeypatch.setattr(can, "Bus", fake_bus)
    with pytest.raises(InterfaceError):
        open_bus("slcan", "/dev/ttyACM0@115200", bitrate=1_000_000, data_bitrate=5_000_000)
    timing = seen["timing"]
    assert isinstance(timing, can.BitTimingFd)
    assert (timing.nom_bitrate, timing.data_bitrate) == (1_000_000, 5_000_000)
    assert "data_bitrate" not in seen and "bitrate" not in seen
