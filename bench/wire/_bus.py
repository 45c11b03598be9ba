"""One factory for every CAN bus the bench talks to.

The bench depends on :class:`can.BusABC` only; which bus it gets is
configuration, never code:

- ``socketcan``: a Linux SocketCAN device, ``vcan0`` in tests or a real
  ``can0`` (its bit rates are set with ``ip link``, not here);
- ``udp_multicast``: python-can's CAN-over-UDP-multicast bus, the default
  between processes on a host without vcan (no bit rate: a simulated bench can
  run faster than any real bus, see :mod:`bench.wire._busload`);
- ``virtual``: python-can's in-process bus, for tests;
- any other python-can interface by name (``pcan``, ``kvaser``, ``vector``,
  ``slcan``, ``gs_usb``, ...), with its channel and bit rates.

With ``interface=None``, python-can's own configuration (``~/.canrc``,
``/etc/can.conf``, ``CAN_INTERFACE``/``CAN_CHANNEL``/``CAN_BITRATE``) is used
when it names an interface, else :func:`default_transport` decides.
"""

from __future__ import annotations

import functools
import gc
import inspect
import logging
import socket
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import can
from can.interfaces.udp_multicast import UdpMulticastBus

from bench._errors import InterfaceError

__all__ = [
    "UDP_GROUP_IPV4",
    "UDP_GROUP_IPV6",
    "default_channel",
    "default_transport",
    "open_bus",
    "resolve_bus",
    "udp_multicast_group",
]

UDP_GROUP_IPV6: str = UdpMulticastBus.DEFAULT_GROUP_IPv6
"""python-can's default IPv6 multicast group (link scope of one hop)."""
UDP_GROUP_IPV4: str = UdpMulticastBus.DEFAULT_GROUP_IPv4
"""python-can's fallback IPv4 multicast group."""
UDP_DEFAULT_PORT: int = int(inspect.signature(UdpMulticastBus.__init__).parameters["port"].default)
"""python-can's default udp_multicast port, 43113 (the default of its ``port``, read from
python-can itself; ``bench run --controller external`` and ``bench monitor`` use it)."""

VIRTUAL_CHANNEL = "bench"
"""Default channel of the in-process ``virtual`` bus."""

_SYS_NET = Path("/sys/class/net")
_IFF_UP = 0x1


def _af_can_works() -> bool:
    """True when the kernel opens a raw CAN socket (``AF_CAN``)."""
    af_can = getattr(socket, "AF_CAN", None)
    if af_can is None:
        return False
    try:
        sock = socket.socket(af_can, socket.SOCK_RAW, socket.CAN_RAW)
    except OSError:
        return False
    sock.close()
    return True


def _link_up(name: str, sys_net: Path = _SYS_NET) -> bool | None:
    """None when the network device does not exist, else whether it is up."""
    flags = sys_net / name / "flags"
    if not (sys_net / name).exists():
        return None
    try:
        return bool(int(flags.read_text().strip(), 0) & _IFF_UP)
    except (OSError, ValueError):
        return True  # present but unreadable: let the open report any problem


@functools.cache
def udp_multicast_group() -> str:
    """The multicast group that this host can join: IPv6 when possible, else IPv4."""
    try:
        info = socket.getaddrinfo(UDP_GROUP_IPV6, None, socket.AF_INET6, socket.SOCK_DGRAM)
        group_bin = socket.inet_pton(socket.AF_INET6, str(info[0][4][0]))
        with socket.socket(socket.AF_INET6, socket.SOCK_DGRAM) as sock:
            sock.setsockopt(
                socket.IPPROTO_IPV6, socket.IPV6_JOIN_GROUP, group_bin + (0).to_bytes(4, "little")
            )
        return UDP_GROUP_IPV6
    except OSError:
        return UDP_GROUP_IPV4


