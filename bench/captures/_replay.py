"""Replaying a capture onto a bus with its recorded timing (reading: :mod:`bench.captures._read`).

``bench replay LOG`` sends a capture onto a bus with its recorded timing.
Every frame has an absolute deadline, ``t_0 + (t_i - t_first) / speed``
(plus whole capture spans when looping), measured on
:func:`time.perf_counter`, so a late frame never delays the next ones.  Two
clocks are offered: ``deadline`` sleeps until shortly before each deadline
and spins the rest (sub-10-microsecond error, at the cost of a busy core
near each frame), and ``messagesync``, python-can's :class:`can.MessageSync`,
which only sleeps (its error is the sleep overshoot of the OS, typically
50-100 us).  The achieved error (send instant minus deadline) is measured
for every frame and reported as median and worst; a median or p99 lateness
above ``max(1 ms, 10 % of the mean frame gap)`` is reported as a replay that
could not keep up (:meth:`ReplayResult.lag_warning`).

``--time sim`` replays a capture in simulated time instead (:func:`sim_timestamps`):
a lockstep run's capture carries the slowed pace at which the two processes
stepped (e.g. 27.8 s of capture for 4 s simulated), while its frames carry
the plant's step.  Each ``PlantTruth`` (32-bit step; ``PhaseSamples``,
unwrapped, in a capture without truth) of a new step is an anchor at
``step * T_s``, and the frames between two anchors are spread between their
instants in the order and proportion of their capture times; frames before
the first anchor and after the last keep their capture gaps to it.  The
default stays ``--time wall``, the capture's own timestamps: what a capture
of a real bus, or a real-time run, holds, and what ``replay`` has always sent.

Bench captures tag each frame with the bus it was recorded on: channel 1 is
the plant-side bus, 2 the controller-side bus (only with a latency link).
python-can's ``.log`` writer turns these into ``can1``/``can2``; both forms
are understood.  ``--channel-map CH=INTERFACE:CHANNEL`` sends each capture
channel onto a bus of its own (:func:`plan_replay`): every bus is opened
once, all follow the one absolute time line, and the frames of channels not
mapped go to the default bus.
"""

from __future__ import annotations

import contextlib
import copy
import ipaddress
import math
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field

import can
import numpy as np
import numpy.typing as npt

from bench._errors import BenchError, CaptureError
from bench.wire._bus import BusSpec
from bench.wire._codec import Codec

#: Replay clocks: own absolute-deadline loop, or python-can's ``MessageSync``.
CLOCKS = ("deadline", "messagesync")
#: Replay time lines: the capture's timestamps, or the simulated time of its steps.
TIMES = ("wall", "sim")
#: Messages whose step anchors the simulated time line, in order of preference.
_ANCHORS = ("PlantTruth", "PhaseSamples")


def channel_tag(channel: object) -> int | None:
    """The bench's bus tag of a frame's channel: ``1``, ``"1"`` and ``"can1"`` give 1."""
    if isinstance(channel, int):
        return channel
    if isinstance(channel, str):
        digits = ""
        for ch in reversed(channel):
            if not ch.isdigit():
                break
            digits = ch + digits
        return int(digits) if digits else None
    return None


