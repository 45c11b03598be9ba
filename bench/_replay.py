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
for every frame and reported as median and worst.

Bench captures tag each frame with the bus it was recorded on: channel 1 is
the plant-side bus, 2 the controller-side bus (only with a latency link).
python-can's ``.log`` writer turns these into ``can1``/``can2``; both forms
are understood.
"""

from __future__ import annotations

import json
import math
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import can
import numpy as np
import numpy.typing as npt

from bench._codec import Codec
from bench._errors import BenchError, CaptureError, ScenarioError
from bench._run import RunResult, finish_run
from bench._scenario import Scenario, load_scenario, scenario_from_dict

__all__ = [
    "CAPTURE_SUFFIXES",
    "CLOCKS",
    "ReplayResult",
    "analyze_capture",
    "capture_scenario",
    "channel_tag",
    "parse_id_map",
    "read_capture",
    "replay_frames",
    "select_frames",
]

#: Suffixes python-can reads (``.mf4`` needs ``asammdf``), in the order a folder is searched.
CAPTURE_SUFFIXES = (".blf", ".asc", ".log", ".trc", ".csv", ".mf4")

#: Replay clocks: own absolute-deadline loop, or python-can's ``MessageSync``.
CLOCKS = ("deadline", "messagesync")


def _find_in_folder(path: Path) -> Path:
    for suffix in CAPTURE_SUFFIXES:
        cand = path / f"capture{suffix}"
        if cand.is_file():
            return cand
    raise CaptureError(f"{path}: a folder without capture.* ({', '.join(CAPTURE_SUFFIXES)})")


def read_capture(path: Path) -> tuple[list[can.Message], str | None]:
    """All frames python-can can read from ``path``, and why reading stopped early (or None).

    ``path`` may also be a run folder (its ``capture.*`` is read).

    Raises
    ------
    CaptureError
        Missing file, a format python-can does not read, a missing optional
        reader, or no frame at all.
    """
    if path.is_dir():
        path = _find_in_folder(path)
    if not path.is_file():
        raise CaptureError(f"{path}: no such capture file")
    try:
        reader = can.LogReader(str(path))
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
    problem: str | None = None
    try:
        for msg in reader:
            frames.append(msg)
    except Exception as e:  # truncated or corrupt tail: keep what was read
        problem = f"{type(e).__name__}: {e}"
    finally:
        try:
            reader.stop()
        except Exception:
            pass
    if not frames:
        raise CaptureError(
            f"{path}: no frames could be read" + (f" ({problem})" if problem else "")
        )
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
        try:
            return scenario_from_meta(meta), meta
        except (KeyError, TypeError) as e:
            raise CaptureError(f"{meta_path}: no usable scenario in the metadata ({e})") from None
    raise ScenarioError(
        f"{path}: no meta.json beside the capture; give --scenario NAME_OR_FILE for its PWM rate and motor"
    )


def capture_summary(frames: Sequence[can.Message], codec: Codec, problem: str | None) -> str:
    """One line on what a capture holds besides the run: other IDs, rejections, order."""
    from bench._analysis import analyze_frames

    try:
        cap = analyze_frames(frames, codec, T_s=1.0, n_p=1)
    except ValueError:
        return f"capture: {len(frames)} frames, no complete step"
    rej = ", ".join(f"{k} {v}" for k, v in sorted(cap.rejected.items()))
    s = (
        f"capture: {cap.frames} frames, {cap.unknown_ids} with IDs not in the DBC, "
        f"{cap.frames_rejected} rejected{f' ({rej})' if rej else ''}, "
        f"{cap.duplicates} duplicates, {cap.out_of_order} out of order, "
        f"{cap.incomplete_steps} incomplete steps, first step {cap.first_step}"
    )
    if problem:
        s += f"; reading stopped early: {problem}"
    return s


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
        Receives a one-line summary of the capture's counters (default: stderr).
    plots : bool
        Draw ``run.png``.
    """
    codec = codec or Codec()
    frames, problem = read_capture(path)
    capture = path if path.is_file() else _find_in_folder(path)
    scn, meta = capture_scenario(path, scenario)
    say = echo or (lambda s: print(s, file=sys.stderr))
    say(capture_summary(frames, codec, problem))
    out = out_dir or capture.parent
    out.mkdir(parents=True, exist_ok=True)
    meta = dict(meta, analyzed_from=str(capture))
    if problem:
        meta["capture_read_error"] = problem
    wall_s = float(meta.get("wall_s", 0.0))
    try:
        return finish_run(
            frames, codec, scn, out, meta=meta, wall_s=wall_s, capture=capture, plots=plots
        )
    except ValueError as e:
        if "score_from_s" not in str(e):
            raise CaptureError(f"{capture}: {e}") from None
    # a capture that ends before the scenario's scoring window: score all of it, say so
    say(
        f"capture ends before {scn.score_from_s} s (the scenario's scoring start): scoring all steps"
    )
    meta["scoring_window_moved"] = f"capture ends before score_from_s = {scn.score_from_s} s"
    try:
        return finish_run(
            frames,
            codec,
            scn.with_overrides(score_from_s=0.0),
            out,
            meta=meta,
            wall_s=wall_s,
            capture=capture,
            plots=plots,
        )
    except ValueError as e:
        raise CaptureError(f"{capture}: {e}") from None


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


