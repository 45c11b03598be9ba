"""The native recorder's receive side (``bn_rec.c``): a C thread keeps every frame.

A run's recorder (:class:`bench.runs._recorder.Recording`) reads python-can's
``udp_multicast`` bus, or a SocketCAN interface, through :class:`NativeReader`
where the native library loads: a C thread without the GIL, under ``SCHED_FIFO``
when asked for, drains the socket into a ring preallocated at open, with each
frame's kernel receive stamp; a Python thread takes the ring in batches and turns
each into the :class:`can.Message` python-can's bus would have returned
(udp_multicast: the fields ``bn_rec_parse`` reads in C from python-can's usual map,
checked as python-can checks them, else python-can's own ``unpack_message``;
SocketCAN: its ``dissect_can_frame`` and the fields its ``capture_message`` sets; the
time stamp computed as python-can computes it), which it hands to its listener a
batch at a time (``on_messages``), or one by one as :class:`can.Notifier` does.  On SocketCAN the kernel's drops for the socket are
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
import numpy as np
import numpy.typing as npt
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
from bench.wire._frames import FRAME_DTYPE

__all__ = [
    "INTERFACES",
    "RING_CAPACITY",
    "NativeReader",
    "SlotBatch",
    "can_message",
    "unavailable",
]

#: The ring's datagrams.  A 10 kHz native pair puts 4 datagrams a period on the
#: recorder's bus (wen-5.1 with tt-dq, measured: 160,050 in 40,000 periods: the plant's
#: samples and truth, the controller's duty and telemetry, the status), 40,000 a second
#: while the clock keeps time; the Python side turns one into a recorded frame in about
#: 4-5 us of CPU (of which python-can's BLF writer 2.3 us), 20 % of a core, which it may
#: not get beside two SCHED_FIFO nodes on 2 cores.  2**18 datagrams
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


class _Frame(ctypes.Structure):
    """``bn_rec_frame_t`` (bn_rec.h)."""

    _fields_ = [
        ("id", ctypes.c_uint32),
        ("channel", ctypes.c_uint32),
        ("off", ctypes.c_uint16),
        ("len", ctypes.c_uint8),
        ("flags", ctypes.c_uint8),
        ("ok", ctypes.c_uint8),
        ("has_channel", ctypes.c_uint8),
        ("pad", ctypes.c_uint8 * 2),
        ("data", ctypes.c_uint8 * 64),
    ]


#: ``bn_frame_t``'s flags (bn.h: BN_EXT 1, BN_FD 2, BN_BRS 4, BN_ESI 8, BN_ERR 32) that
#: bn_rec_parse sets, as (is_extended_id, is_fd, bitrate_switch, error_state_indicator,
#: is_error_frame).
_FLAGS = tuple(
    (bool(f & 1), bool(f & 2), bool(f & 4), bool(f & 8), bool(f & 32)) for f in range(64)
)
#: The same flags as the columns of FRAME_DTYPE.
_ROW_FLAGS = (("extended", 1), ("fd", 2), ("brs", 4), ("error", 32))

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
    dll.bn_rec_frame_size.restype = ctypes.c_size_t
    if int(dll.bn_rec_frame_size()) != ctypes.sizeof(_Frame):
        raise OSError(0, "bn_rec_frame_t and its Python mirror differ in size")
    dll.bn_rec_parse.argtypes = [ctypes.c_void_p, ctypes.c_uint64, ctypes.c_void_p]
    dll.bn_rec_parse.restype = ctypes.c_uint64
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


class SlotBatch:
    """The slots of one batch taken from the ring (``bn_rec_take``), and the
    :class:`can.Message` each holds as python-can's bus on ``interface`` (``channel``) would
    have returned it.

    udp_multicast: ``bn_rec_parse`` reads python-can's msgpack map where it has the shape
    python-can's ``pack_message`` writes and its values pass ``can.Message``'s check, and
    the message is built from those fields (``check=False``: checked in C); any other
    datagram goes through python-can's own ``unpack_message``, which decides.
    """

    def __init__(self, interface: str, channel: str, capacity: int = TAKE_BATCH) -> None:
        self._dll, slot = _lib()
        self.interface = interface
        self.channel = channel
        self.capacity = capacity
        self.buf = (slot * capacity)()
        self._slot_size = ctypes.sizeof(slot)
        self._data_off = int(slot.data.offset)
        self._dgram = ctypes.sizeof(slot) - self._data_off
        self._slots = np.ctypeslib.as_array(self.buf)  # a view: the columns of a batch
        self._raw = memoryview(self.buf).cast("B")
        self._parsed = (_Frame * capacity)()
        self._frames = np.ctypeslib.as_array(self._parsed)
        #: The slots of the last batch that bn_rec_parse read (the rest: python-can's).
        self.parsed = 0

    def put(self, datagrams: list[tuple[bytes, int, int]]) -> int:
        """Fill the first slots with ``(datagram, sec, nsec)`` as the receive thread does
        (a datagram longer than a slot: truncated); how many (replays and tests)."""
        n = min(len(datagrams), self.capacity)
        for i, (d, sec, nsec) in enumerate(datagrams[:n]):
            s = self.buf[i]
            s.sec, s.nsec = sec, nsec
            s.truncated = len(d) > self._dgram
            s.len = min(len(d), self._dgram)
            s.local = 0
            ctypes.memmove(ctypes.addressof(s) + self._data_off, d, s.len)
        return n

    def messages(self, n: int) -> tuple[list[can.Message], int, npt.NDArray[np.void] | None]:
        """The messages python-can's bus would have returned for the first ``n`` slots, how
        many slots held none (truncated, or refused as python-can's bus refuses them), and
        where bn_rec_parse read every slot, the same frames as rows of
        :data:`bench.wire._frames.FRAME_DTYPE` (else None)."""
        slots = self._slots[:n]
        secs = slots["sec"]
        # python-can's bus: seconds + nanoseconds * 1.0e-9 of SO_TIMESTAMPNS (the same
        # float64 operations, column-wise); time.time() where the kernel gave no stamp
        stamps = (secs.astype(np.float64) + slots["nsec"] * 1.0e-9).tolist()
        if (secs < 0).any():
            for i in np.flatnonzero(secs < 0).tolist():
                stamps[i] = time.time()
        raw = self._raw
        base = np.arange(n) * self._slot_size + self._data_off
        if self.interface == "udp_multicast":
            parsed = int(self._dll.bn_rec_parse(self.buf, n, self._parsed))
            fr = self._frames[:n]
        else:
            parsed = 0
        self.parsed = parsed
        message = can.Message
        if parsed == n:
            # bn_rec_parse: unpack_message's fields, its check passed (every slot)
            flags = map(_FLAGS.__getitem__, fr["flags"].tolist())
            has = fr["has_channel"]
            chans: list[int | None]
            if not has.any():
                chans = [None] * n
            elif has.all():
                chans = list(fr["channel"].tolist())
            else:
                chans = [
                    c if h else None
                    for c, h in zip(fr["channel"].tolist(), has.tolist(), strict=True)
                ]
            rows = np.zeros(n, dtype=FRAME_DTYPE)
            rows["timestamp"] = stamps
            rows["id"] = fr["id"]
            fl = fr["flags"]
            for name, bit in _ROW_FLAGS:
                rows[name] = (fl & bit) != 0
            rows["len"] = fr["len"]
            rows["data"] = fr["data"]
            start = (base + fr["off"]).tolist()
            end = (base + fr["off"] + fr["len"]).tolist()
            msgs = [
                message(ts, aid, ext, False, err, ch, dlc, bytearray(raw[a:b]), fd, True, brs, esi)
                for ts, aid, (ext, fd, brs, esi, err), ch, dlc, a, b in zip(
                    stamps,
                    fr["id"].tolist(),
                    flags,
                    chans,
                    fr["len"].tolist(),
                    start,
                    end,
                    strict=True,
                )
            ]
            return msgs, 0, rows
        # one by one: some slots are python-can's to judge
        lens = slots["len"].tolist()
        truncated = slots["truncated"].tolist()
        bases = base.tolist()
        if parsed:
            ok, ids, offs, dlcs, flag, chan, has_chan = (
                fr[k].tolist()
                for k in ("ok", "id", "off", "len", "flags", "channel", "has_channel")
            )
        else:
            ok = [0] * n
        malformed = 0
        msgs = []
        append = msgs.append
        for i in range(n):
            if truncated[i]:
                malformed += 1
                continue
            ts = stamps[i]
            if ok[i]:
                ext, fd, brs, esi, err = _FLAGS[flag[i]]
                a = bases[i] + offs[i]
                append(
                    message(
                        ts,
                        ids[i],
                        ext,
                        False,
                        err,
                        chan[i] if has_chan[i] else None,
                        dlcs[i],
                        bytearray(raw[a : a + dlcs[i]]),
                        fd,
                        True,
                        brs,
                        esi,
                    )
                )
                continue
            data = bytes(raw[bases[i] : bases[i] + lens[i]])
            try:
                if self.interface == "socketcan":
                    msg = can_message(data, ts, bool(slots["local"][i]), self.channel)
                else:
                    msg = unpack_message(data, replace={"timestamp": ts}, check=True)
            except Exception:  # python-can's bus raises CanOperationError on it
                malformed += 1
                continue
            append(msg)
        return msgs, malformed, None


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
        self._dll = _lib()[0]
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
        self._batch_buf = SlotBatch(interface, group)
        #: The listener's batch entry (``on_messages``: one call per batch), if it has one.
        self._batch = getattr(listener, "on_messages", None)
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
        n = int(self._dll.bn_rec_take(self._h, self._batch_buf.buf, TAKE_BATCH))
        if not n:
            return 0
        msgs, bad, rows = self._batch_buf.messages(n)
        self.malformed += bad
        self.frames += len(msgs)
        if self._batch is not None:
            self._batch(msgs, rows)
        else:
            on = self.listener.on_message_received
            for msg in msgs:
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