def default_transport(sys_net: Path = _SYS_NET) -> tuple[str, str, str]:
    """Transport to use when the user names none.

    ``socketcan`` on ``vcan0`` when that device exists, is up and the kernel
    has ``AF_CAN``; ``udp_multicast`` otherwise.

    Returns
    -------
    interface, channel, reason : str
        The python-can interface and channel, and a short phrase saying why
        (no newline), for the command line to print next to them.
    """
    up = _link_up("vcan0", sys_net)
    if up is None:
        why = "no vcan0"
    elif not _af_can_works():
        why = "vcan0 exists but this kernel has no AF_CAN sockets"
    elif not up:
        why = "vcan0 is down (ip link set up vcan0)"
    else:
        return "socketcan", "vcan0", "vcan0 is up and the kernel has AF_CAN"
    return (
        "udp_multicast",
        udp_multicast_group(),
        f"{why}; udp_multicast has no bit rate, so no real bus timing",
    )


#: The range a run's own udp_multicast port is drawn from: even ports (a latency
#: link's second bus takes the next one, :meth:`BusSpec.peer`) above python-can's default.
OWN_PORT_BASE, OWN_PORT_CHOICES = 44000, 5000


def own_udp_port(seed: int | None = None) -> int:
    """A udp_multicast port of a run's own (even; the next one free for a latency link's
    second bus): parallel runs on one host must not hear each other.  ``seed``: the same
    seed, the same port (the command line seeds with its process id); None draws anew."""
    import random

    rng = random.Random(seed) if seed is not None else random.SystemRandom()
    return OWN_PORT_BASE + 2 * rng.randrange(OWN_PORT_CHOICES)


def default_channel(interface: str) -> str | None:
    """The channel :func:`open_bus` uses for ``interface`` when none is given.

    ``vcan0`` for socketcan, :func:`udp_multicast_group` for udp_multicast,
    ``"bench"`` for virtual; None for adapters, which need an explicit one.
    """
    if interface == "socketcan":
        return "vcan0"
    if interface == "udp_multicast":
        return udp_multicast_group()
    if interface == "virtual":
        return VIRTUAL_CHANNEL
    return None


def _valid_interfaces() -> frozenset[str]:
    return frozenset(can.interfaces.VALID_INTERFACES)


