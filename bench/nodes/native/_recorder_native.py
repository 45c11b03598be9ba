"""The native recorder's receive side (``bn_rec.c``): a C thread keeps every frame.

A run's recorder (:class:`bench.runs._recorder.Recording`) reads python-can's
``udp_multicast`` bus, or a SocketCAN interface, through :class:`NativeReader`
where the native library loads: a C thread without the GIL, under ``SCHED_FIFO``
when asked for, drains the socket into a ring preallocated at open, with each
frame's kernel receive stamp; a Python thread takes the ring in batches and turns
each into the :class:`can.Message` python-can's bus would have returned
(udp_multicast: python-can's own ``unpack_message``; SocketCAN: its
``dissect_can_frame`` and the fields its ``capture_message`` sets; the time stamp
computed as python-can computes it), which it hands to its listener as
:class:`can.Notifier` does.  On SocketCAN the kernel's drops for the socket are
counted too (``SO_RXQ_OVFL``), which python-can's bus does not say.
The socket is emptied at C speed, so the kernel's buffer no longer overflows
while the Python side is descheduled or slower than the bus: the ring absorbs
the lag, and a datagram that finds it full is counted (:attr:`NativeReader.lost`).
"""

from __future__ import annotations

import ctypes
import os
import threading
import time
from typing import Any

import can
from can.interfaces.socketcan.constants import (
    CAN_EFF_FLAG,
    CAN_ERR_FLAG,
    CAN_RTR_FLAG,
    CANFD_BRS,
    CANFD_ESI,
    CANFD_MTU,
)
from can.interfaces.socketcan.socketcan import dissect_can_frame
from can.interfaces.udp_multicast.utils import unpack_message

from bench.nodes.native._native import library

__all__ = ["INTERFACES", "RING_CAPACITY", "NativeReader", "can_message", "unavailable"]

#: The ring's datagrams.  A 10 kHz native pair puts 4 datagrams a period on the
#: recorder's bus (wen-5.1 with tt-dq, measured: 160,050 in 40,000 periods: the plant's
#: samples and truth, the controller's duty and telemetry, the status), 40,000 a second
#: while the clock keeps time; the Python side turns one into a recorded frame in about
#: 15 us of CPU (python-can's unpack, the Recorder's checks, the BLF writer), 60 % of a
#: core, which it does not get beside two SCHED_FIFO nodes on 2 cores.  2**18 datagrams
#: hold 6.6 s of that bus with the Python side not running at all, longer than the
#: real-time runs of ``bench perf`` (4 s); about 90 MB (bn_rec_slot_t: 344 bytes).
RING_CAPACITY = 1 << 18

#: The python-can interfaces the native recorder reads.
INTERFACES = ("udp_multicast", "socketcan")

#: Datagrams taken from the ring per call (one ctypes call per batch).
TAKE_BATCH = 4096


class _Stats(ctypes.Structure):
    """``bn_rec_stats_t`` (bn_rec.h)."""

    _fields_ = [
        ("received", ctypes.c_uint64),
        ("ring_lost", ctypes.c_uint64),
        ("unread", ctypes.c_uint64),
        ("errors", ctypes.c_uint64),
        ("calls", ctypes.c_uint64),
        ("cpu_ns", ctypes.c_int64),
        ("fifo", ctypes.c_int32),
        ("err_sched", ctypes.c_int32),
        ("fd", ctypes.c_int32),
        ("kind", ctypes.c_int32),
        ("kernel_drops", ctypes.c_uint64),
    ]


def _slot_type(dgram: int) -> type[ctypes.Structure]:
    class Slot(ctypes.Structure):
        """``bn_rec_slot_t`` (bn_rec.h)."""

        _fields_ = [
            ("sec", ctypes.c_int64),
            ("nsec", ctypes.c_int64),
            ("len", ctypes.c_uint16),
            ("truncated", ctypes.c_uint8),
            ("local", ctypes.c_uint8),
            ("pad", ctypes.c_uint8 * 4),
            ("data", ctypes.c_uint8 * dgram),
        ]

    return Slot


_DECLARED: list[tuple[ctypes.CDLL, type[ctypes.Structure]]] = []


