"""Captures: read any python-can log, analyse it as a live run would, replay it onto a bus.

``bench analyze LOG`` reads the capture with python-can's own readers
(``.blf``, ``.asc``, ``.log``, ``.trc``, ``.csv``, ``.mf4`` with its optional
dependency), decodes it with the DBC and writes the same ``signals.csv``,
``metrics.json`` and plots a live run writes.  The scenario (for the PWM
period, the scoring window and the paper's numbers) comes from the
``meta.json`` beside the capture, or from ``--scenario`` for a capture made
elsewhere.

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
import io
import ipaddress
import json
import math
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import can
import numpy as np
import numpy.typing as npt

from bench._errors import BenchError, CaptureError, ScenarioError
from bench.runs._results import RunResult, finish_run
from bench.scenarios._schema import Scenario, load_scenario, scenario_from_dict
from bench.wire._bus import BusSpec
from bench.wire._codec import Codec

__all__ = [
    "CAPTURE_SUFFIXES",
    "CLOCKS",
    "ChannelMap",
    "ReplayPlan",
    "ReplayResult",
    "analyze_capture",
    "capture_scenario",
    "channel_tag",
    "incomplete_warning",
    "open_buses",
    "parse_channel_map",
    "parse_id_map",
    "plan_replay",
    "read_capture",
    "replay_frames",
    "resolve_channel_map",
    "scoring_scenario",
    "select_frames",
]

#: Suffixes python-can reads (``.mf4`` needs ``asammdf``), in the order a folder is searched.
CAPTURE_SUFFIXES = (".blf", ".asc", ".log", ".trc", ".csv", ".mf4")

#: Replay clocks: own absolute-deadline loop, or python-can's ``MessageSync``.
CLOCKS = ("deadline", "messagesync")


def _find_in_folder(path: Path) -> Path:
    """The capture of a run folder: the one its ``meta.json`` names, else the first ``capture.*``.

    A folder reused by runs in different formats may hold an older
    ``capture.*`` beside the latest run's; ``meta.json`` (rewritten by every
    run) names the latest one in ``capture``.
    """
    try:
        named = json.loads((path / "meta.json").read_text()).get("capture")
    except (OSError, ValueError, AttributeError):
        named = None
    if isinstance(named, str) and named:
        cand = path / Path(named).name
        if cand.is_file():
            return cand
    for suffix in CAPTURE_SUFFIXES:
        cand = path / f"capture{suffix}"
        if cand.is_file():
            return cand
    raise CaptureError(f"{path}: a folder without capture.* ({', '.join(CAPTURE_SUFFIXES)})")


#: Text formats python-can reads line by line (a cut last line is dropped, not parsed).
_TEXT_READERS: dict[str, type[can.io.generic.TextIOMessageReader]] = {
    ".asc": can.ASCReader,
    ".log": can.CanutilsLogReader,
    ".trc": can.TRCReader,
    ".csv": can.CSVReader,
}


def _blf_header(path: Path) -> tuple[int, int]:
    """File size and object count a BLF header declares (both 0 for an unfinished file).

    Raises
    ------
    CaptureError
        The file is too short for a BLF header or lacks its ``LOGG`` signature.
    """
    from can.io.blf import FILE_HEADER_STRUCT

    with path.open("rb") as f:
        data = f.read(FILE_HEADER_STRUCT.size)
    if len(data) < FILE_HEADER_STRUCT.size:
        raise CaptureError(
            f"{path}: not a readable BLF capture ({len(data)} bytes, "
            f"shorter than the {FILE_HEADER_STRUCT.size}-byte BLF file header)"
        )
    header = FILE_HEADER_STRUCT.unpack(data)
    if header[0] != b"LOGG":
        raise CaptureError(f"{path}: not a readable BLF capture (no 'LOGG' signature at its start)")
    return int(header[10]), int(header[12])


def _blf_problem(path: Path, declared: tuple[int, int], n_read: int) -> str | None:
    """Why a BLF looks incomplete: its size or object count against its header."""
    from can.io.blf import FILE_HEADER_SIZE

    size_decl, count = declared
    size = path.stat().st_size
    if count == 0 and size_decl <= FILE_HEADER_SIZE and size > FILE_HEADER_SIZE:
        return (
            "the BLF header was never completed (its writer did not close the file), "
            "so the capture may end early"
        )
    if size < size_decl:
        return (
            f"truncated BLF: {size} of the {size_decl} bytes its header declares "
            f"({n_read} of its {count} frames read)"
        )
    if n_read < count:
        return (
            f"{n_read} of the {count} objects the BLF header counts were read "
            "(a damaged file, or object types python-can does not read)"
        )
    return None


def _text_tail(path: Path) -> tuple[int | None, bool]:
    """Where the last complete line of a text capture ends (None: the file ends with
    one), and whether an ASC file's ``End TriggerBlock`` footer is missing."""
    size = path.stat().st_size
    with path.open("rb") as f:
        f.seek(max(0, size - 4096))
        tail = f.read()
    no_footer = path.suffix.lower() == ".asc" and b"end triggerblock" not in tail.lower()
    if not tail or tail.endswith((b"\n", b"\r")):
        return None, no_footer
    nl = max(tail.rfind(b"\n"), tail.rfind(b"\r"))
    if nl < 0 and size > len(tail):  # a last line longer than 4 kB: find its start
        data = path.read_bytes()
        nl = max(data.rfind(b"\n"), data.rfind(b"\r"))
        return nl + 1, no_footer
    return size - len(tail) + nl + 1, no_footer