def open_bus(
    interface: str | None,
    channel: str | None,
    *,
    fd: bool = True,
    bitrate: int | None = None,
    data_bitrate: int | None = None,
    receive_own_messages: bool = False,
    **kwargs: Any,
) -> can.BusABC:
    """Open a python-can bus.

    Parameters
    ----------
    interface : str or None
        python-can interface name (``socketcan``, ``udp_multicast``,
        ``virtual``, ``pcan``, ...). None: python-can's configuration when it
        names an interface, else :func:`default_transport`.
    channel : str or None
        Channel; defaults: ``vcan0`` (socketcan), :func:`udp_multicast_group`
        (udp_multicast), ``"bench"`` (virtual). Other interfaces need one
        unless python-can's configuration gives it.
    fd : bool
        Open the bus for CAN FD frames (the recorder frames are FD).
    bitrate, data_bitrate : int or None
        Arbitration and data bit rates (bit/s) for adapters that set them;
        ignored by socketcan (set with ``ip link``), udp_multicast and
        virtual. Adapters that need full bit timing take ``timing=`` (a
        :class:`can.BitTiming` or :class:`can.BitTimingFd`) in ``kwargs``.
    receive_own_messages : bool
        Also receive the frames this bus sends (not supported by
        udp_multicast).
    **kwargs
        Passed to :class:`can.Bus` (e.g. ``port`` for udp_multicast).

    Raises
    ------
    InterfaceError
        Unknown interface, missing channel, or any error of python-can or the
        driver while opening, as one line.
    """
    if interface is None:
        spec, _ = resolve_bus(None, channel, kwargs.pop("port", None), bitrate, data_bitrate)
        interface, channel = spec.interface, spec.channel
        bitrate, data_bitrate = spec.bitrate, spec.data_bitrate
        if spec.port is not None:
            kwargs["port"] = spec.port

    check_interface(interface)

    args: dict[str, Any] = dict(kwargs)
    if channel is None:
        channel = default_channel(interface)
    if interface == "socketcan":
        args.update(fd=fd, receive_own_messages=receive_own_messages)
    elif interface == "udp_multicast":
        if receive_own_messages:
            raise InterfaceError(
                f"interface udp_multicast channel {channel}: receive_own_messages unsupported"
            )
        args.update(fd=fd, hop_limit=UDP_HOP_LIMIT)
    elif interface == "virtual":
        args.update(receive_own_messages=receive_own_messages)
    else:
        if channel is None:
            raise InterfaceError(f"interface {interface}: needs a channel (--channel)")
        args.update(fd=fd, receive_own_messages=receive_own_messages)
        if interface == "slcan" and data_bitrate is not None:
            # python-can's slcan sets the CAN FD data rate only from a BitTimingFd
            # (nominal and data rate; CANable 2.0 firmware: 2 or 5 Mbit/s data)
            args["timing"] = slcan_fd_timing(bitrate or 1_000_000, int(data_bitrate))
        else:
            if bitrate is not None:
                args["bitrate"] = int(bitrate)
            if data_bitrate is not None:
                args["data_bitrate"] = int(data_bitrate)
    # A bus whose constructor failed is freed with the exception; python-can
    # then logs "... was not properly shut down", a second line after ours.
    log = logging.getLogger("can.bus")
    level = log.level
    try:
        return can.Bus(interface=interface, channel=channel, **args)
    except Exception as e:  # drivers raise anything from CanError to OSError or ImportError
        why = _one_line(e)
        log.setLevel(logging.ERROR)
    try:
        gc.collect()
    finally:
        log.setLevel(level)
    raise InterfaceError(f"interface {interface} channel {channel}: {why}")


#: What each adapter's python-can driver needs besides python-can, and where to get it.
DRIVER_NEEDS = {
    "slcan": "pyserial (pip install 'can-hil-bench[slcan]', or pip install pyserial)",
    "serial": "pyserial (pip install 'can-hil-bench[slcan]', or pip install pyserial)",
    "pcan": "PEAK's PCAN-Basic library libpcanbasic.so (PCAN-Basic for Linux, peak-system.com)",
    "kvaser": "Kvaser's CANlib libcanlib.so (Kvaser Linux Drivers and SDK, kvaser.com)",
}


def missing_driver(interface: str) -> str | None:
    """What ``interface``'s driver lacks on this machine (:data:`DRIVER_NEEDS`), or None."""
    import ctypes
    import ctypes.util
    import importlib.util

    if interface in ("slcan", "serial"):
        return None if importlib.util.find_spec("serial") else DRIVER_NEEDS[interface]
    if interface == "pcan":
        return None if ctypes.util.find_library("pcanbasic") else DRIVER_NEEDS[interface]
    if interface == "kvaser":
        try:
            ctypes.cdll.LoadLibrary("libcanlib.so")
        except OSError:
            return DRIVER_NEEDS[interface]
    return None


def slcan_fd_timing(bitrate: int, data_bitrate: int) -> can.BitTimingFd:
    """The bit timing that makes python-can's slcan send the nominal and data rate
    commands (it reads only ``nom_bitrate`` and ``data_bitrate``; an 80 MHz clock
    at 80 % sample points gives a valid timing for 1/2/5 Mbit/s)."""
    return can.BitTimingFd.from_sample_point(
        f_clock=80_000_000,
        nom_bitrate=int(bitrate),
        nom_sample_point=80.0,
        data_bitrate=int(data_bitrate),
        data_sample_point=80.0,
    )