def _lib() -> tuple[ctypes.CDLL, type[ctypes.Structure]]:
    """The library with the recorder's calls declared, and the slot type (its size checked)."""
    if _DECLARED:
        return _DECLARED[0]
    dll = library()
    dll.bn_rec_slot_size.restype = ctypes.c_size_t
    size = int(dll.bn_rec_slot_size())
    slot = _slot_type(size - 24)
    if ctypes.sizeof(slot) != size:
        raise OSError(0, f"bn_rec_slot_t is {size} bytes, the Python mirror {ctypes.sizeof(slot)}")
    dll.bn_rec_open.argtypes = [
        ctypes.c_char_p,
        ctypes.c_uint16,
        ctypes.c_int,
        ctypes.c_uint64,
        ctypes.c_int,
        ctypes.POINTER(ctypes.c_int),
    ]
    dll.bn_rec_open.restype = ctypes.c_void_p
    dll.bn_rec_open_can.argtypes = [
        ctypes.c_char_p,
        ctypes.c_int,
        ctypes.c_int,
        ctypes.c_uint64,
        ctypes.c_int,
        ctypes.POINTER(ctypes.c_int),
    ]
    dll.bn_rec_open_can.restype = ctypes.c_void_p
    dll.bn_rec_start.argtypes = [ctypes.c_void_p]
    dll.bn_rec_start.restype = ctypes.c_int
    dll.bn_rec_take.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_uint64]
    dll.bn_rec_take.restype = ctypes.c_uint64
    dll.bn_rec_pending.argtypes = [ctypes.c_void_p]
    dll.bn_rec_pending.restype = ctypes.c_uint64
    dll.bn_rec_stop.argtypes = [ctypes.c_void_p]
    dll.bn_rec_stop.restype = None
    dll.bn_rec_stats.argtypes = [ctypes.c_void_p, ctypes.POINTER(_Stats)]
    dll.bn_rec_stats.restype = None
    dll.bn_rec_close.argtypes = [ctypes.c_void_p]
    dll.bn_rec_close.restype = None
    _DECLARED.append((dll, slot))
    return _DECLARED[0]


def unavailable(interface: str) -> str | None:
    """Why the native recorder cannot read ``interface`` here (None: it can)."""
    from bench._errors import BenchError

    if interface not in INTERFACES:
        return f"the native recorder reads udp_multicast and socketcan only, not {interface}"
    try:
        _lib()
    except (BenchError, OSError) as e:
        return f"the native library is not available ({e})"
    return None


def can_message(frame: bytes, ts: float, local: bool, channel: str) -> can.Message:
    """The :class:`can.Message` python-can's socketcan bus on ``channel`` returns for the
    ``struct can(fd)_frame`` bytes ``frame`` received at ``ts`` (``local``: the kernel's
    ``MSG_DONTROUTE``, a frame sent on this host): the fields of python-can's
    ``capture_message``, the channel its bus fills in."""
    can_id, dlc, flags, data = dissect_can_frame(frame)
    ext = bool(can_id & CAN_EFF_FLAG)
    return can.Message(
        timestamp=ts,
        channel=channel,
        arbitration_id=can_id & (0x1FFFFFFF if ext else 0x7FF),
        is_extended_id=ext,
        is_remote_frame=bool(can_id & CAN_RTR_FLAG),
        is_error_frame=bool(can_id & CAN_ERR_FLAG),
        is_fd=len(frame) == CANFD_MTU,
        is_rx=not local,
        bitrate_switch=bool(flags & CANFD_BRS),
        error_state_indicator=bool(flags & CANFD_ESI),
        dlc=dlc,
        data=data,
    )