def sim_timestamps(frames: Sequence[can.Message], codec: Codec, T_s: float) -> list[float]:
    """Each frame's instant in simulated time (s), for ``bench replay --time sim``.

    Anchors are the frames of ``PlantTruth`` (else ``PhaseSamples``) that
    carry a step above every step before them (copies, resends and a latency
    link's other bus are no anchors), at ``step * T_s``.  A frame between two
    anchors is placed between their instants in proportion of its capture
    time; before the first anchor and after the last, a frame keeps its
    capture gap to that anchor.  The first frame is at its own simulated
    instant (not shifted to 0), so a capture that starts mid-run keeps its
    place.

    Raises
    ------
    CaptureError
        No frame of the anchor messages passed the DBC's checks.
    """
    from bench.wire._batch_decode import decode_batch
    from bench.wire._protocol import unwrap

    dec = decode_batch(frames, codec)  # E2E-checked: a rejected frame is no anchor
    wall = np.array([m.timestamp for m in frames], dtype=float)
    anchors_t: list[float] = []
    anchors_s: list[float] = []
    for name in _ANCHORS:
        b = dec.messages.get(name)
        if b is None:
            continue
        modulus = 1 << codec.step_bits(name)
        last: int | None = None
        for i, raw in zip(
            b.index.tolist(), b.signals["step"].astype(np.int64).tolist(), strict=True
        ):
            step = raw if last is None else unwrap(raw, last, modulus)
            if last is not None and step <= last:
                continue
            if anchors_t and wall[i] <= anchors_t[-1]:
                continue  # a capture time that goes back: the earlier anchor holds
            last = step
            anchors_t.append(float(wall[i]))
            anchors_s.append(step * T_s)
        if len(anchors_t) >= 2:
            break
        anchors_t, anchors_s = [], []
    if not anchors_t:
        raise CaptureError(
            "--time sim: no valid PlantTruth or PhaseSamples frames (two steps at least) "
            "to place the frames in simulated time"
        )
    at, sim = np.asarray(anchors_t), np.asarray(anchors_s)
    out = np.interp(wall, at, sim)
    before, after = wall < at[0], wall > at[-1]
    out[before] = sim[0] - (at[0] - wall[before])
    out[after] = sim[-1] + (wall[after] - at[-1])
    return [float(v) for v in out]


def with_timestamps(frames: Sequence[can.Message], stamps: Sequence[float]) -> list[can.Message]:
    """Copies of ``frames`` with ``stamps`` as their timestamps (channel and all else kept)."""
    out = []
    for m, t in zip(frames, stamps, strict=True):
        c = copy.copy(m)
        c.timestamp = t
        out.append(c)
    return out


def parse_id(text: str, option: str | None = None) -> int:
    """A CAN identifier from ``0x210``, ``210h`` or decimal ``528`` (``option`` names it in errors)."""
    where = f"{option}: " if option else ""
    t = text.strip().lower()
    try:
        if t.startswith("0x"):
            v = int(t, 16)
        elif t.endswith("h"):
            v = int(t[:-1], 16)
        else:
            v = int(t, 10)
    except ValueError:
        raise BenchError(f"{where}not a CAN identifier: {text!r} (use 0x210 or 528)") from None
    if not 0 <= v < (1 << 29):
        raise BenchError(f"{where}CAN identifier out of range: {text!r}")
    return v


def parse_id_map(items: Iterable[str]) -> dict[int, int]:
    """``["0x10=0x210", ...]`` to ``{0x10: 0x210, ...}``; errors name ``--map`` and the item."""
    out: dict[int, int] = {}
    for item in items:
        old, sep, new = item.partition("=")
        if not sep:
            raise BenchError(f"--map: expected OLD=NEW (e.g. 0x10=0x210), got {item!r}")
        out[parse_id(old, f"--map {item}")] = parse_id(new, f"--map {item}")
    return out


def _selected(
    frames: Iterable[can.Message],
    *,
    ids: Iterable[int] | None,
    exclude_ids: Iterable[int] | None,
    channels: Iterable[int] | None,
    id_map: dict[int, int] | None,
) -> list[tuple[can.Message, can.Message]]:
    """Pairs (recorded frame, fresh frame to send) of :func:`select_frames`, in timestamp order."""
    keep = None if ids is None else frozenset(ids)
    drop = frozenset(exclude_ids or ())
    chans = None if channels is None else frozenset(channels)
    remap = id_map or {}
    out: list[tuple[can.Message, can.Message]] = []
    for m in frames:
        if m.is_error_frame:
            continue
        fid = m.arbitration_id
        if keep is not None and fid not in keep:
            continue
        if fid in drop:
            continue
        if chans is not None and channel_tag(m.channel) not in chans:
            continue
        new_id = remap.get(fid, fid)
        fresh = can.Message(
            timestamp=m.timestamp,
            arbitration_id=new_id,
            is_extended_id=m.is_extended_id or new_id > 0x7FF,
            is_remote_frame=m.is_remote_frame,
            is_fd=m.is_fd,
            bitrate_switch=m.bitrate_switch,
            error_state_indicator=m.error_state_indicator,
            dlc=m.dlc,
            data=m.data,
            check=False,
        )
        out.append((m, fresh))
    out.sort(key=lambda pair: pair[1].timestamp)  # stable: equal stamps keep their order
    return out