def _open_reader(path: Path, cut_at: int | None) -> Iterable[can.Message]:
    """python-can's reader of ``path``; only its first ``cut_at`` bytes when given."""
    if cut_at is None:
        return can.LogReader(str(path))
    data = path.read_bytes()[:cut_at]
    text = io.TextIOWrapper(io.BytesIO(data), encoding="utf-8", errors="replace")
    return _TEXT_READERS[path.suffix.lower()](text)


def read_capture(path: Path) -> tuple[list[can.Message], str | None]:
    """All frames python-can can read from ``path``, and why the capture is incomplete (or None).

    ``path`` may also be a run folder (its ``capture.*`` is read).  A reader
    that stops on a corrupt object keeps what it read; python-can's readers
    stop silently at a truncated end, so the capture is also checked against
    what its format promises: a BLF's size and object count against its
    header, a text capture's last line (a line cut short is dropped, never
    parsed into a frame with missing bytes) and an ASC's ``End TriggerBlock``.

    Raises
    ------
    CaptureError
        Missing file, a format python-can does not read (or a file that is
        not what its suffix says), a missing optional reader, or no frame.
    """
    if path.is_dir():
        path = _find_in_folder(path)
    if not path.is_file():
        raise CaptureError(f"{path}: no such capture file")
    suffix = path.suffix.lower()
    problems: list[str] = []
    blf = _blf_header(path) if suffix == ".blf" else None
    cut_at: int | None = None
    if suffix in _TEXT_READERS:
        cut_at, no_footer = _text_tail(path)
        if cut_at is not None:
            problems.append("its last line is cut short (no line end); that line was dropped")
        if no_footer:
            problems.append("no 'End TriggerBlock' line at its end (the file was cut short)")
    try:
        reader = _open_reader(path, cut_at)
    except ValueError as e:
        raise CaptureError(f"{path}: not a capture python-can can read ({e})") from None
    except ImportError as e:
        raise CaptureError(
            f"{path}: reading {path.suffix} needs an optional package ({e.name or e}); "
            "for .mf4: pip install asammdf"
        ) from None
    except Exception as e:  # a reader that fails on the header
        raise CaptureError(f"{path}: unreadable capture: {type(e).__name__}: {e}") from None
    frames: list[can.Message] = []
    read_error: str | None = None
    try:
        for msg in reader:
            frames.append(msg)
    except Exception as e:  # truncated or corrupt tail: keep what was read
        read_error = f"{type(e).__name__}: {e}"
        problems.insert(0, f"reading stopped at a corrupt record ({read_error})")
    finally:
        try:
            reader.stop()  # type: ignore[attr-defined]
        except Exception:
            pass
    if blf is not None:
        why = _blf_problem(path, blf, len(frames))
        if why:
            problems.append(why)
    if not frames:
        kind = "not a readable BLF capture: " if blf is not None else ""
        raise CaptureError(
            f"{path}: {kind}no frames could be read" + (f" ({read_error})" if read_error else "")
        )
    problem = "; ".join(problems) if problems else None
    return frames, problem


def scenario_from_meta(meta: dict[str, Any]) -> Scenario:
    d = dict(meta["scenario"])
    return scenario_from_dict(d, str(d.get("source", "meta.json")))


def capture_scenario(path: Path, scenario: str | None) -> tuple[Scenario, dict[str, Any]]:
    """The scenario of a capture and the run metadata beside it (empty when none).

    ``scenario`` (a name or TOML path) wins over the ``meta.json`` beside the
    capture; without either, the PWM rate and the motor are unknown.
    """
    folder = path if path.is_dir() else path.parent
    meta_path = folder / "meta.json"
    meta: dict[str, Any] = {}
    if meta_path.is_file():
        try:
            meta = json.loads(meta_path.read_text())
        except (OSError, ValueError) as e:
            raise CaptureError(f"{meta_path}: unreadable run metadata ({e})") from None
    if scenario is not None:
        return load_scenario(scenario), meta
    if meta:
        if not isinstance(meta.get("scenario"), dict):
            raise CaptureError(
                f"{meta_path}: no scenario in this metadata; "
                "give --scenario NAME_OR_FILE for the capture's PWM rate and motor"
            )
        try:
            return scenario_from_meta(meta), meta
        except (KeyError, TypeError) as e:
            raise CaptureError(f"{meta_path}: no usable scenario in the metadata ({e})") from None
    raise ScenarioError(
        f"{path}: no meta.json beside the capture; give --scenario NAME_OR_FILE for its PWM rate and motor"
    )