def check_interface(interface: str) -> None:
    """Raise :class:`InterfaceError` (one line) when ``interface`` cannot work here."""
    if interface not in _valid_interfaces():
        known = ", ".join(sorted(_valid_interfaces()))
        raise InterfaceError(f"interface {interface!r}: unknown; python-can knows: {known}")
    if need := missing_driver(interface):
        raise InterfaceError(f"interface {interface}: its driver needs {need}")
    if interface == "socketcan" and not _af_can_works():
        raise InterfaceError(
            "interface socketcan: this kernel has no SocketCAN (no AF_CAN sockets); "
            "use udp_multicast (the default here), or tools/vcan-tests for vcan "
            "inside User-Mode Linux"
        )


#: How :func:`resolve_bus` names python-can's configuration as the reason for its bus.
FROM_CONFIG = "python-can configuration"


def resolve_bus(
    interface: str | None,
    channel: str | None,
    port: int | None = None,
    bitrate: int | None = None,
    data_bitrate: int | None = None,
    *,
    own_port: int | None = None,
    virtual: str | None = None,
) -> tuple[BusSpec, str | None]:
    """The bus the options name: the one place the bench resolves a bus.

    An ``interface`` given is taken with its ``channel`` (or
    :func:`default_channel`); none given, python-can's own configuration
    (:func:`python_can_config`: interface, channel, bit rates and port, each
    only where the options leave it open), else :func:`default_transport`,
    whose udp_multicast bus gets ``own_port`` when no ``port`` is given (a
    run's own, :func:`own_udp_port`; None: python-can's
    :data:`UDP_DEFAULT_PORT`, to join a bus rather than make one).
    ``virtual``: the one-line refusal of python-can's in-process ``virtual`` bus
    (for a caller whose bus must reach other processes); None takes it.

    Returns the bus and why it was chosen (None when the options named it;
    :data:`FROM_CONFIG`, or :func:`default_transport`'s reason).

    Raises
    ------
    InterfaceError
        An unknown interface or a missing driver, ``virtual`` refused, a
        channel without an interface, an adapter without a channel (one line).
    """
    why: str | None = None
    if interface is None and (cfg := python_can_config()) is not None:
        interface = str(cfg.get("interface"))
        channel = channel or cfg.get("channel")
        bitrate = (
            bitrate if bitrate is not None or cfg.get("bitrate") is None else int(cfg["bitrate"])
        )
        if data_bitrate is None and cfg.get("data_bitrate") is not None:
            data_bitrate = int(cfg["data_bitrate"])
        if port is None and cfg.get("port") is not None:
            port = int(cfg["port"])
        why = FROM_CONFIG
    if interface is None:
        if channel is not None:
            raise InterfaceError("--channel given without --interface")
        interface, channel, why = default_transport()
        if interface == "udp_multicast" and port is None:
            port = own_port
    else:
        check_interface(interface)
        if interface == "virtual" and virtual is not None:
            raise InterfaceError(virtual)
        channel = channel or default_channel(interface)
        if channel is None:
            raise InterfaceError(f"--interface {interface}: this adapter needs --channel")
    return BusSpec(interface, str(channel), port, bitrate, data_bitrate), why


def python_can_config() -> dict[str, Any] | None:
    """python-can's own configuration when it names an interface, else None."""
    if not _python_can_config_names_interface():
        return None
    try:
        return dict(can.util.load_config())
    except Exception as e:
        raise InterfaceError(f"python-can configuration: {_one_line(e)}") from None


def _python_can_config_names_interface() -> bool:
    """True when can.rc, the environment or a config file names an interface."""
    sources: list[dict[str, Any]] = [dict(can.rc)]
    try:
        sources.append(dict(can.util.load_environment_config()))
        sources.append(dict(can.util.load_file_config()))
    except Exception as e:
        raise InterfaceError(f"python-can configuration: {_one_line(e)}") from None
    return any(src.get("interface") or src.get("bustype") for src in sources)


def _one_line(e: BaseException) -> str:
    text = str(e).strip()
    first = text.splitlines()[0] if text else ""
    return f"{type(e).__name__}: {first}" if first else type(e).__name__