def select_frames(
    frames: Iterable[can.Message],
    *,
    ids: Iterable[int] | None = None,
    exclude_ids: Iterable[int] | None = None,
    channels: Iterable[int] | None = None,
    id_map: dict[int, int] | None = None,
) -> list[can.Message]:
    """The frames to replay, as fresh messages (no channel), in timestamp order.

    Error frames are dropped; ``ids``/``exclude_ids`` filter on the recorded
    identifier, ``channels`` on the bench's bus tag (:func:`channel_tag`),
    and ``id_map`` renames identifiers (a new ID above 0x7FF is sent extended).
    """
    pairs = _selected(frames, ids=ids, exclude_ids=exclude_ids, channels=channels, id_map=id_map)
    return [fresh for _, fresh in pairs]


# -- channel remapping -----------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ChannelMap:
    """One ``--channel-map CH=INTERFACE:CHANNEL``: frames of capture channel ``channel`` go to ``bus``.

    ``item`` is the text as given (for messages).
    """

    item: str
    channel: str
    bus: BusSpec


_CHANNEL_MAP_FORM = "CH=INTERFACE:CHANNEL (e.g. 2=socketcan:can1, 1=udp_multicast:239.0.0.1:43001)"


def _udp_target(rest: str, where: str) -> tuple[str | None, int | None]:
    """Group and port of ``GROUP``, ``GROUP:PORT``, ``[GROUP]:PORT`` or ``:PORT`` (udp_multicast)."""
    group: str = rest
    port_text: str | None = None
    if rest.startswith("["):
        close = rest.find("]")
        after = rest[close + 1 :] if close >= 0 else ""
        if close < 0 or (after and not after.startswith(":")):
            raise BenchError(f"{where}: expected udp_multicast:[GROUP]:PORT for an IPv6 group")
        group, port_text = rest[1:close], (after[1:] if after else None)
    elif rest.count(":") == 1:  # IPv4 group (or none) and a port; bare IPv6 has several colons
        group, port_text = rest.split(":")
    port: int | None = None
    if port_text is not None:
        try:
            port = int(port_text)
        except ValueError:
            port = -1
        if not 0 < port < 65536:
            raise BenchError(f"{where}: not a UDP port: {port_text!r} (1-65535)")
    if not group:
        return None, port
    try:
        is_multicast = ipaddress.ip_address(group).is_multicast
    except ValueError:
        raise BenchError(
            f"{where}: not an IP address: {group!r} (a multicast group such as 239.0.0.1; "
            "an IPv6 group with a port goes in brackets: [ff15::1]:43001)"
        ) from None
    if not is_multicast:
        raise BenchError(f"{where}: {group} is not a multicast group")
    return group, port


def parse_channel_map(
    items: Iterable[str], *, bitrate: int | None = None, data_bitrate: int | None = None
) -> list[ChannelMap]:
    """``["2=socketcan:can1", ...]`` to :class:`ChannelMap` items; errors name ``--channel-map``.

    ``INTERFACE`` is any python-can interface; ``CHANNEL`` is its channel and
    may be left out (``2=virtual``, ``2=socketcan:``) for the interface's
    default (``vcan0``, the udp_multicast group, ``bench``).  For
    ``udp_multicast`` the channel is ``GROUP``, ``GROUP:PORT``, ``:PORT``
    (the default group) or ``[GROUP]:PORT`` for an IPv6 group; without a port,
    python-can's default port.  ``bitrate``/``data_bitrate`` apply to every
    bus (real adapters).  Only the text is checked here; whether ``CH`` is
    in a capture is :func:`resolve_channel_map`'s part.
    """
    from bench.wire._bus import check_interface, default_channel

    out: list[ChannelMap] = []
    for item in items:
        where = f"--channel-map {item}"
        ch, sep, target = item.partition("=")
        ch, target = ch.strip(), target.strip()
        if not sep or not ch or not target:
            raise BenchError(f"--channel-map: expected {_CHANNEL_MAP_FORM}, got {item!r}")
        interface, _, rest = target.partition(":")
        interface, rest = interface.strip(), rest.strip()
        try:
            check_interface(interface)
        except BenchError as e:
            raise BenchError(f"{where}: {e}") from None
        port: int | None = None
        channel: str | None
        if interface == "udp_multicast":
            channel, port = _udp_target(rest, where)
        else:
            channel = rest or None
        channel = channel or default_channel(interface)
        if channel is None:
            raise BenchError(
                f"{where}: interface {interface} needs a channel ({ch}={interface}:CHANNEL)"
            )
        out.append(ChannelMap(item, ch, BusSpec(interface, channel, port, bitrate, data_bitrate)))
    return out


