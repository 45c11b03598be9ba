"""What the live monitor knows about a bus: pure state, no terminal, no thread.

Two halves, fed from two threads of :mod:`bench.monitor._app` and driven by
hand in the tests:

- :meth:`MonitorModel.on_frame` runs in the bus-reading thread for *every*
  frame. It only looks at the identifier: frames and wire time per message
  (the frame rate and bus load), frames of foreign identifiers, the gaps in
  the plant's frames (stalls, "stopped"), and it queues the frame for the view.
  Nothing there decodes, so the reader keeps up with the bus.
- :meth:`MonitorModel.update` runs in the view's thread a few times a second.
  It decodes the queued frames with the DBC (E2E CRC and range checks of
  :class:`~bench.wire._codec.Codec`): latest values, rolling traces, rejections by
  reason, the plant's state and counters. Frames it cannot decode in time
  (more than ``max_view_frames`` waiting, or the queue full) are dropped from
  the view and counted; the frame rates, loads and stalls still count them.

Time is the receive time of a frame in seconds on the ``time.time()`` clock:
the kernel's receive stamp where the bus gives one (socketcan,
udp_multicast), so a monitor that is descheduled for a while still measures
the plant's gaps right.

Thresholds (:class:`MonitorPars`) and their reasons:

- a *stall* is a pause of the plant's frames longer than ``stall_periods``
  PWM periods and at least ``stall_min_s``, that ends within
  ``stopped_after_s``: the plant's own duty watchdog defaults (10 periods,
  at least 20 ms, :data:`bench.nodes._loops.WATCHDOG_PERIODS`), so a stall is what
  would trip a drive's watchdog, and the floor keeps the scheduling jitter of
  a general-purpose OS (milliseconds) out of the count. The PWM period is
  measured: the mean gap between ``PhaseSamples`` frames (one per period),
  gaps above the threshold left out;
- the bench is *stopped* after ``stopped_after_s`` = 2 s without a bench
  frame: 20 cycles of ``PlantStatus``, the slowest periodic frame of the DBC
  (``GenMsgCycleTime`` 100 ms), so a living plant is never taken for stopped;
- the bus load is the wire time of each received frame on a reference bus
  (:func:`bench.wire._busload.frame_time_us`, worst-case bit stuffing), 1 Mbit/s
  arbitration and 5 Mbit/s data by default (the ``FD 1M/5M`` bus of
  ``bench busload``): vcan and udp_multicast have no bit rate of their own.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field
from threading import Lock
from typing import Any

import can
import numpy as np

from bench.wire._busload import frame_time_us
from bench.wire._codec import Codec

__all__ = [
    "TRACES",
    "MessageRate",
    "MonitorModel",
    "MonitorPars",
    "Numbers",
    "Trace",
    "envelope",
]

RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)
DEG_PER_RAD = 180.0 / math.pi
TWO_PI = 2.0 * math.pi

#: Rolling traces, by name: (plot, legend label, unit).
TRACES: dict[str, tuple[str, str, str]] = {
    "theta_e": ("angle", "true", "deg el."),
    "theta_hat": ("angle", "estimate", "deg el."),
    "theta_err": ("error", "true - estimate", "deg el."),
    "speed_ref": ("speed", "reference", "rpm"),
    "speed": ("speed", "true", "rpm"),
    "speed_hat": ("speed", "estimate", "rpm"),
    "tau_e": ("torque", "electromagnetic", "N m"),
    "tau_L": ("torque", "load", "N m"),
    "i_a": ("currents", "i_a", "A"),
    "i_b": ("currents", "i_b", "A"),
    "i_c": ("currents", "i_c", "A"),
    "duty_a": ("duties", "a", ""),
    "duty_b": ("duties", "b", ""),
    "duty_c": ("duties", "c", ""),
}

_FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)
_FOREIGN_IDS_KEPT = 32  # distinct foreign identifiers listed (all are counted)
_PAIR_KEEP = 4096  # truth/telemetry steps kept for pairing (periods)


@dataclass(frozen=True, slots=True)
class MonitorPars:
    """Settings of the monitor (see the module docstring for the thresholds).

    Parameters
    ----------
    stall_periods : int
        A stall lasts more than this many PWM periods ...
    stall_min_s : float
        ... and more than this (s).
    stopped_after_s : float
        No bench frame for this long: the bench is stopped (s); also the
        longest gap counted as a stall.
    rate_window_s : float
        Frame rates and loads are averaged over about this long (s).
    queue_frames : int
        Frames waiting for the view at most; more are dropped from the view.
    max_view_frames : int or None
        Frames decoded per :meth:`MonitorModel.update` at most (the newest
        are kept); None: as many as ``decode_share`` allows at the measured
        cost per frame.
    decode_share : float
        Share of the time between two updates that decoding may take: 0.2,
        a fifth of a core, so the view stays a light process beside the bench.
    trace_points : int
        Points kept per trace.
    max_window_s : float
        Widest time window of the plots (s); with ``trace_points`` it sets
        the finest spacing kept per trace.
    bitrate, data_bitrate : float, float or None
        Reference bus of the load figures (bit/s); ``data_bitrate`` None: a
        classic bus (CAN FD frames counted as ``ceil(n/8)`` classic frames,
        as in :mod:`bench.wire._busload`).
    n_p : int or None
        Pole pairs of the motor (estimated speed is electrical on the wire);
        None: inferred from estimated over true speed.
    T_s : float or None
        PWM period of the bench (s), for the simulated time; None: unknown.
    n_steps : int or None
        Length of the run in periods, for its progress; None: unknown.
    """

    stall_periods: int = 10
    stall_min_s: float = 0.02
    stopped_after_s: float = 2.0
    rate_window_s: float = 1.0
    queue_frames: int = 100_000
    max_view_frames: int | None = None
    decode_share: float = 0.2
    trace_points: int = 1 << 16
    max_window_s: float = 20.0
    bitrate: float = 1e6
    data_bitrate: float | None = 5e6
    n_p: int | None = None
    T_s: float | None = None
    n_steps: int | None = None

    def bus_name(self) -> str:
        """The reference bus as ``bench busload`` names it (``FD 1M/5M``)."""

        def short(x: float) -> str:
            return f"{x / 1e6:g}M" if x >= 1e6 else f"{x / 1e3:g}k"

        if self.data_bitrate is None:
            return f"classic {short(self.bitrate)}"
        return f"FD {short(self.bitrate)}/{short(self.data_bitrate)}"


class Trace:
    """A rolling trace: the latest ``capacity`` points ``(t, v)``, thinned at ``min_dt``."""

    __slots__ = ("_n", "_t", "_v", "capacity", "last_t", "min_dt")

    def __init__(self, capacity: int, min_dt: float) -> None:
        self.capacity = capacity
        self.min_dt = min_dt
        self._t = np.zeros(capacity)
        self._v = np.zeros(capacity)
        self._n = 0  # points ever appended
        self.last_t = -math.inf

    def append(self, t: float, v: float) -> None:
        if t - self.last_t < self.min_dt:
            return
        i = self._n % self.capacity
        self._t[i] = t
        self._v[i] = v
        self._n += 1
        self.last_t = t

    def __len__(self) -> int:
        return min(self._n, self.capacity)

    def clear(self) -> None:
        self._n = 0
        self.last_t = -math.inf

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """Times and values, oldest first (copies)."""
        n, c = self._n, self.capacity
        if n <= c:
            return self._t[:n].copy(), self._v[:n].copy()
        i = n % c
        return np.concatenate((self._t[i:], self._t[:i])), np.concatenate(
            (self._v[i:], self._v[:i])
        )

    def window(self, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
        """Points with ``t0 <= t <= t1``."""
        t, v = self.arrays()
        a, b = np.searchsorted(t, [t0, t1], side="left"), np.searchsorted(t, t1, side="right")
        return t[a[0] : b], v[a[0] : b]


def envelope(
    t: np.ndarray, v: np.ndarray, t0: float, t1: float, buckets: int
) -> tuple[np.ndarray, np.ndarray]:
    """Min and max of ``v`` in each of ``buckets`` equal time slots of ``[t0, t1]``.

    A scope's peak detection: a trace of many points drawn in a few columns
    keeps its envelope (an injected HF ripple stays visible as a band)
    instead of aliasing. Returns the points in time order, each slot's min
    and max at its centre (one point for a slot of one sample).
    """
    if len(t) == 0 or buckets < 1 or not t1 > t0:
        return np.zeros(0), np.zeros(0)
    if len(t) <= 2 * buckets:
        return t, v
    width = (t1 - t0) / buckets
    idx = np.clip(((t - t0) / width).astype(np.int64), 0, buckets - 1)
    starts = np.concatenate(([0], np.flatnonzero(np.diff(idx)) + 1))
    lo = np.minimum.reduceat(v, starts)
    hi = np.maximum.reduceat(v, starts)
    x = t0 + (idx[starts] + 0.5) * width
    return np.repeat(x, 2), np.column_stack((lo, hi)).ravel()


@dataclass(frozen=True, slots=True)
class MessageRate:
    """Traffic of one message (or of all foreign identifiers) over the rate window.

    Parameters
    ----------
    name : str
        Message name; ``"foreign"`` for identifiers not in the DBC.
    frames : int
        Frames since the statistics were reset.
    rate_hz : float
        Frames per second.
    load : float
        Fraction of the reference bus the message takes.
    """

    name: str
    frames: int
    rate_hz: float
    load: float


@dataclass(frozen=True, slots=True)
class Numbers:
    """Everything the view prints, at one instant.

    Values a frame has not given yet are None. Angles and errors in degrees
    electrical, speeds in rpm mechanical, currents in A, torques in N m.
    ``dropped``: frames the monitor received but did not decode for the
    view; ``missed``: periods whose sample frame never reached the monitor
    (gaps of the step counter: lost on the bus, or from the monitor's own
    socket when it fell behind).
    """

    now: float
    status: str  # "waiting", "foreign", "live", "stalled", "stopped"
    status_line: str
    state: str | None
    fault: str | None
    ctrl_mode: str | None
    step: int | None
    sim_s: float | None
    progress: float | None
    realtime_factor: float | None
    duty_age: int | None
    overruns: int | None
    overruns_rate: float | None
    late_frames: int | None
    late_rate: float | None
    stalls: int
    longest_stall_s: float
    stall_now_s: float
    period_s: float | None
    restarts: int
    speed_ref: float | None
    speed: float | None
    speed_hat: float | None
    n_p: int | None
    n_p_inferred: bool
    theta_e: float | None
    theta_hat: float | None
    theta_err: float | None
    tau_e: float | None
    tau_L: float | None
    i_abc: tuple[float, float, float] | None
    duties: tuple[float, float, float] | None
    enable: int | None
    messages: tuple[MessageRate, ...]
    total_rate_hz: float
    total_load: float
    rejected: dict[str, dict[str, int]]
    foreign_ids: tuple[int, ...]
    dropped: int
    missed: int
    decoded: int
    bus_name: str


@dataclass
class _Tally:
    frames: int = 0
    wire_us: float = 0.0


@dataclass
class _Wire:
    """Counters of the reading thread (guarded by :attr:`MonitorModel.lock`)."""

    tally: dict[str, _Tally] = field(default_factory=dict)
    foreign_ids: dict[int, int] = field(default_factory=dict)
    last_bench_t: float | None = None
    last_foreign_t: float | None = None
    last_plant_t: float | None = None
    last_period_t: float | None = None
    period_s: float | None = None
    stalls: int = 0
    longest_stall_s: float = 0.0
    restarts: int = 0
    dropped: int = 0
    last_raw_step: int | None = None
    missed: int = 0


class MonitorModel:
    """State of the monitor for one DBC (see the module docstring).

    Parameters
    ----------
    codec : Codec
        Codec of the DBC the bus is decoded with.
    pars : MonitorPars, optional
    """

    def __init__(self, codec: Codec, pars: MonitorPars | None = None) -> None:
        self.codec = codec
        self.pars = pars or MonitorPars()
        self.lock = Lock()
        self._names: dict[int, str] = {}
        for name in codec.names:
            m = codec.message(name)
            key = m.frame_id | (1 << 31) if m.is_extended_frame else m.frame_id
            self._names[key] = name
        self._plant = frozenset(
            n for n in codec.names if "Plant" in (codec.message(n).senders or [])
        )
        self._period_name = "PhaseSamples" if "PhaseSamples" in codec.names else None
        # the period message's step counter, read from the raw payload (no decoding)
        self._step_at: tuple[int, int, int] | None = None  # (length, shift, bits)
        if self._period_name is not None:
            msg = codec.message(self._period_name)
            sig = msg.get_signal_by_name("step")
            if sig.byte_order == "little_endian" and not sig.is_signed:
                self._step_at = (msg.length, sig.start, sig.length)
        self._wire_us_cache: dict[tuple[int, bool, bool, bool], float] = {}
        self._choices = {
            (n, s.name): {int(k): str(v) for k, v in s.choices.items()}
            for n in codec.names
            for s in codec.message(n).signals
            if s.choices
        }
        self._m_samples = 1 << codec.step_bits("PhaseSamples") if self._period_name else 0
        self._m_command = (
            1 << codec.step_bits("BenchCommand") if "BenchCommand" in codec.names else 0
        )
        self._queue: deque[tuple[float, can.Message]] = deque()
        self._cost_s = 10e-6  # decode cost per frame (s), measured
        min_dt = self.pars.max_window_s / self.pars.trace_points
        self.traces: dict[str, Trace] = {
            name: Trace(self.pars.trace_points, min_dt) for name in TRACES
        }
        self._reset_view()
        self._wire = _Wire()
        self._rate_marks: deque[tuple[float, dict[str, tuple[int, float]]]] = deque()
        self._t_start: float | None = None
        self._t_update: float | None = None

    # -- the reading thread ------------------------------------------------

    def _wire_us(self, n: int, fd: bool, brs: bool, ext: bool) -> float:
        key = (n, fd, brs, ext)
        us = self._wire_us_cache.get(key)
        if us is None:
            p = self.pars
            if fd and p.data_bitrate is not None:
                n_fd = next((x for x in _FD_LENGTHS if x >= n), 64)
                us = frame_time_us(
                    n_fd,
                    fd=True,
                    bitrate=p.bitrate,
                    data_bitrate=p.data_bitrate if brs else None,
                    extended=ext,
                )
            else:  # classic, or FD on a classic reference bus: split in 8-byte frames
                full, rest = divmod(n, 8)
                us = full * frame_time_us(8, fd=False, bitrate=p.bitrate, extended=ext)
                if rest or not full:
                    us += frame_time_us(rest, fd=False, bitrate=p.bitrate, extended=ext)
            self._wire_us_cache[key] = us
        return us

    def on_frame(self, t: float, msg: can.Message) -> None:
        """Count one received frame and queue it for the view (reading thread)."""
        fid = msg.arbitration_id
        name = self._names.get(fid | (1 << 31) if msg.is_extended_id else fid)
        us = (
            0.0
            if msg.is_error_frame
            else self._wire_us(len(msg.data), msg.is_fd, msg.bitrate_switch, msg.is_extended_id)
        )
        p = self.pars
        with self.lock:
            w = self._wire
            tally = w.tally.get(name or "foreign")
            if tally is None:
                tally = w.tally[name or "foreign"] = _Tally()
            tally.frames += 1
            tally.wire_us += us
            if name is None:
                w.last_foreign_t = t
                if fid in w.foreign_ids or len(w.foreign_ids) < _FOREIGN_IDS_KEPT:
                    w.foreign_ids[fid] = w.foreign_ids.get(fid, 0) + 1
                return
            w.last_bench_t = t
            if name in self._plant:
                last = w.last_plant_t
                if last is not None:
                    gap = t - last
                    limit = max(p.stall_periods * (w.period_s or 0.0), p.stall_min_s)
                    if gap > limit:
                        if gap < p.stopped_after_s:
                            w.stalls += 1
                            w.longest_stall_s = max(w.longest_stall_s, gap)
                        else:
                            w.restarts += 1
                if last is None or t > last:
                    w.last_plant_t = t
                if name == self._period_name:
                    self._count_missed(w, msg.data, t)
                    lp = w.last_period_t
                    if lp is not None:
                        gap = t - lp
                        limit = max(p.stall_periods * (w.period_s or 0.0), p.stall_min_s)
                        if 0.0 <= gap <= limit:
                            # mean gap over about 256 periods
                            w.period_s = (
                                gap
                                if w.period_s is None
                                else w.period_s + (gap - w.period_s) / 256.0
                            )
                    w.last_period_t = t
            if len(self._queue) < p.queue_frames:
                self._queue.append((t, msg))
            else:
                w.dropped += 1

    def _count_missed(self, w: _Wire, data: bytearray, t: float) -> None:
        """Periods whose sample frame never reached the monitor (gaps in the step counter).

        A frame behind the newest (a retransmission) or a repeat counts
        nothing; after a pause of ``stopped_after_s`` the counter starts
        afresh (another run).
        """
        at = self._step_at
        if at is None or len(data) != at[0]:
            return
        bits = at[2]
        raw = (int.from_bytes(data, "little") >> at[1]) & ((1 << bits) - 1)
        last = w.last_raw_step
        lp = w.last_period_t
        if last is None or (lp is not None and t - lp >= self.pars.stopped_after_s):
            w.last_raw_step = raw
            return
        ahead = (raw - last) % (1 << bits)
        if 0 < ahead < 1 << (bits - 1):
            w.missed += ahead - 1
            w.last_raw_step = raw

    # -- the view's thread -------------------------------------------------

    def _reset_view(self) -> None:
        self._restart()
        self.rejected: dict[str, dict[str, int]] = {}
        self.decoded = 0
        self.dropped_view = 0
        self._np_votes: dict[int, int] = {}
        self._status_base: tuple[int, int] | None = None
        self._status_marks: deque[tuple[float, int, int]] = deque()

    def _restart(self) -> None:
        """Forget the run's step bookkeeping (a new run starts its steps from 0)."""
        self.k: int | None = None  # the plant's period, from its newest frame
        self.k_t: float | None = None
        self.k_first: tuple[int, float] | None = None
        self.last: dict[str, dict[str, float]] = {}
        self._last_t: float | None = None
        self._pending: list[tuple[int, float, float]] = []  # (apply step, speed ref, load)
        self.speed_ref: float | None = None
        self.load_ref: float | None = None
        self._truth: dict[int, float] = {}
        self._telemetry: dict[int, float] = {}
        self.theta_err: float | None = None

    def reset(self, now: float) -> None:
        """Zero the statistics (counters, rates, rejections, stalls); traces stay."""
        with self.lock:
            w = self._wire
            for tally in w.tally.values():
                tally.frames, tally.wire_us = 0, 0.0
            w.foreign_ids.clear()
            w.stalls, w.longest_stall_s, w.restarts, w.dropped, w.missed = 0, 0.0, 0, 0, 0
        self.rejected = {}
        self.decoded = 0
        self.dropped_view = 0
        self._rate_marks.clear()
        st = self.last.get("PlantStatus")
        if st is not None:
            self._status_base = (int(st["overruns"]), int(st["late_frames"]))
        self._status_marks.clear()

    def update(self, now: float) -> None:
        """Decode the frames queued since the last update (view's thread)."""
        if self._t_start is None:
            self._t_start = now
        since = min(max(now - self._t_update, 0.05), 1.0) if self._t_update is not None else 0.25
        self._t_update = now
        with self.lock:
            queue, self._queue = self._queue, deque()
        n = len(queue)
        limit = self.pars.max_view_frames
        if limit is None:
            limit = max(100, int(self.pars.decode_share * since / max(self._cost_s, 1e-7)))
        if n > limit:
            self.dropped_view += n - limit
            for _ in range(n - limit):
                queue.popleft()
        t0 = time.perf_counter()
        for t, msg in queue:
            self._decode(t, msg)
        if queue:
            cost = (time.perf_counter() - t0) / len(queue)
            self._cost_s += (cost - self._cost_s) * 0.2
        self._mark_rates(now)

    def _decode(self, t: float, msg: can.Message) -> None:
        d = self.codec.decode(msg)
        if d is None:
            return
        if self._last_t is not None and t - self._last_t >= self.pars.stopped_after_s:
            self._restart()  # the bench was stopped: this is another run
        self._last_t = t
        self.decoded += 1
        if d.reason is not None:
            by = self.rejected.setdefault(d.name, {})
            by[d.reason] = by.get(d.reason, 0) + 1
            return
        s = d.signals
        self.last[d.name] = s
        name = d.name
        tr = self.traces
        if name == "PlantTruth":
            k = int(s["step"])
            self._plant_step(k, t)
            theta = float(s["theta_e"])
            tr["theta_e"].append(t, theta * DEG_PER_RAD)
            tr["speed"].append(t, float(s["w_m"]) * RPM_PER_RAD_S)
            tr["tau_e"].append(t, float(s["tau_e"]))
            tr["tau_L"].append(t, float(s["tau_L"]))
            self._pair(k, t, theta, None)
        elif name == "CtrlTelemetry":
            k = int(s["step"])
            theta_hat = float(s["theta_hat"])
            tr["theta_hat"].append(t, theta_hat * DEG_PER_RAD)
            n_p = self.n_p
            if n_p is not None:
                tr["speed_hat"].append(t, float(s["w_hat"]) / n_p * RPM_PER_RAD_S)
            self._pair(k, t, None, theta_hat)
        elif name == "PhaseSamples":
            if "PlantTruth" not in self.last:  # else the truth's 32-bit step is the clock
                raw = int(s["step"])
                self._plant_step(
                    raw if self.k is None else _unwrap(raw, self.k, self._m_samples), t
                )
            tr["i_a"].append(t, float(s["i_a"]))
            tr["i_b"].append(t, float(s["i_b"]))
            tr["i_c"].append(t, float(s["i_c"]))
        elif name == "PwmDuty":
            tr["duty_a"].append(t, float(s["duty_a"]))
            tr["duty_b"].append(t, float(s["duty_b"]))
            tr["duty_c"].append(t, float(s["duty_c"]))
        elif name == "BenchCommand":
            k0 = self.k if self.k is not None else 0
            apply = _unwrap(int(s["step"]), k0, self._m_command)
            entry = (apply, float(s["speed_ref"]), float(s["load_torque"]))
            if self.k is not None and apply <= self.k:
                self._apply_command(entry, t)
            elif entry not in self._pending:
                self._pending.append(entry)
                self._pending.sort()
        elif name == "PlantStatus":
            self._status_marks.append((t, int(s["overruns"]), int(s["late_frames"])))

    def _plant_step(self, k: int, t: float) -> None:
        if self.k is None or k > self.k:
            self.k, self.k_t = k, t
            if self.k_first is None:
                self.k_first = (k, t)
            while self._pending and self._pending[0][0] <= k:
                self._apply_command(self._pending.pop(0), t)
        if self.speed_ref is not None:
            self.traces["speed_ref"].append(t, self.speed_ref)

    def _apply_command(self, entry: tuple[int, float, float], t: float) -> None:
        _, self.speed_ref, self.load_ref = entry
        self.traces["speed_ref"].append(t, self.speed_ref)

    def _pair(self, k: int, t: float, theta: float | None, theta_hat: float | None) -> None:
        """Position error of period ``k`` once its truth and estimate have both come."""
        if theta is not None:
            other = self._telemetry.pop(k, None)
            if other is None:
                _keep(self._truth, k, theta)
                return
            theta_hat = other
        else:
            other = self._truth.pop(k, None)
            if other is None:
                assert theta_hat is not None
                _keep(self._telemetry, k, theta_hat)
                return
            theta = other
        assert theta is not None and theta_hat is not None
        err = (theta - theta_hat + math.pi) % TWO_PI - math.pi
        self.theta_err = err * DEG_PER_RAD
        self.traces["theta_err"].append(t, self.theta_err)
        if self.pars.n_p is None:
            truth, tele = self.last.get("PlantTruth"), self.last.get("CtrlTelemetry")
            if truth is not None and tele is not None and abs(float(truth["w_m"])) > 1.0:
                ratio = float(tele["w_hat"]) / float(truth["w_m"])
                vote = round(ratio)
                if 1 <= vote <= 64 and abs(ratio - vote) < 0.1 * vote:
                    self._np_votes[vote] = self._np_votes.get(vote, 0) + 1

    @property
    def n_p(self) -> int | None:
        """Pole pairs: given, or inferred once 50 periods agree on one ratio."""
        if self.pars.n_p is not None:
            return self.pars.n_p
        if not self._np_votes:
            return None
        best = max(self._np_votes, key=lambda v: self._np_votes[v])
        return best if self._np_votes[best] >= 50 else None

    def _mark_rates(self, now: float) -> None:
        with self.lock:
            marks = {k: (v.frames, v.wire_us) for k, v in self._wire.tally.items()}
        self._rate_marks.append((now, marks))
        window = self.pars.rate_window_s
        while len(self._rate_marks) > 2 and now - self._rate_marks[1][0] >= window:
            self._rate_marks.popleft()
        while (
            self._status_marks
            and len(self._status_marks) > 1
            and (self._status_marks[-1][0] - self._status_marks[1][0] >= window)
        ):
            self._status_marks.popleft()

    def _rates(self) -> tuple[tuple[MessageRate, ...], float, float]:
        if not self._rate_marks:
            return (), 0.0, 0.0
        t1, now_marks = self._rate_marks[-1]
        t0, old_marks = self._rate_marks[0]
        dt = t1 - t0
        out = []
        total_rate = total_load = 0.0
        order = [n for n in self.codec.names if n in now_marks]
        if "foreign" in now_marks:
            order.append("foreign")
        for name in order:
            frames, us = now_marks[name]
            f0, us0 = old_marks.get(name, (0, 0.0))
            if frames < f0:  # reset in between
                f0, us0 = 0, 0.0
            rate = (frames - f0) / dt if dt > 0 else 0.0
            load = (us - us0) * 1e-6 / dt if dt > 0 else 0.0
            out.append(MessageRate(name, frames, rate, load))
            total_rate += rate
            total_load += load
        return tuple(out), total_rate, total_load

    def _status_rates(self) -> tuple[float | None, float | None]:
        m = self._status_marks
        if len(m) < 2 or not m[-1][0] > m[0][0]:
            return None, None
        dt = m[-1][0] - m[0][0]
        return max(0, m[-1][1] - m[0][1]) / dt, max(0, m[-1][2] - m[0][2]) / dt

    def numbers(self, now: float) -> Numbers:
        """What the view shows at time ``now`` (view's thread)."""
        p = self.pars
        if self._t_start is None:
            self._t_start = now
        with self.lock:
            w = self._wire
            last_bench_t = w.last_bench_t
            last_foreign_t, last_plant_t = w.last_foreign_t, w.last_plant_t
            stalls, longest, restarts = w.stalls, w.longest_stall_s, w.restarts
            period_s = w.period_s
            foreign_ids = tuple(sorted(w.foreign_ids))
            n_foreign = w.tally["foreign"].frames if "foreign" in w.tally else 0
            dropped = w.dropped + self.dropped_view
            missed = w.missed
        messages, total_rate, total_load = self._rates()
        stall_limit = max(p.stall_periods * (period_s or 0.0), p.stall_min_s)
        gap_plant = now - last_plant_t if last_plant_t is not None else 0.0
        stall_now = gap_plant if stall_limit < gap_plant < p.stopped_after_s else 0.0
        foreign_now = last_foreign_t is not None and now - last_foreign_t < p.stopped_after_s
        ids = ", ".join(f"0x{i:X}" for i in foreign_ids[:6]) + (
            ", ..." if len(foreign_ids) > 6 else ""
        )
        if last_bench_t is None:
            if foreign_now or n_foreign:
                status = "foreign"
                line = (
                    f"no bench frames on the bus: only foreign IDs ({ids}; {n_foreign} frames), "
                    "none of the DBC's messages"
                )
            else:
                status = "waiting"
                line = (
                    f"no bench frames on the bus: nothing received for {now - self._t_start:.0f} s"
                )
        elif now - last_bench_t >= p.stopped_after_s:
            status = "stopped"
            line = f"stopped: no bench frames for {now - last_bench_t:.1f} s"
            st = self.last.get("PlantStatus")
            if st is not None:
                line += f" (plant last {self._choice('PlantStatus', 'state', st['state'])})"
            if foreign_now:
                line += f"; the bus carries only foreign IDs now ({ids})"
        elif stall_now:
            status = "stalled"
            line = f"stalled: no plant frame for {1e3 * stall_now:.0f} ms"
        else:
            status = "live"
            line = f"live: {total_rate:,.0f} frames/s, {100 * total_load:.1f} % of {p.bus_name()}"
        st = self.last.get("PlantStatus")
        samples = self.last.get("PhaseSamples")
        state = fault = None
        overruns = late = None
        if st is not None:
            state = self._choice("PlantStatus", "state", st["state"])
            fault = self._choice("PlantStatus", "fault_code", st["fault_code"])
            base = self._status_base or (0, 0)
            overruns = max(0, int(st["overruns"]) - base[0])
            late = max(0, int(st["late_frames"]) - base[1])
        elif samples is not None:
            state = self._choice("PhaseSamples", "status", samples["status"])
        overruns_rate, late_rate = self._status_rates()
        truth = self.last.get("PlantTruth")
        tele = self.last.get("CtrlTelemetry")
        duty = self.last.get("PwmDuty")
        n_p = self.n_p
        sim_s = self.k * p.T_s if (self.k is not None and p.T_s) else None
        rtf = None
        if p.T_s and self.k_first is not None and self.k is not None and self.k_t is not None:
            k0, t0 = self.k_first
            if self.k_t - t0 > 0.5:
                rtf = (self.k - k0) * p.T_s / (self.k_t - t0)
        progress = min(1.0, self.k / p.n_steps) if (self.k is not None and p.n_steps) else None
        return Numbers(
            now=now,
            status=status,
            status_line=line,
            state=state,
            fault=fault,
            ctrl_mode=self._choice("CtrlTelemetry", "mode", tele["mode"]) if tele else None,
            step=self.k,
            sim_s=sim_s,
            progress=progress,
            realtime_factor=rtf,
            duty_age=int(truth["duty_age"]) if truth else None,
            overruns=overruns,
            overruns_rate=overruns_rate,
            late_frames=late,
            late_rate=late_rate,
            stalls=stalls,
            longest_stall_s=longest,
            stall_now_s=stall_now,
            period_s=period_s,
            restarts=restarts,
            speed_ref=self.speed_ref,
            speed=float(truth["w_m"]) * RPM_PER_RAD_S if truth else None,
            speed_hat=float(tele["w_hat"]) / n_p * RPM_PER_RAD_S if (tele and n_p) else None,
            n_p=n_p,
            n_p_inferred=p.n_p is None and n_p is not None,
            theta_e=float(truth["theta_e"]) * DEG_PER_RAD if truth else None,
            theta_hat=float(tele["theta_hat"]) * DEG_PER_RAD if tele else None,
            theta_err=self.theta_err,
            tau_e=float(truth["tau_e"]) if truth else None,
            tau_L=float(truth["tau_L"]) if truth else None,
            i_abc=(float(samples["i_a"]), float(samples["i_b"]), float(samples["i_c"]))
            if samples
            else None,
            duties=(float(duty["duty_a"]), float(duty["duty_b"]), float(duty["duty_c"]))
            if duty
            else None,
            enable=int(duty["enable"]) if duty else None,
            messages=messages,
            total_rate_hz=total_rate,
            total_load=total_load,
            rejected={k: dict(v) for k, v in self.rejected.items()},
            foreign_ids=foreign_ids,
            dropped=dropped,
            missed=missed,
            decoded=self.decoded,
            bus_name=p.bus_name(),
        )

    def _choice(self, message: str, signal: str, value: Any) -> str:
        v = int(value)
        return self._choices.get((message, signal), {}).get(v, str(v))


def _unwrap(raw: int, expected: int, modulus: int) -> int:
    diff = (raw - expected) % modulus
    if diff >= modulus >> 1:
        diff -= modulus
    return expected + diff


def _keep(d: dict[int, float], k: int, v: float) -> None:
    d[k] = v
    if len(d) > _PAIR_KEEP:
        del d[next(iter(d))]
