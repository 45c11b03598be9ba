"""The recorder of a run: every frame of the bus(es) into one python-can log file.

:class:`Recorder` keeps every frame (tagged with its bus: 1 the plant side, 2
the controller side of a latency link), writes it to the capture and follows
the plant's step from the sample counters, which paces the bench's commands
(:mod:`bench.runs._run`).  :class:`Recording` opens the buses, the writer
and the notifiers of one run and closes them in order.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import can
import numpy as np
import numpy.typing as npt

from bench.nodes._loops import STATE_DONE
from bench.wire._batch_decode import decode_batch
from bench.wire._bus import UDP_DEFAULT_PORT, BusSpec, quiet_receive
from bench.wire._codec import Codec
from bench.wire._frames import FrameArray
from bench.wire._protocol import SHARED_RUN_FRAMES

#: A batch of at least this many frames has its sample, truth and telemetry frames decoded
#: column-wise (:meth:`Recorder._follow`), below it one by one: numpy's fixed cost per
#: batch (a few tenths of a ms) is then less than the codec's 2 us per frame it saves
#: (the demo's capture in batches of 128: one by one 6.4 us a frame in all, column-wise 7.1).
BATCH_DECODE_MIN = 256


#: The signals the rules read from a batch decoded column-wise (:meth:`Recorder._follow`).
_FOLLOWED_SIGNALS = ("run_id", "step", "cmd_ack_valid", "cmd_ack")


class Recorder(can.Listener):
    """Keeps every frame (with the index of the bus it came from) and writes the capture."""

    def __init__(
        self, codec: Codec, writer: can.Listener, channel: int, *, watch_duties: bool = False
    ) -> None:
        self.codec = codec
        self.writer = writer
        self.channel = channel
        self.frames: list[can.Message] = []
        self.samples_id = codec.frame_id("PhaseSamples")
        #: What another run sends and a controller under test waiting for its
        #: first sample does not: the plant's frames and the bench's commands.
        self.run_ids_frames = frozenset(
            codec.frame_id(n) for n in ("PhaseSamples", "PlantTruth", "PlantStatus", "BenchCommand")
        )
        self.status_id = codec.frame_id("PlantStatus")
        self.last_raw_step = -1
        #: The plant's step from the sample counter, unwrapped here where every
        #: frame is seen in order (a poller could miss a whole counter cycle).
        self.step = -1
        self._m_step = 1 << codec.step_bits("PhaseSamples")
        #: The plant's step from this run's ``PlantTruth`` counter, unwrapped alike: the
        #: plant's progress while its samples are lost to a fault (``[[faults]]`` drop,
        #: silence), which a lockstep bench must still pace.
        self.truth_step = -1
        self._last_raw_truth = -1
        self._m_truth = 1 << codec.step_bits("PlantTruth")
        self.done = threading.Event()
        self.lock = threading.Lock()
        #: ``PwmDuty`` frames checked here (a controller under test): valid ones,
        #: and the rejected ones by the codec's reason (CRC, length, range).
        self.duty_id = codec.frame_id("PwmDuty") if watch_duties else -1
        self.duties_ok = 0
        self.duty_rejected: dict[str, int] = {}
        #: The newest ``PlantStatus``: fault code, step (raw), late_frames, overruns.
        self.status: dict[str, int] = {}
        #: This run's nonce; valid ``PlantTruth`` and ``CtrlTelemetry`` frames of
        #: another (nonzero) run_id are counted in ``foreign``, by run_id: frames
        #: of distinct steps (another run sends one a period; copies of one
        #: frame, a replay or a random frame that passed the CRC, count once).
        self.recorder_ids = (codec.frame_id("PlantTruth"), codec.frame_id("CtrlTelemetry"))
        self.run_id: int | None = None
        self.foreign: dict[int, int] = {}
        self._foreign_seen: set[tuple[int, int, int]] = set()
        #: Valid plant and bench frames seen before :meth:`Recording.expect_run`
        #: (another run's: the nodes of this one have not started).
        self.known = 0
        self._known_seen: set[tuple[int, bytes]] = set()
        #: ``CtrlTelemetry`` as (step, cmd_ack_valid, cmd_ack), for the pacer (DBC 2.2).
        self.tel_id = codec.frame_id("CtrlTelemetry")
        self.acks: list[tuple[int, int, int]] = []
        #: The raw ``PlantStatus.step`` of the first status that carried each fault code
        #: (the trip's own frame; later ones carry later steps).
        self.fault_steps: dict[int, int] = {}
        #: The frames a long batch decodes column-wise (:meth:`_follow`), and every frame
        #: a rule reads.
        self._hot_ids = frozenset((self.samples_id, *self.recorder_ids))
        self._samples_name = "PhaseSamples"
        self._recorder_names = ("PlantTruth", "CtrlTelemetry")
        self._followed = self._hot_ids | self.run_ids_frames | {self.duty_id, self.status_id}
        self._hot_array = np.array(sorted(self._hot_ids), dtype=np.uint32)
        self._followed_array = np.array(sorted(self._followed - {-1}), dtype=np.uint32)

    def on_message_received(self, msg: can.Message) -> None:
        """One frame (python-can's :class:`can.Notifier`): :meth:`on_messages` of one."""
        self.on_messages([msg])

    def on_messages(
        self, msgs: list[can.Message], rows: npt.NDArray[np.void] | None = None
    ) -> None:
        """Frames in the order received (the native reader's batch): kept and written
        under one lock, then followed frame by frame (:meth:`_follow`).  ``rows``: the
        same frames as rows of :data:`bench.wire._frames.FRAME_DTYPE`, where the reader
        has them (read in place of the messages' fields)."""
        channel = self.channel
        for msg in msgs:
            msg.channel = channel
        write = self.writer.on_message_received
        with self.lock:
            self.frames.extend(msgs)
            for msg in msgs:
                write(msg)
        self._follow(msgs, rows)

    # -- following the run: each rule once, fed frame by frame or from a batch's columns --

    def _follow(self, msgs: list[can.Message], rows: npt.NDArray[np.void] | None = None) -> None:
        """The plant's step, this run's truth step, acknowledgements, other runs' frames,
        duties and status, from the frames in order (the run_id as at the batch's start).

        A batch of at least :data:`BATCH_DECODE_MIN` frames has its sample, truth and
        telemetry frames decoded column-wise (:func:`bench.wire._batch_decode.decode_batch`:
        the values and verdicts of :meth:`Codec.decode`); every other frame, and every
        frame of a shorter batch, is decoded by the codec one by one.  The rules are the
        same methods either way; their state is per kind of frame, so each kind is
        followed in the order of its frames."""
        run_id = self.run_id
        if len(msgs) < BATCH_DECODE_MIN:
            for msg in msgs:
                self._follow_one(msg, run_id)
            return
        frames: Sequence[can.Message]
        if rows is not None:  # the reader's columns: no message's field read
            ids = rows["id"]
            plain = ~(rows["extended"] | rows["remote"] | rows["error"])
            hot = np.isin(ids, self._hot_array) & plain
            rest = np.flatnonzero(np.isin(ids, self._followed_array) & ~hot).tolist()
            at = np.flatnonzero(hot).tolist()
            frames = FrameArray(rows[hot])
        else:
            at, rest = [], []
            for i, m in enumerate(msgs):
                if m.arbitration_id in self._hot_ids and not (
                    m.is_extended_id or m.is_remote_frame or m.is_error_frame
                ):
                    at.append(i)
                elif m.arbitration_id in self._followed:
                    rest.append(i)
            frames = [msgs[i] for i in at]
        for i in rest:
            self._follow_one(msgs[i], run_id)
        res = decode_batch(frames, self.codec, _FOLLOWED_SIGNALS)
        samples = res.messages.get(self._samples_name)
        if samples is not None:
            if run_id is None:
                for j in samples.index.tolist():
                    self._known_frame(msgs[at[j]])
            self._samples(samples.signals["step"].astype(np.int64).tolist())
        # truth and telemetry in the order they came (other runs' count has a cap)
        parts = [res.messages.get(n) for n in self._recorder_names]
        found = [p for p in parts if p is not None]
        if not found:
            return
        idx = np.concatenate([p.index for p in found])
        aid = np.concatenate([np.full(len(p.index), self.codec.frame_id(p.name)) for p in found])
        cols = {
            k: np.concatenate(
                [p.signals[k] if k in p.signals else np.zeros(len(p.index)) for p in found]
            )
            for k in _FOLLOWED_SIGNALS
        }
        order = np.argsort(idx, kind="stable")
        recs = zip(
            idx[order].tolist(),
            aid[order].tolist(),
            *(
                cols[k][order].astype(np.int64).tolist()  # counters: whole numbers
                for k in _FOLLOWED_SIGNALS
            ),
            strict=True,
        )
        if run_id is None:
            for j, a, *_ in recs:
                if a == self.recorder_ids[0]:
                    self._known_frame(msgs[at[j]])
            return
        frame = self._recorder_frame
        for _, a, rid, step, ack_valid, ack in recs:
            frame(a, rid, step, ack_valid, ack, run_id)

    def _valid(self, msg: can.Message) -> dict[str, float] | None:
        """The frame's signals where it passes the codec's checks, else None."""
        d = self.codec.decode(msg)
        return d.signals if d is not None and d.reason is None else None

    def _follow_one(self, msg: can.Message, run_id: int | None) -> None:
        """One frame, decoded by the codec."""
        aid = msg.arbitration_id
        if aid not in self._followed:
            return
        sig = None
        if run_id is None and not msg.is_extended_id and aid in self.run_ids_frames:
            sig = self._valid(msg)
            if sig is not None:
                self._known_frame(msg)
        if aid in self.recorder_ids and run_id is not None:
            sig = self._valid(msg)
            if sig is not None:
                tel = aid == self.tel_id
                self._recorder_frame(
                    aid,
                    int(sig["run_id"]),
                    int(sig["step"]),
                    int(sig["cmd_ack_valid"]) if tel else 0,
                    int(sig["cmd_ack"]) if tel else 0,
                    run_id,
                )
        elif aid == self.samples_id:
            sig = sig if sig is not None else self._valid(msg)
            if sig is not None:
                self._samples((sig["step"],))
        elif aid == self.duty_id:
            d = self.codec.decode(msg)
            if d is not None and d.reason is None:
                self.duties_ok += 1
            elif d is not None and d.reason is not None:
                self.duty_rejected[d.reason] = self.duty_rejected.get(d.reason, 0) + 1
        elif aid == self.status_id:
            sig = sig if sig is not None else self._valid(msg)
            if sig is not None:
                self.status = {k: int(v) for k, v in sig.items()}
                self.fault_steps.setdefault(self.status["fault_code"], self.status["step"])
                if int(sig["state"]) == STATE_DONE:
                    self.done.set()

    def _known_frame(self, msg: can.Message) -> None:
        """A valid plant or bench frame before the run's start: another run's, unless a
        copy of one already counted (a replay)."""
        key = (msg.arbitration_id, bytes(msg.data))
        if key not in self._known_seen:
            self._known_seen.add(key)
            self.known += 1

    def _samples(self, raws: Iterable[float]) -> None:
        """Valid ``PhaseSamples`` step counters, in order: the plant's step unwrapped."""
        m, half = self._m_step, self._m_step // 2
        for r in raws:
            raw = int(r)
            last = self.last_raw_step
            if last < 0:
                self.step, self.last_raw_step = raw, raw
            else:
                ahead = (raw - last) % m
                if ahead < half:  # behind: a retransmitted old frame
                    self.step += ahead
                    self.last_raw_step = raw

    def _recorder_frame(
        self, aid: int, rid: int, step: int, ack_valid: int, ack: int, run_id: int
    ) -> None:
        """A valid ``PlantTruth`` or ``CtrlTelemetry`` (its run_id, step and, telemetry,
        acknowledgement) once the run's own run_id is known."""
        if rid == run_id and aid == self.recorder_ids[0]:
            if self._last_raw_truth < 0:
                self.truth_step = self._last_raw_truth = step
            elif (ahead := (step - self._last_raw_truth) % self._m_truth) < self._m_truth // 2:
                self.truth_step += ahead
                self._last_raw_truth = step
        if rid not in (run_id, 0):  # 0: a controller that copies no nonce
            seen = (aid, rid, step)
            if seen not in self._foreign_seen and len(self._foreign_seen) < 4096:
                self._foreign_seen.add(seen)
                self.foreign[rid] = self.foreign.get(rid, 0) + 1
        elif aid == self.tel_id:
            self.acks.append((step, ack_valid, ack))


def socket_drops(bus: can.BusABC) -> int | None:
    """Frames the recorder lost on ``bus``'s UDP socket: those the kernel dropped (its
    receive buffer was full), and those still queued in it, unread, when its reader
    has stopped (a drain that gave up: :func:`drain`'s limit).

    The drops are the ``drops`` column of ``/proc/net/udp`` (``udp6``) for the
    socket's inode (:func:`fd_drops`); the queued ones are read out here and counted.
    None where the bus has no UDP socket or the system does not say (not Linux).
    """
    sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
    if sock is None:
        return None
    unread = 0
    sock.setblocking(False)
    try:
        while True:
            sock.recv(4096)
            unread += 1
    except OSError:  # BlockingIOError: empty
        pass
    drops = fd_drops(sock.fileno())
    return None if drops is None else drops + unread


def fd_drops(fd: int) -> int | None:
    """The ``drops`` column of ``/proc/net/udp`` (``udp6``) for the UDP socket ``fd``: the
    datagrams the kernel dropped for it (its receive buffer was full); None where the
    system does not say."""
    import os

    try:
        inode = str(os.fstat(fd).st_ino)
    except OSError:
        return None
    for table in ("/proc/net/udp", "/proc/net/udp6"):
        try:
            lines = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            cols = line.split()
            if len(cols) >= 13 and cols[9] == inode:
                return int(cols[12])
    return None


#: How often :func:`drain` looks (s): the recorders' notifier timeout
#: (:class:`Recording`), the longest their thread blocks in a receive before it looks again.
DRAIN_POLL_S = 0.05


def queued_bytes(bus: can.BusABC) -> int | None:
    """What waits unread in the bus's socket (``FIONREAD``: for a UDP socket the size of
    the next datagram, 0 when none); None where the bus or its socket cannot say (a
    SocketCAN raw socket, an adapter without a file descriptor, not Linux)."""
    try:
        import fcntl
        import struct
        import termios

        fd = bus.fileno()
        if not isinstance(fd, int) or fd < 0:
            return None
        n = struct.unpack("i", fcntl.ioctl(fd, termios.FIONREAD, b"\0\0\0\0"))[0]
    except (ImportError, AttributeError, NotImplementedError, OSError, ValueError):
        return None
    return int(n)


def drain(
    recorders: list[Recorder],
    quiet_s: float = 0.5,
    limit_s: float = 10.0,
    buses: list[can.BusABC] | None = None,
    pending: list[Callable[[], int | None]] | None = None,
) -> None:
    """Wait until the recorders have read what is still queued in their sockets.

    On a slow host (User-Mode Linux) the recorder thread lags the nodes by
    thousands of frames; stopping it as soon as the nodes end would lose them.
    Called once the nodes have ended.  Returns once every socket of ``buses``
    says it is empty (:func:`queued_bytes`) and no frame came in for one look
    (:data:`DRAIN_POLL_S`): a frame the recorder thread has taken from its socket
    is recorded before its notifier's ``stop()`` lets it end.  Where a socket
    cannot say: once no frame came in for ``quiet_s``.  At most ``limit_s``.
    ``pending``: one call per reader that says what it has not yet recorded in place of
    a socket's :func:`queued_bytes` (:meth:`NativeReader.pending`: 0 once recorded).
    """
    t0 = time.monotonic()
    last, t_last = -1, t0
    while time.monotonic() - t0 < limit_s:
        n = sum(len(r.frames) for r in recorders)
        now = time.monotonic()
        if n != last:
            last, t_last = n, now
        else:
            queued = [queued_bytes(b) for b in buses or []]
            queued += [p() for p in pending or []]
            empty = bool(queued) and all(q == 0 for q in queued)
            if now - t_last >= (DRAIN_POLL_S if empty else quiet_s):
                return
        time.sleep(DRAIN_POLL_S)


class Recording:
    """The buses of a run (one, or two with a latency link), each with its recorder.

    Opening the buses comes first, so a bus that cannot be opened leaves no
    empty capture behind.  :meth:`close` drains what is still queued, then
    stops the readers, the writer and the buses.

    Each bus is read by the native recorder (:mod:`bench.nodes.native._recorder_native`:
    a C thread drains its socket into a ring, a Python thread hands the frames to
    its :class:`Recorder`) where it can serve (udp_multicast, the native library
    built), else by python-can's :class:`can.Notifier`; :attr:`engine` says which,
    :attr:`engine_note` why not native.  The python-can bus stays open for what the
    bench sends (commands); where the native recorder reads, its own receive side is
    quieted (:func:`quiet_receive`).  ``engine``: ``"auto"`` (native where it can),
    ``"python"``.  ``rt_priority``: the native receive thread's ``SCHED_FIFO`` priority.
    """

    def __init__(
        self,
        specs: list[BusSpec],
        capture: Path,
        codec: Codec,
        *,
        watch_duties: bool = False,
        engine: str = "auto",
        rt_priority: int | None = None,
    ) -> None:
        from bench.wire._bus import RECEIVE_BUFFER

        self.buses: list[can.BusABC] = []
        try:
            for spec in specs:
                self.buses.append(spec.open())
        except BaseException:
            for b in self.buses:
                b.shutdown()
            raise
        self.writer = can.Logger(str(capture))
        # duties are watched where the controller sends them (its side of a link)
        n = len(self.buses)
        self.recorders = [
            Recorder(codec, self.writer, i + 1, watch_duties=watch_duties and i == n - 1)
            for i in range(n)
        ]
        self.frames_lost: int | None = None
        for r in self.recorders[1:]:
            r.lock = self.recorders[0].lock  # one writer: one lock, or the capture is corrupted
        #: Which recorder reads the buses: ``native`` or ``python``; and why not native.
        self.engine = "python"
        self.engine_note: str | None = (
            "asked for the Python recorder" if engine == "python" else None
        )
        self.native: list[Any] = []
        self._native_final: list[dict[str, Any]] = []
        if engine != "python":
            self.native, self.engine_note = _native_readers(
                specs, self.recorders, rt_priority, RECEIVE_BUFFER
            )
        if self.native:
            self.engine = "native"
            for b, spec in zip(self.buses, specs, strict=True):
                quiet_receive(b, spec.channel)
            self.notifiers: list[can.Notifier] = []
        else:
            self.notifiers = [
                can.Notifier(b, [r], timeout=DRAIN_POLL_S)
                for b, r in zip(self.buses, self.recorders, strict=True)
            ]

    @property
    def native_stats(self) -> list[dict[str, Any]]:
        """The native readers' counters (one per bus; empty with the Python recorder); after
        :meth:`close`, their final values."""
        return self._native_final or [nr.stats() for nr in self.native]

    @property
    def plant_bus(self) -> can.BusABC:
        """The plant's bus (the bench sends its commands there)."""
        return self.buses[0]

    @property
    def plant_step(self) -> int:
        """The plant's newest step the recorder has seen (-1 before the first sample)."""
        r = self.recorders[0]
        return r.step if r.step < 0 else max(r.step, r.truth_step)

    @property
    def plant_done(self) -> bool:
        """Whether the plant has said that the run is over (``PlantStatus``)."""
        return self.recorders[0].done.is_set()

    @property
    def bench_frames(self) -> int:
        """Plant and bench frames (another run's, before this one starts) seen, every bus."""
        return sum(r.known for r in self.recorders)

    def expect_run(self, run_id: int) -> None:
        """From now on, count ``PlantTruth`` of any other run_id as another run's."""
        for r in self.recorders:
            r.run_id = run_id

    @property
    def foreign(self) -> dict[int, int]:
        """Other runs on the bus: their run_id and recorder frames seen, by run_id.

        Only a run_id seen in at least ``SHARED_RUN_FRAMES`` valid frames of
        distinct steps counts (:mod:`bench.wire._protocol`).
        """
        out: dict[int, int] = {}
        for r in self.recorders:
            for k, v in r.foreign.items():
                out[k] = out.get(k, 0) + v
        return {k: v for k, v in out.items() if v >= SHARED_RUN_FRAMES}

    @property
    def duty_watch(self) -> Recorder:
        """The recorder of the controller's bus (where its ``PwmDuty`` frames are checked)."""
        return self.recorders[-1]

    def frames(self) -> list[can.Message]:
        """Every recorded frame, in time order across the buses."""
        if len(self.recorders) == 1:
            return self.recorders[0].frames
        return sorted((m for r in self.recorders for m in r.frames), key=lambda m: m.timestamp)

    def close(self) -> None:
        if self.native:
            drain(self.recorders, pending=[nr.pending for nr in self.native])
            drops: list[int | None] = []
            for nr in self.native:
                nr.stop()  # the rest of its ring recorded; what the socket still held counted
                st = nr.stats()
                self._native_final.append(st)
                # SocketCAN: the kernel's count came with the frames (SO_RXQ_OVFL)
                kernel = st["kernel_drops"] if nr.interface == "socketcan" else fd_drops(st["fd"])
                drops.append(None if kernel is None else kernel + st["unread"] + st["ring_lost"])
                nr.close()
        else:
            drain(self.recorders, buses=self.buses)
            for nt in self.notifiers:
                nt.stop()
            drops = [socket_drops(b) for b in self.buses]
        #: Frames the recorder's sockets lost (their receive buffers overflowed, or the
        #: native recorder's ring), None where the transport does not say (:func:`socket_drops`).
        self.frames_lost = None if None in drops else sum(d for d in drops if d is not None)
        self.writer.stop()
        for b in self.buses:
            b.shutdown()


def _native_readers(
    specs: list[BusSpec], recorders: list[Recorder], rt_priority: int | None, rcvbuf: int
) -> tuple[list[Any], str | None]:
    """One native reader per bus, each feeding its recorder; or none, and why (a bus the
    native recorder cannot read, the library not built, a socket it cannot open)."""
    from bench.nodes.native._recorder_native import NativeReader, unavailable

    for spec in specs:
        if why := unavailable(spec.interface):
            return [], why
    readers: list[Any] = []
    try:
        for spec, r in zip(specs, recorders, strict=True):
            port = spec.port if spec.port is not None else UDP_DEFAULT_PORT
            readers.append(
                NativeReader(
                    spec.channel,
                    port,
                    r,
                    interface=spec.interface,
                    priority=rt_priority,
                    rcvbuf=rcvbuf,
                )
            )
    except OSError as e:
        for nr in readers:
            nr.close()
        return [], f"the native recorder could not open its socket ({e.strerror or e})"
    return readers, None