def _channel_key(channel: object) -> str | None:
    return None if channel is None else str(channel)


def resolve_channel_map(
    maps: Sequence[ChannelMap], frames: Iterable[can.Message]
) -> dict[str, int]:
    """Which map item each channel of the capture follows: ``{str(channel): index in maps}``.

    ``CH`` names a channel as python-can reads it (``1``, ``can1``); when no
    channel is spelled that way, the bench's bus tag matches (``1`` finds
    ``can1`` and ``can1`` finds ``1``, as with ``--channel-filter``).

    Raises
    ------
    BenchError
        ``CH`` is not in the capture, or names more than one of its channels,
        or a channel is mapped twice; one line naming ``--channel-map`` and the item.
    """
    present: dict[str, None] = {}
    for m in frames:
        key = _channel_key(m.channel)
        if key is not None:
            present[key] = None
    names = ", ".join(present) or "none: its frames carry no channel"
    out: dict[str, int] = {}
    for j, cm in enumerate(maps):
        hits = [c for c in present if c == cm.channel]
        tag = channel_tag(cm.channel)
        if not hits and tag is not None:
            hits = [c for c in present if channel_tag(c) == tag]
        where = f"--channel-map {cm.item}"
        if not hits:
            raise BenchError(
                f"{where}: channel {cm.channel} is not in the capture (its channels: {names})"
            )
        if len(hits) > 1:
            raise BenchError(
                f"{where}: channel {cm.channel} matches several of the capture's channels "
                f"({', '.join(hits)}); name one exactly"
            )
        if hits[0] in out:
            raise BenchError(
                f"{where}: capture channel {hits[0]} is already mapped by "
                f"--channel-map {maps[out[hits[0]]].item}"
            )
        out[hits[0]] = j
    return out


@dataclass(slots=True)
class ReplayPlan:
    """What a replay sends where.

    ``buses`` are distinct (each opened once); ``route[i]`` is the index in
    ``buses`` of frame ``i``; ``channels[b]`` lists the capture channels sent
    on bus ``b`` (``"*"``: every channel no ``--channel-map`` names).
    """

    frames: list[can.Message]
    route: list[int]
    buses: list[BusSpec]
    channels: list[list[str]]

    def describe(self) -> str:
        """``virtual:a (channel 1), udp_multicast:... (other channels)``; one bus: its name only."""
        if len(self.buses) == 1 and self.channels[0] == ["*"]:
            return self.buses[0].describe()
        parts = []
        for spec, chans in zip(self.buses, self.channels, strict=True):
            named = [c for c in chans if c != "*"]
            what = []
            if named:
                what.append(f"channel{'s' if len(named) > 1 else ''} {', '.join(named)}")
            if "*" in chans:
                what.append("unmapped channels")
            parts.append(f"{spec.describe()} ({' and '.join(what)})")
        return ", ".join(parts)