class NativeReader:
    """Reads python-can's udp_multicast bus ``group``/``port`` (``interface``
    ``udp_multicast``) or the SocketCAN interface ``group`` (``socketcan``; ``port`` unused)
    in C, and hands each frame to ``listener`` from a Python thread (the part of
    :class:`can.Notifier` a recorder uses).

    ``priority``: the C thread's ``SCHED_FIFO`` priority (None: normal scheduling).
    ``rcvbuf``: the socket's receive buffer (bytes); ``capacity``: the ring's datagrams
    (default :data:`RING_CAPACITY`); ``fd``: SocketCAN, receive CAN FD frames too (as
    the bench's buses do).  :class:`OSError` when the socket cannot be opened.
    """

    def __init__(
        self,
        group: str,
        port: int,
        listener: can.Listener,
        *,
        interface: str = "udp_multicast",
        fd: bool = True,
        priority: int | None = None,
        rcvbuf: int = 0,
        capacity: int | None = None,
        poll_s: float = 0.05,
    ) -> None:
        self._dll, slot = _lib()
        self.listener = listener
        self.interface = interface
        self._channel = group
        err = ctypes.c_int(0)
        cap = RING_CAPACITY if capacity is None else capacity
        if interface == "socketcan":
            handle = self._dll.bn_rec_open_can(
                group.encode(), int(fd), rcvbuf, cap, priority or 0, ctypes.byref(err)
            )
        elif interface == "udp_multicast":
            handle = self._dll.bn_rec_open(
                group.encode(), port, rcvbuf, cap, priority or 0, ctypes.byref(err)
            )
        else:
            raise OSError(0, f"the native recorder cannot read {interface}")
        if not handle:
            raise OSError(-err.value, f"native recorder: {os.strerror(-err.value)}")
        self._h: int | None = handle
        self._buf = (slot * TAKE_BATCH)()
        self._poll_s = poll_s
        #: Datagrams that were not python-can messages (truncated, or refused by
        #: ``unpack_message``: python-can's bus raises on them).
        self.malformed = 0
        #: Frames handed to the listener.
        self.frames = 0
        self._stopping = threading.Event()
        self._ended = False
        rc = self._dll.bn_rec_start(handle)
        if rc != 0:
            self._dll.bn_rec_close(handle)
            self._h = None
            raise OSError(-rc, f"native recorder thread: {os.strerror(-rc)}")
        self._thread = threading.Thread(target=self._run, name="native-recorder", daemon=True)
        self._thread.start()

    def _take(self) -> int:
        """Hand one batch of the ring to the listener; how many datagrams it held."""
        assert self._h is not None
        n = int(self._dll.bn_rec_take(self._h, self._buf, TAKE_BATCH))
        buf = self._buf
        on = self.listener.on_message_received
        can_bus = self.interface == "socketcan"
        for i in range(n):
            s = buf[i]
            length = int(s.len)
            if s.truncated:
                self.malformed += 1
                continue
            data = bytes(memoryview(s.data)[:length])
            sec = int(s.sec)
            # python-can's bus: seconds + nanoseconds * 1.0e-9 of SO_TIMESTAMPNS
            ts = sec + int(s.nsec) * 1.0e-9 if sec >= 0 else time.time()
            try:
                if can_bus:
                    msg = can_message(data, ts, bool(s.local), self._channel)
                else:
                    msg = unpack_message(data, replace={"timestamp": ts}, check=True)
            except Exception:  # python-can's bus raises CanOperationError on it
                self.malformed += 1
                continue
            self.frames += 1
            on(msg)
        return n

    def _run(self) -> None:
        while True:
            stopping = self._stopping.is_set()
            n = self._take()
            if n:
                continue
            if stopping:
                return
            time.sleep(self._poll_s / 10)

    def pending(self) -> int:
        """Datagrams not yet handed to the listener (ring, plus 1 when the socket holds any):
        0 once everything received so far is recorded."""
        if self._h is None:
            return 0
        return int(self._dll.bn_rec_pending(self._h))

    def stop(self) -> None:
        """Stop the C thread (what is left in the socket is counted in ``unread``), then hand
        the rest of the ring to the listener and end the Python thread."""
        if self._h is None or self._ended:
            return
        self._dll.bn_rec_stop(self._h)
        self._stopping.set()
        self._thread.join()
        self._ended = True

    def stats(self) -> dict[str, Any]:
        """The C thread's counters (bn_rec_stats_t) and the Python side's."""
        st = _Stats()
        if self._h is not None:
            self._dll.bn_rec_stats(self._h, ctypes.byref(st))
        return {
            "received": int(st.received),
            "ring_lost": int(st.ring_lost),
            "unread": int(st.unread),
            "errors": int(st.errors),
            "calls": int(st.calls),
            "cpu_ns": int(st.cpu_ns),
            "fifo": bool(st.fifo),
            "err_sched": int(st.err_sched),
            "fd": int(st.fd),
            "kernel_drops": int(st.kernel_drops),
            "malformed": self.malformed,
            "frames": self.frames,
        }

    def close(self) -> None:
        """Stop, close the socket and free the ring."""
        self.stop()
        if self._h is not None:
            self._dll.bn_rec_close(self._h)
            self._h = None