def _summarize(
    frames: Sequence[can.Message], codec: Codec, problem: str | None
) -> tuple[str, tuple[int, int] | None]:
    """One line on the capture's counters, and its first and last step (None: no step)."""
    from bench.runs._analysis import analyze_frames

    try:
        cap = analyze_frames(frames, codec, T_s=1.0, n_p=1)
    except ValueError:
        return f"capture: {len(frames)} frames, no complete step", None
    rej = ", ".join(f"{k} {v}" for k, v in sorted(cap.rejected.items()))
    s = (
        f"capture: {cap.frames} frames, {cap.unknown_ids} with IDs not in the DBC, "
        f"{cap.frames_rejected} rejected{f' ({rej})' if rej else ''}, "
        f"{cap.duplicates} duplicates, {cap.out_of_order} out of order, "
        f"{cap.incomplete_steps} incomplete steps, first step {cap.first_step}"
    )
    if problem:
        s += "; incomplete capture (see the warning)"
    steps = cap.table["step"]
    span = (int(steps[0]), int(steps[-1])) if len(steps) else None
    return s, span


def capture_summary(frames: Sequence[can.Message], codec: Codec, problem: str | None) -> str:
    """One line on what a capture holds besides the run: other IDs, rejections, order."""
    return _summarize(frames, codec, problem)[0]


def incomplete_warning(path: Path, problem: str, n_frames: int) -> str:
    """The one-line warning about an incomplete capture (what was kept)."""
    return f"warning: {path}: incomplete capture: {problem}; using the {n_frames} frames read"


def scoring_scenario(scn: Scenario, t_first: float, t_end: float) -> tuple[Scenario, str | None]:
    """The scenario to score a capture spanning ``t_first`` .. ``t_end`` (s) with, and what changed.

    A live run shorter than its scenario's scoring start is scored over its
    second half (:meth:`Scenario.with_overrides` with its ``duration``).  A
    capture whose span ends at or before ``score_from_s`` is scored the same
    way, from the middle of its span, with the scenario's duration set to the
    span's end, so that a capture of a shortened run scores as the live run
    did and the ``meta.json`` written with it scores the same again.
    """
    if scn.score_from_s < t_end:
        return scn, None
    t_end = round(t_end, 9)
    start = round(t_first + (t_end - t_first) / 2, 9)
    out = scn.with_overrides(duration=max(t_end, 1e-3), score_from_s=start)
    return out, (
        f"capture ends at {t_end:g} s, not after the scenario's scoring start "
        f"({scn.score_from_s:g} s): scoring its second half, from {start:g} s "
        "(as a run of that duration is scored)"
    )


def analyze_capture(
    path: Path,
    *,
    out_dir: Path | None = None,
    scenario: str | None = None,
    codec: Codec | None = None,
    echo: Callable[[str], None] | None = None,
    plots: bool = True,
) -> RunResult:
    """Decode a capture into the files of a run.

    Parameters
    ----------
    path : Path
        Capture file (any python-can format) or run folder.
    out_dir : Path, optional
        Where to write; default beside the capture.
    scenario : str, optional
        Scenario name or file; default from ``meta.json`` beside the capture.
    echo : callable, optional
        Receives the one-line summary of the capture's counters and any
        warning line (default: stderr).
    plots : bool
        Draw ``run.png``.

    The ``meta.json`` written carries the scenario used (as a live run's
    does), so a later ``bench analyze`` or ``bench rerun`` of the same folder
    needs no ``--scenario``.  An incomplete capture (see
    :func:`read_capture`) is analysed as far as it was read, with a warning
    and ``capture_truncated``/``capture_read_error`` in ``metrics.json``.
    """
    from bench.scenarios._setup import sample_period

    codec = codec or Codec()
    frames, problem = read_capture(path)
    capture = path if path.is_file() else _find_in_folder(path)
    scn, meta = capture_scenario(path, scenario)
    say = echo or (lambda s: print(s, file=sys.stderr))
    line, span = _summarize(frames, codec, problem)
    say(line)
    if problem:
        say(incomplete_warning(capture, problem, len(frames)))
    if span is not None:
        T_s = sample_period(scn)
        scn, moved = scoring_scenario(scn, span[0] * T_s, span[1] * T_s)
        if moved:
            say(moved)
    out = out_dir or capture.parent
    out.mkdir(parents=True, exist_ok=True)
    meta = dict(meta, analyzed_from=str(capture), scenario=scn.to_dict())
    meta.pop("capture_read_error", None)
    if problem:
        meta["capture_read_error"] = problem
    wall_s = float(meta.get("wall_s", 0.0))
    try:
        res = finish_run(
            frames, codec, scn, out, meta=meta, wall_s=wall_s, capture=capture, plots=plots
        )
    except ValueError as e:
        raise CaptureError(f"{capture}: {e}") from None
    if problem:
        res.metrics["capture_truncated"] = True
        res.metrics["capture_read_error"] = problem
        (out / "metrics.json").write_text(json.dumps(res.metrics, indent=2, sort_keys=True) + "\n")
    return res


# -- replay ----------------------------------------------------------------------------


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

        t_start = perf()
        i = 0
        for stamp in can.MessageSync(timed(), timestamps=True, skip=math.inf):
            now = perf()
            if i == 0:
                t_start = now
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