def plan_replay(
    frames: Iterable[can.Message],
    *,
    default: Callable[[], BusSpec],
    channel_map: Sequence[ChannelMap] = (),
    ids: Iterable[int] | None = None,
    exclude_ids: Iterable[int] | None = None,
    channels: Iterable[int] | None = None,
    id_map: dict[int, int] | None = None,
) -> ReplayPlan:
    """Select the frames (:func:`select_frames`) and choose the bus of each.

    Frames of a channel named in ``channel_map`` go to its bus; all others
    to ``default()``, which is called only when such a frame is left after
    the filters.  Every mapped bus is in the plan (even when the filters
    leave it no frame); a bus named twice, or equal to the default, is one bus.

    Raises
    ------
    BenchError
        A ``channel_map`` item that does not fit the capture (:func:`resolve_channel_map`).
    """
    frames = list(frames)
    by_channel = resolve_channel_map(channel_map, frames)
    pairs = _selected(frames, ids=ids, exclude_ids=exclude_ids, channels=channels, id_map=id_map)
    buses: list[BusSpec] = []
    chans: list[list[str]] = []
    index: dict[tuple[str, str, int | None], int] = {}

    def bus_of(spec: BusSpec) -> int:
        key = (spec.interface, spec.channel, spec.port)
        if key not in index:
            index[key] = len(buses)
            buses.append(spec)
            chans.append([])
        return index[key]

    of_map = [bus_of(cm.bus) for cm in channel_map]
    for ch, j in by_channel.items():
        chans[of_map[j]].append(ch)
    default_bus: int | None = None
    route: list[int] = []
    for rec, _ in pairs:
        key = _channel_key(rec.channel)
        j_map = by_channel.get(key, -1) if key is not None else -1
        if j_map >= 0:
            route.append(of_map[j_map])
            continue
        if default_bus is None:
            default_bus = bus_of(default())
            chans[default_bus].append("*")
        route.append(default_bus)
    return ReplayPlan([fresh for _, fresh in pairs], route, buses, chans)


@contextlib.contextmanager
def open_buses(specs: Sequence[BusSpec]) -> Iterator[list[can.BusABC]]:
    """Open every bus of ``specs`` in order; all are shut down on exit or on any error.

    A bus that fails to open shuts down those opened before it, so an error
    leaves nothing open (and python-can logs no "not properly shut down").
    """
    with contextlib.ExitStack() as stack:
        buses: list[can.BusABC] = []
        for spec in specs:
            bus = spec.open()
            stack.callback(bus.shutdown)
            buses.append(bus)
        yield buses