@dataclass(frozen=True, slots=True)
class BusSpec:
    """Where a node's bus is: a python-can interface, channel and options."""

    interface: str
    channel: str
    port: int | None = None
    bitrate: int | None = None
    data_bitrate: int | None = None

    def args(self) -> list[str]:
        a = ["--interface", self.interface, "--channel", self.channel]
        if self.port is not None:
            a += ["--port", str(self.port)]
        if self.bitrate is not None:
            a += ["--bitrate", str(self.bitrate)]
        if self.data_bitrate is not None:
            a += ["--data-bitrate", str(self.data_bitrate)]
        return a

    def open(self) -> can.BusABC:
        kw: dict[str, Any] = {}
        if self.port is not None:
            kw["port"] = self.port
        bus = open_bus(
            self.interface,
            self.channel,
            fd=True,
            bitrate=self.bitrate,
            data_bitrate=self.data_bitrate,
            **kw,
        )
        grow_receive_buffer(bus)
        return bus

    def peer(self) -> BusSpec:
        """The second bus of a latency link (controller side)."""
        if self.interface == "udp_multicast":
            return BusSpec(self.interface, self.channel, (self.port or UDP_DEFAULT_PORT) + 1)
        if self.interface == "socketcan" and self.channel[-1:].isdigit():
            return BusSpec(self.interface, self.channel[:-1] + str(int(self.channel[-1]) + 1))
        return BusSpec(self.interface, self.channel + "-b", self.port)

    def describe(self) -> str:
        s = f"{self.interface}:{self.channel}"
        return s + (f" port {self.port}" if self.port is not None else "")


#: Receive buffer asked for on socket-based buses (bytes): a recorder thread that
#: is descheduled for a while must not lose frames (udp_multicast drops on
#: overflow). A lockstep plant is paced to at most the command lead (3000
#: periods, about 15,000 frames of about 1 kB in the kernel) ahead of it.
RECEIVE_BUFFER = 64 << 20

#: The hop limit (IPv6) or TTL (IPv4) every udp_multicast bus of the bench sends with,
#: python-can's (``hop_limit``) and the native nodes' (bench/nodes/native, compiled with
#: it as ``BN_UDP_HOPS``): 0, this host.  The kernel still gives each datagram to every
#: socket of the group on this host (multicast loop-back, on as python-can leaves it),
#: but no network device sends it.  With python-can's default of 1 each datagram also
#: left on the host's network interface; in a virtual machine each is a transmit the
#: hypervisor does for the VM, and at a node pair's tens of thousands of datagrams a
#: second the host descheduled the whole VM for about 16 ms of every 100 ms (the host
#: stalls of docs/REALTIME.md).  Measured with ``bench perf``'s real-time run (the Python
#: nodes, 4 kHz, ``--rt-priority``, 2 s, two runs each, interleaved): 45-52 % of the
#: periods missed with 1, 1.0-4.5 % with 0.  udp_multicast is the bus of the nodes of
#: one host (docs/HARDWARE.md); between hosts the bench runs on CAN.
UDP_HOP_LIMIT = 0


def grow_receive_buffer(bus: can.BusABC) -> None:
    """Ask for a :data:`RECEIVE_BUFFER` receive buffer on a socket-based bus (best effort)."""
    sock = getattr(getattr(bus, "_multicast", None), "_socket", None) or getattr(
        bus, "socket", None
    )
    if not isinstance(sock, socket.socket):
        return
    # SO_RCVBUFFORCE (root: above net.core.rmem_max) is 33 on Linux; Python does not name it
    force = getattr(socket, "SO_RCVBUFFORCE", 33 if sys.platform.startswith("linux") else None)
    for opt in (force, socket.SO_RCVBUF):
        if opt is None:
            continue
        try:
            sock.setsockopt(socket.SOL_SOCKET, opt, RECEIVE_BUFFER)
            return
        except OSError:
            continue