def parse_id(text: str) -> int:
    """A CAN identifier from ``0x210``, ``210h`` or decimal ``528``."""
    t = text.strip().lower()
    try:
        if t.startswith("0x"):
            v = int(t, 16)
        elif t.endswith("h"):
            v = int(t[:-1], 16)
        else:
            v = int(t, 10)
    except ValueError:
        raise BenchError(f"not a CAN identifier: {text!r} (use 0x210 or 528)") from None
    if not 0 <= v < (1 << 29):
        raise BenchError(f"CAN identifier out of range: {text!r}")
    return v


def parse_id_map(items: Iterable[str]) -> dict[int, int]:
    """``["0x10=0x210", ...]`` to ``{0x10: 0x210, ...}``."""
    out: dict[int, int] = {}
    for item in items:
        old, sep, new = item.partition("=")
        if not sep:
            raise BenchError(f"--map: expected OLD=NEW (e.g. 0x10=0x210), got {item!r}")
        out[parse_id(old)] = parse_id(new)
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
    keep = None if ids is None else frozenset(ids)
    drop = frozenset(exclude_ids or ())
    chans = None if channels is None else frozenset(channels)
    remap = id_map or {}
    out: list[can.Message] = []
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
        out.append(
            can.Message(
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
        )
    out.sort(key=lambda m: m.timestamp)  # stable: equal stamps keep their order
    return out


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

    def summary(self) -> str:
        return (
            f"replayed {self.sent} frames ({self.loops} loop{'s' if self.loops != 1 else ''}, "
            f"speed x{self.speed:g}, clock {self.clock}) in {self.wall_s:.3f} s; "
            f"timing error vs capture: median {self.error_median_us:.1f} us, "
            f"p99 {self.error_p99_us:.1f} us, worst {self.error_worst_us:.1f} us"
            + (f"; {self.send_failures} send failures" if self.send_failures else "")
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
    bus: can.BusABC,
    frames: Sequence[can.Message],
    *,
    speed: float = 1.0,
    loops: int = 1,
    clock: str = "deadline",
    max_gap_s: float | None = None,
    spin_s: float = 0.0002,
    stop: Callable[[], bool] = lambda: False,
) -> ReplayResult:
    """Send ``frames`` on ``bus`` at their recorded times (absolute deadlines).

    Parameters
    ----------
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
    """
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
                if not _send(bus, frames[i]):
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
            if not _send(bus, frames[i % n]):
                failures += 1
            i += 1
        t0 = t_start
        done_loops = i // n
    wall = perf() - t0
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
    )
