"""One resolution of a bus (bench/wire/_bus.py, ``resolve_bus``) for every command.

``bench run``/``plant``/``controller``/``link`` (:func:`bench.cli._common.bus_spec`),
``bench monitor`` (:func:`bench.cli.monitor.monitor_bus`) and :func:`open_bus` with
no interface all resolve through it: the options first, then python-can's
configuration, then the default transport; a run's own udp_multicast port only
where the bench makes the bus; python-can's default port under one name.
"""

from __future__ import annotations

import argparse
import inspect
from pathlib import Path

import can
import pytest
from can.interfaces.udp_multicast import UdpMulticastBus

from bench._errors import InterfaceError
from bench.cli._common import bus_spec, same_bus
from bench.cli.monitor import monitor_bus
from bench.wire import _bus as busmod
from bench.wire._bus import FROM_CONFIG, UDP_DEFAULT_PORT, BusSpec, resolve_bus


@pytest.fixture
def no_config(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Path:
    """No python-can configuration (files, environment), no vcan0: udp_multicast by default."""
    monkeypatch.setenv("HOME", str(tmp_path))
    for var in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setattr(can, "rc", {})
    monkeypatch.setattr(busmod, "_SYS_NET", tmp_path / "net")
    return tmp_path


def _args(**kw: object) -> argparse.Namespace:
    base: dict[str, object] = dict(
        interface=None, channel=None, port=None, bitrate=None, data_bitrate=None
    )
    return argparse.Namespace(**{**base, **kw})


def test_the_default_port_is_python_cans_own() -> None:
    sig = inspect.signature(UdpMulticastBus.__init__)
    assert UDP_DEFAULT_PORT == sig.parameters["port"].default == 43113


def test_a_run_makes_its_own_port_and_the_monitor_joins_the_default(no_config: Path) -> None:
    spec, why = resolve_bus(None, None, own_port=44002)
    assert (spec.interface, spec.port) == ("udp_multicast", 44002) and why and "vcan0" in why
    run = bus_spec(_args(), announce=False)
    assert run.interface == "udp_multicast" and run.port is not None and run.port % 2 == 0
    assert run.port != UDP_DEFAULT_PORT
    mon = monitor_bus(_args())
    assert (mon.interface, mon.channel, mon.port) == ("udp_multicast", run.channel, None)
    # one bus: the monitor without --port and a run on python-can's default port
    assert same_bus(mon, BusSpec("udp_multicast", "x", UDP_DEFAULT_PORT))


def test_python_can_configuration_fills_what_the_options_leave_open(no_config: Path) -> None:
    (no_config / ".canrc").write_text(
        "[default]\ninterface = udp_multicast\nchannel = 239.1.2.3\nport = 45000\nbitrate = 500000\n"
    )
    spec, why = resolve_bus(None, None, own_port=44002)
    assert why == FROM_CONFIG
    assert (spec.channel, spec.port, spec.bitrate) == ("239.1.2.3", 45000, 500000)
    spec, _ = resolve_bus(None, None, 46000, 250000)
    assert (spec.port, spec.bitrate) == (46000, 250000)
    args = _args()
    assert (
        bus_spec(args, announce=False)
        == monitor_bus(_args())
        == BusSpec("udp_multicast", "239.1.2.3", 45000, 500000)
    )
    assert args.interface == "udp_multicast" and args.port == 45000  # written back


def test_the_mistakes_are_one_line(no_config: Path) -> None:
    with pytest.raises(InterfaceError, match="--channel given without --interface"):
        resolve_bus(None, "vcan7")
    with pytest.raises(InterfaceError, match="gs_usb: this adapter needs --channel"):
        resolve_bus("gs_usb", None)
    with pytest.raises(InterfaceError, match="virtual bus lives inside one process"):
        bus_spec(_args(interface="virtual"), announce=False)
    with pytest.raises(InterfaceError, match="the monitor is a process of its own"):
        monitor_bus(_args(interface="virtual"))
    # a bus inside one process (replay) takes it
    assert bus_spec(_args(interface="virtual"), announce=False, one_process=True).channel == (
        "bench"
    )