def quiet_receive(bus: can.BusABC, group: str) -> None:
    """Stop delivery to a python-can udp_multicast bus that nobody reads (a native reader
    reads its ``group``: the recorder's, a native node's): it leaves the group, takes no
    other group's datagrams (``IP(V6)_MULTICAST_ALL`` off) and keeps the smallest receive
    buffer, so the kernel does not copy every frame of the bus into it (best effort).
    A python-can socketcan bus takes no frame at all (an empty ``CAN_RAW_FILTER``, the
    kernel's way to disable reception; python-can's ``set_filters([])`` means every
    frame); it still sends."""
    can_sock = getattr(bus, "socket", None)
    af_can = getattr(socket, "AF_CAN", None)
    if isinstance(can_sock, socket.socket) and af_can is not None and can_sock.family == af_can:
        try:
            can_sock.setsockopt(socket.SOL_CAN_RAW, socket.CAN_RAW_FILTER, b"")
            can_sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 0)
        except OSError:
            pass
        return
    sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
    if not isinstance(sock, socket.socket):
        return
    v6 = sock.family == socket.AF_INET6
    try:
        if v6:
            addr = socket.inet_pton(socket.AF_INET6, group)
            # IPV6_MULTICAST_ALL is 29 on Linux; Python does not name it
            sock.setsockopt(socket.IPPROTO_IPV6, 29, 0)
            mreq = addr + (0).to_bytes(4, "little")
            sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_LEAVE_GROUP, mreq)
        else:
            addr = socket.inet_aton(group)
            sock.setsockopt(socket.IPPROTO_IP, 49, 0)  # IP_MULTICAST_ALL
            sock.setsockopt(
                socket.IPPROTO_IP, socket.IP_DROP_MEMBERSHIP, addr + socket.inet_aton("0.0.0.0")
            )
    except (OSError, ValueError, AttributeError):
        pass
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 0)  # the kernel's minimum
    except OSError:
        pass


def bus_of(transport: str | None, *, known_port: bool = False) -> BusSpec:
    """The bus of ``transport=``: ``"socketcan:vcan0"``, ``"udp_multicast"`` (its group, on a
    port of the run's own), ``"udp_multicast:GROUP:PORT"``, any python-can interface as
    ``"NAME:CHANNEL"``; None: ``bench run``'s default (python-can's own configuration
    when it names an interface, else vcan0 when it is up, else udp_multicast on a port
    of the run's own). :func:`bench.wire._bus.resolve_bus` resolves it, as it does every
    bus of the bench.

    ``known_port``: udp_multicast without a port takes python-can's default port
    instead, where a controller under test that was told nothing finds it (as ``bench
    run --controller external`` does).
    """
    from dataclasses import replace

    iface: str | None = None
    chan: str | None = None
    port: int | None = None
    if transport is not None:
        iface, _, rest = transport.partition(":")
        if (
            iface == "udp_multicast"
            and rest.rpartition(":")[2].isdigit()
            and rest.count(":") in (1, 8)
        ):  # GROUP:PORT (an IPv6 group has 7 colons of its own)
            rest, _, p = rest.rpartition(":")
            port = int(p)
        check_interface(iface)
        chan = rest or default_channel(iface)
        if not chan and iface != "virtual":
            raise InterfaceError(
                f"transport {transport}: this adapter needs a channel (NAME:CHANNEL)"
            )
    spec, _ = resolve_bus(
        iface,
        chan,
        port,
        virtual="transport virtual: python-can's virtual bus lives inside one process and "
        "the bench's nodes are separate processes; use udp_multicast or socketcan",
    )
    if spec.interface == "udp_multicast" and spec.port is None:
        # parallel runs must not hear each other, unless the other side must find this one
        spec = replace(spec, port=UDP_DEFAULT_PORT if known_port else own_udp_port())
    return spec