@dataclass(slots=True)
class ReplayResult:
    """What a replay achieved.

    ``error_s[i]`` is the send instant of frame ``i`` (``perf_counter`` just
    before ``bus.send``) minus its deadline, seconds; positive is late.
    """

    sent: int
    loops: int
    clock: str
    speed: float
    span_s: float
    wall_s: float
    error_s: npt.NDArray[np.float64]
    send_failures: int = 0
    skipped_gap_s: float = 0.0
    sent_at: list[float] = field(default_factory=list)
    mean_gap_s: float = 0.0
    bus_names: list[str] = field(default_factory=list)
    sent_per_bus: list[int] = field(default_factory=list)

    @property
    def error_median_us(self) -> float:
        return float(1e6 * np.median(self.error_s)) if len(self.error_s) else math.nan

    @property
    def error_worst_us(self) -> float:
        return float(1e6 * np.max(np.abs(self.error_s))) if len(self.error_s) else math.nan

    @property
    def error_p99_us(self) -> float:
        return (
            float(1e6 * np.percentile(np.abs(self.error_s), 99)) if len(self.error_s) else math.nan
        )

    def lag_limit_s(self) -> float:
        """Lateness above which the replay did not keep up: ``max(1 ms, 10 % of the mean gap)``.

        1 ms is well above what a working replay shows (the OS sleep
        overshoot of ``messagesync`` is 50-100 us, the spinning ``deadline``
        clock a few us, a classic CAN frame at 500 kbit/s takes about
        0.25 ms), so it flags a replay that falls behind, not scheduler
        noise; 10 % of the mean frame gap (after ``speed``) takes over for
        sparse captures, where a frame that late is already out of step with
        its neighbours.
        """
        return max(1e-3, 0.1 * self.mean_gap_s)

    def lag_warning(self) -> str | None:
        """One line when the median or p99 lateness exceeds :meth:`lag_limit_s`, else None."""
        if not len(self.error_s):
            return None
        med = float(np.median(self.error_s))
        p99 = float(np.percentile(self.error_s, 99))
        limit = self.lag_limit_s()
        if med <= limit and p99 <= limit:
            return None
        figures = (
            f"frames late by median {1e3 * med:.3f} ms, p99 {1e3 * p99:.3f} ms "
            f"(limit {1e3 * limit:.3f} ms)"
        )
        if med > limit:
            want = 1.0 / self.mean_gap_s if self.mean_gap_s > 0 else math.inf
            got = self.sent / self.wall_s if self.wall_s > 0 else math.inf
            return (
                f"warning: the replay could not keep up with the capture's timing at "
                f"x{self.speed:g}: {figures}; sent {got:.0f} frames/s where the capture "
                f"needs {want:.0f} frames/s; lower --speed or use a faster interface"
            )
        return (
            f"warning: the replay could not keep the capture's timing for its latest 1 % of "
            f"frames: {figures}; it caught up (absolute deadlines): the machine stalled it "
            "at times" + ("; --clock deadline keeps closer" if self.clock == "messagesync" else "")
        )

    def summary(self) -> str:
        return (
            f"replayed {self.sent} frames ({self.loops} loop{'s' if self.loops != 1 else ''}, "
            f"speed x{self.speed:g}, clock {self.clock}) in {self.wall_s:.3f} s; "
            f"timing error vs capture: median {self.error_median_us:.1f} us, "
            f"p99 {self.error_p99_us:.1f} us, worst {self.error_worst_us:.1f} us"
            + (f"; {self.send_failures} send failures" if self.send_failures else "")
            + self._per_bus()
        )

    def _per_bus(self) -> str:
        if not self.bus_names:
            return ""
        return "; frames per bus: " + ", ".join(
            f"{name} {n}" for name, n in zip(self.bus_names, self.sent_per_bus, strict=True)
        )


def schedule(
    frames: Sequence[can.Message], *, speed: float = 1.0, max_gap_s: float | None = None
) -> tuple[list[float], float]:
    """Offsets of the frames from the first (s, already divided by ``speed``), and gap time cut.

    A silence longer than ``max_gap_s`` (in capture time) is shortened to it.
    """
    if speed <= 0 or not math.isfinite(speed):
        raise BenchError(f"--speed must be > 0, got {speed}")
    offs: list[float] = []
    t_first = frames[0].timestamp if frames else 0.0
    cut = 0.0
    prev = t_first
    for m in frames:
        gap = m.timestamp - prev
        if max_gap_s is not None and gap > max_gap_s:
            cut += gap - max_gap_s
        prev = m.timestamp
        offs.append((m.timestamp - t_first - cut) / speed)
    return offs, cut / speed


def _send(bus: can.BusABC, msg: can.Message) -> bool:
    for attempt in range(3):
        try:
            bus.send(msg)
            return True
        except can.CanOperationError:
            if attempt == 2:
                return False
            time.sleep(0.0005)
    return False


def replay_frames(
    bus: can.BusABC | Sequence[can.BusABC],
    frames: Sequence[can.Message],
    *,
    speed: float = 1.0,
    loops: int = 1,
    clock: str = "deadline",
    max_gap_s: float | None = None,
    spin_s: float = 0.0002,
    stop: Callable[[], bool] = lambda: False,
    route: Sequence[int] | None = None,
    bus_names: Sequence[str] | None = None,
) -> ReplayResult:
    """Send ``frames`` on ``bus`` at their recorded times (absolute deadlines).

    Parameters
    ----------
    bus : can.BusABC or sequence of can.BusABC
        One bus, or several: frame ``i`` goes to ``bus[route[i]]``.  All
        share one absolute time line (the schedule does not depend on the bus).
    speed : float
        Time compression: 2 replays twice as fast.
    loops : int
        Times to send the whole capture; 0 repeats until ``stop()``.  Loop
        ``j`` starts one capture span (plus one median frame gap) after loop
        ``j - 1`` started, on the same absolute time line.
    clock : str
        ``"deadline"`` (sleep, then spin the last ``spin_s``) or
        ``"messagesync"`` (:class:`can.MessageSync`, sleep only).
    max_gap_s : float, optional
        Shorten silences longer than this (capture seconds).
    route : sequence of int, optional
        Index into ``bus`` of each frame (default: all on the first).
    bus_names : sequence of str, optional
        Names of the buses, for :meth:`ReplayResult.summary` (frames per bus).
    """
    buses = [bus] if isinstance(bus, can.BusABC) else list(bus)
    if not buses:
        raise ValueError("replay_frames: no bus")
    route = [0] * len(frames) if route is None else list(route)
    if len(route) != len(frames) or any(not 0 <= r < len(buses) for r in route):
        raise ValueError("replay_frames: route must give a bus index for every frame")
    if bus_names is not None and len(bus_names) != len(buses):
        raise ValueError("replay_frames: bus_names must name every bus")
    target_bus = [buses[r] for r in route]  # one lookup per frame in the send loop
    if clock not in CLOCKS:
        raise BenchError(f"--clock: unknown {clock!r} (known: {', '.join(CLOCKS)})")
    if loops < 0:
        raise BenchError(f"--loop must be >= 0, got {loops}")
    if not frames:
        raise CaptureError("nothing to replay: no frame passed the filters")
    offs, cut = schedule(frames, speed=speed, max_gap_s=max_gap_s)
    gaps = np.diff(np.asarray(offs)) if len(offs) > 1 else np.zeros(1)
    period = offs[-1] + (float(np.median(gaps)) if len(gaps) else 0.0)
    n = len(frames)
    errors: list[float] = []
    sent_at: list[float] = []
    failures = 0
    done_loops = 0
    perf = time.perf_counter
    t0 = perf()
    if clock == "deadline":
        sleep = time.sleep
        j = 0
        while (loops == 0 or j < loops) and not stop():
            base = t0 + j * period
            for i in range(n):
                target = base + offs[i]
                while True:
                    now = perf()
                    rem = target - now
                    if rem <= 0.0:
                        break
                    if rem > spin_s:
                        sleep(rem - spin_s)
                errors.append(now - target)
                sent_at.append(now)
                if not _send(target_bus[i], frames[i]):
                    failures += 1
            j += 1
            done_loops = j
    else:

        def timed() -> Iterable[can.Message]:
            j = 0
            while (loops == 0 or j < loops) and not stop():
                base_ts = frames[0].timestamp
                for i in range(n):
                    yield can.Message(timestamp=base_ts + j * period + offs[i], check=False)
                j += 1

        # MessageSync takes its time origin when its first frame is asked for:
        # the same instant here, not when that frame is handed over (on a busy
        # machine later, which would make every later frame look early)
        i = 0
        sync = iter(can.MessageSync(timed(), timestamps=True, skip=math.inf))
        t_start = perf()
        for stamp in sync:
            now = perf()
            target = t_start + (stamp.timestamp - frames[0].timestamp)
            errors.append(now - target)
            sent_at.append(now)
            if not _send(target_bus[i % n], frames[i % n]):
                failures += 1
            i += 1
        t0 = t_start
        done_loops = i // n
    wall = perf() - t0
    per_loop = [0] * len(buses)
    for r in route:
        per_loop[r] += 1
    full, rest = divmod(len(errors), n)
    per_bus = [full * c for c in per_loop]
    for r in route[:rest]:
        per_bus[r] += 1
    return ReplayResult(
        sent=len(errors),
        loops=done_loops,
        clock=clock,
        speed=speed,
        span_s=offs[-1],
        wall_s=wall,
        error_s=np.asarray(errors, dtype=float),
        send_failures=failures,
        skipped_gap_s=cut,
        sent_at=sent_at,
        mean_gap_s=offs[-1] / (n - 1) if n > 1 else 0.0,
        bus_names=list(bus_names or []),
        sent_per_bus=per_bus,
    )
