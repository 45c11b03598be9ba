"""The in-process native pair: :func:`bench.nodes._loops.run_inprocess` with its loop in C.

The plant node and the controller node are built by Python as for the Python
loop (the same plant core and controller core, by address); :func:`run_pair`
hands the loop to ``bn_pair_run`` (``bn_pair.h``), which steps both units for
many periods per call with the frames passed in memory and no Python per
period.  It returns only to take the recorded frames when their buffer is full,
and at the end.

The bench commands are known before the run, and so is the plant step at which
the Python loop feeds each (:func:`bench.nodes._counters.feed_steps`:
:data:`~bench.nodes._loops.INPROCESS_LEAD` periods ahead of its apply step).  :func:`_schedule` runs the nodes' own rules on each
(:meth:`PlantNode.on_message`, :meth:`ControllerNode.on_message`: the
:class:`~bench.nodes._counters.CommandQueue` of each) once, before the run, with
each node's clock and applied step set to what they are at that feed, and hands
C the outcome: the frame, what each queue made of it, the acknowledgement after
it.  C records the frame at its feed and puts the commands into both units'
pending lists, which apply them at their step (``bn_plant_apply_commands``,
``bn_ctl_apply_commands``).  The outcome is the Python loop's because
``CommandQueue.add`` reads nothing the run changes between the feeds but the
clock and the applied step; a command the run never feeds (it ended first:
its last step, or a stop command applied) is left out.  The frames it returns are those of the
Python loop, bit for bit and in the same order (``tests/test_native_pair.py``), as
one :class:`~bench.wire._frames.FrameArray`: the record buffer's rows, with no
:class:`can.Message` made unless a consumer asks for one.

:func:`pair_unavailable` says why a pair cannot run native (one line), or None:
the plant node's and the controller node's own reasons (``[[faults]]``, noise,
load profiles, the Python plant engine, a controller outside the compiled
core...), and the lockstep latency model, which stays Python's.
"""

from __future__ import annotations

import ctypes
import itertools
import time
from typing import Any

import can
import numpy as np
import numpy.typing as npt

from bench._errors import BenchError
from bench.nodes.native._native import BN_BRS, BN_EXT, BN_FD, Frame
from bench.wire._frames import FRAME_DTYPE, FrameArray
from bench.wire._protocol import CMD_STOP

__all__ = ["PairRun", "pair_unavailable", "run_pair"]

DONE, CMDS, FULL, STALL, ERROR = 0, 3, 4, 5, 6
#: Frames the record buffer holds between two returns (80 bytes each: 5 MB).
RECORD_FRAMES = 1 << 16
_INT64_MAX = (1 << 63) - 1
_REPLIES = 16


class PairCmd(ctypes.Structure):
    """``bn_pair_cmd_t`` (``bn_pair.h``), field for field."""

    _fields_ = [
        ("feed_k", ctypes.c_int64),
        ("frame", Frame),
        ("p_step", ctypes.c_int64),
        ("p_horizon", ctypes.c_int64),
        ("p_cmd", ctypes.c_int32),
        ("p_seq", ctypes.c_int32),
        ("p_load_nm", ctypes.c_double),
        ("c_step", ctypes.c_int64),
        ("c_cmd", ctypes.c_int32),
        ("c_seq", ctypes.c_int32),
        ("c_speed_ref_rpm", ctypes.c_double),
        ("c_ack_seq", ctypes.c_int32),
        ("pad", ctypes.c_int32),
    ]


#: The :class:`PairCmd` fields :func:`_schedule` writes by columns, in its tuples' order,
#: with their numpy types (the sizes checked against the ctypes fields below).
_SCHEDULED: dict[str, type[np.generic]] = {
    "feed_k": np.int64,
    "p_step": np.int64,
    "p_horizon": np.int64,
    "p_cmd": np.int32,
    "p_seq": np.int32,
    "p_load_nm": np.float64,
    "c_step": np.int64,
    "c_cmd": np.int32,
    "c_seq": np.int32,
    "c_speed_ref_rpm": np.float64,
    "c_ack_seq": np.int32,
}
#: Those fields of ``bn_pair_cmd_t`` as numpy reads the rows (offsets from :class:`PairCmd`).
_SCHEDULED_DTYPE = np.dtype(
    {
        "names": list(_SCHEDULED),
        "formats": list(_SCHEDULED.values()),
        "offsets": [getattr(PairCmd, f).offset for f in _SCHEDULED],
        "itemsize": ctypes.sizeof(PairCmd),
    }
)


class Pair(ctypes.Structure):
    """``bn_pair_t`` (``bn_pair.h``), field for field."""

    _fields_ = [
        ("p", ctypes.c_void_p),
        ("c", ctypes.c_void_p),
        ("sched", ctypes.c_void_p),
        ("n_sched", ctypes.c_int64),
        ("n_fed", ctypes.c_int64),
        ("p_next", ctypes.c_int64),
        ("c_next", ctypes.c_int64),
        ("rec", ctypes.POINTER(Frame)),
        ("rec_cap", ctypes.c_uint64),
        ("n_rec", ctypes.c_uint64),
        ("steps", ctypes.c_uint64),
        ("timed", ctypes.c_int32),
        ("pad0", ctypes.c_int32),
        ("plant_ns", ctypes.c_int64),
        ("ctl_ns", ctypes.c_int64),
        ("phase", ctypes.c_int32),
        ("j", ctypes.c_int32),
        ("n_replies", ctypes.c_int32),
        ("pad", ctypes.c_int32),
        ("replies", Frame * _REPLIES),
    ]


_DECLARED: list[ctypes.CDLL] = []


def _lib() -> ctypes.CDLL:
    from bench.nodes.native._plant_native import _lib as plant_lib
    from bench.nodes.native.controller_node import native_library

    dll = plant_lib()
    native_library()
    if not _DECLARED:
        dll.bn_pair_sizeof.restype = ctypes.c_size_t
        dll.bn_pair_cmd_sizeof.restype = ctypes.c_size_t
        if dll.bn_pair_sizeof() != ctypes.sizeof(Pair):
            raise BenchError("native pair: bn_pair_t and its Python mirror differ")
        if dll.bn_pair_cmd_sizeof() != ctypes.sizeof(PairCmd) or any(
            getattr(PairCmd, f).size != np.dtype(t).itemsize for f, t in _SCHEDULED.items()
        ):
            raise BenchError("native pair: bn_pair_cmd_t and its Python mirror differ")
        dll.bn_pair_run.argtypes = [ctypes.POINTER(Pair)]
        dll.bn_pair_run.restype = ctypes.c_int
        _DECLARED.append(dll)
    return dll


def commands_fit(steps: list[int], lead: int) -> bool:
    """True when the C lists hold every command as it comes due: the schedule in step
    order (a list holds the earliest pending commands, one comes due per step, the
    rest wait for room: ``bn_pair.h``), or else no feed leaving more pending than
    :data:`~bench.nodes.native._plant_native.CMDS` (so many apply steps in no ``lead + 1``
    consecutive steps)."""
    from bench.nodes.native._plant_native import CMDS

    if all(a < b for a, b in itertools.pairwise(steps)):
        return True
    ss = sorted(steps)
    return all(ss[j + CMDS] - ss[j] > lead for j in range(len(ss) - CMDS))


def pair_unavailable(
    pn: Any, cn: Any, *, latency: bool, steps: list[int] | None = None, lead: int = 0
) -> str | None:
    """Why the nodes ``pn`` and ``cn`` cannot run as a native pair (one line), or None.

    ``steps``, ``lead``: the commands' apply steps and how far ahead they are fed
    (:func:`commands_fit`)."""
    from bench.nodes.native._plant_native import NATIVE_INTERFACES, native_missing
    from bench.nodes.native.controller_node import native_unavailable

    if latency:
        return "the lockstep latency model is Python's (bench.nodes._link.LockstepLink)"
    if steps is not None and not commands_fit(steps, lead):
        return f"more bench commands within {lead + 1} periods than the native lists hold"
    # The pair does not build the plant node's noise and fault tables (NoiseDraws,
    # NativeFaults): in-process, both stay with the Python loop.
    if pn.faults is not None:
        return "the scenario's [[faults]] are applied by the Python loop in-process"
    sp = pn.plant.sensor_pars
    if sp.noise_i > 0.0 or sp.noise_u > 0.0:
        return "sensor noise is drawn by the Python loop in-process"
    # no transport in-process: the plant node's reasons other than the interface's
    why = native_missing(pn, NATIVE_INTERFACES[0])
    if why is None:
        why = native_unavailable(cn, None)
    return why


class PairRun:
    """What :func:`run_pair` measured: periods advanced, calls into C, the seconds inside
    them, and the whole call's; of the rest, ``frames_seconds`` made the frames'
    :class:`~bench.wire._frames.FrameArray` from the record buffer (the commands fed
    among them); with ``timed``, the seconds inside each unit (two clock reads more per
    frame and per period, so not in the same run as ``c_seconds``)."""

    def __init__(self, timed: bool = False) -> None:
        self.timed = timed
        self.steps = 0
        self.calls = 0
        self.c_seconds = 0.0
        self.wall_seconds = 0.0
        self.plant_seconds = 0.0
        self.ctl_seconds = 0.0
        self.frames_seconds = 0.0


#: ``bn_frame_t`` as numpy reads the record buffer (bn.h; checked against :class:`Frame`).
_FRAME_DTYPE = np.dtype(
    {
        "names": ["id", "len", "flags", "data"],
        "formats": [np.uint32, np.uint8, np.uint8, (np.uint8, 64)],
        "offsets": [Frame.id.offset, Frame.len.offset, Frame.flags.offset, Frame.data.offset],
        "itemsize": ctypes.sizeof(Frame),
    }
)


class _Rows:
    """The run's frames as rows of :data:`~bench.wire._frames.FRAME_DTYPE`, written in
    place into one array grown by doubling (a fresh array per block and a concatenation
    at the end cost more than the C loop: page faults on a busy machine)."""

    def __init__(self, cap: int) -> None:
        self.rows = np.zeros(max(cap, 1), dtype=FRAME_DTYPE)
        self.n = 0

    def _room(self, k: int) -> npt.NDArray[np.void]:
        if self.n + k > len(self.rows):
            more = np.zeros(max(2 * len(self.rows), self.n + k), dtype=FRAME_DTYPE)
            more[: self.n] = self.rows[: self.n]
            self.rows = more
        at = self.n
        self.n += k
        return self.rows[at : self.n]

    def recorded(self, rec: Any, lo: int, hi: int) -> None:
        """Frames ``lo`` to ``hi`` of the record buffer (the fields a :class:`can.Message`
        of the codec gets: no time stamp)."""
        a = np.frombuffer(rec, dtype=_FRAME_DTYPE, count=hi)[lo:]
        r = self._room(hi - lo)
        r["id"] = a["id"]
        r["len"] = a["len"]
        flags = a["flags"]
        r["extended"] = (flags & BN_EXT) != 0
        r["fd"] = (flags & BN_FD) != 0
        r["brs"] = (flags & BN_BRS) != 0
        r["data"] = a["data"]

    def message(self, m: can.Message) -> None:
        self._room(1)[:] = FrameArray.from_messages([m]).rows

    def frames(self) -> FrameArray:
        return FrameArray(self.rows[: self.n])


def _schedule(
    pn: Any, cn: Any, cmds: list[tuple[int, can.Message]], sent: int, at: list[int]
) -> tuple[ctypes.Array[PairCmd], int, int]:
    """The ``bn_pair_cmd_t`` rows: first the commands the nodes hold before the run
    (fed before it, the first ``sent``: the plant's pending ones, then the
    controller's, as fed already), then the others with what the nodes' queues make of
    each at its feed (module docstring); how many rows, and how many of them came
    first.  The nodes' clocks are as before when it returns.

    At a feed the nodes have applied their commands up to its step: ``due`` has run.
    ``CommandQueue.add`` reads of that only the applied step (a late command) and the
    number pending (a full queue), so where no command is late (each fed before its
    step) and the queues cannot fill (fewer commands than
    :data:`~bench.nodes._counters.MAX_PENDING_COMMANDS`) the applied step is moved
    and ``due`` left to the end (:meth:`_Sync.pull`, :meth:`NativeController.merge`),
    which spares a sort of the pending commands twice per command."""
    from bench.nodes._counters import MAX_PENDING_COMMANDS
    from bench.nodes.native._plant_native import to_frame

    ks = at  # the plant step of each command's feed (bench.nodes._counters.feed_steps)
    # a late command (fed at or after its step) is placed by the pending steps
    settle = len(cmds) >= MAX_PENDING_COMMANDS or any(
        s <= k for (s, _), k in zip(cmds, ks, strict=True)
    )
    n_steps = pn.n_steps if pn.n_steps > 0 else _INT64_MAX
    plant, pq, cq = pn.plant, pn.commands, cn.commands
    held_p, held_c = sorted(pq.pending.items()), sorted(cq.pending.items())
    rows = (PairCmd * max(len(held_p) + len(held_c) + len(cmds) - sent, 1))()
    n = 0
    for s, c in held_p:
        r = rows[n]
        r.feed_k, r.c_step = -1, -1
        r.p_step, r.p_cmd, r.p_seq, r.p_load_nm = s, c.cmd, c.seq, c.load_nm
        n += 1
    for s, c in held_c:
        r = rows[n]
        r.feed_k, r.p_step = -1, -1
        r.c_step, r.c_cmd, r.c_seq, r.c_speed_ref_rpm = s, c.cmd, c.seq, c.speed_ref_rpm
        n += 1
    n_held = n
    k0, next0 = plant.k, cn.next_k
    # the run's last instant: its steps, or the step a stop applies (or applied)
    end = 0 if pn.stopped else n_steps
    for s, c in held_p:
        if c.cmd == CMD_STOP:
            end = min(end, s)
    # per command fed: feed_k, p_step, p_horizon, p_cmd, p_seq, p_load_nm, c_step, c_cmd,
    # c_seq, c_speed_ref_rpm, c_ack_seq (PairCmd's order), written by columns after
    cols: list[tuple[int, int, int, int, int, float, int, int, int, float, int]] = []
    cn.last_output = None  # run_inprocess drops the telemetry a command answers
    pending_p, pending_c = pq.pending, cq.pending
    try:
        for (_, m), k in zip(cmds[sent:], ks[sent:], strict=True):
            if k >= end:
                break  # the run ends before this feed
            # the nodes as at this feed: the plant at step k, its commands up to k
            # applied; the controller at k + 1 (it answered sample k)
            plant.k = k
            cn.next_k = k + 1
            if settle:
                pq.due(k)
                cq.due(k)
            else:  # add's outcome is the same (docstring)
                pq.applied_upto = max(pq.applied_upto, k)
                cq.applied_upto = max(cq.applied_upto, k)
            p_before, c_before = len(pending_p), len(pending_c)
            pn.on_message(m)
            cn.on_message(m)
            rows[n + len(cols)].frame = to_frame(m)
            # add puts at most one command in, due only takes out: the newest key
            if len(pending_p) > p_before:
                pc = pending_p[next(reversed(pending_p))]
                p = (pc.apply_step, pc.cmd, pc.seq, pc.load_nm)
                if pc.cmd == CMD_STOP:
                    end = min(end, pc.apply_step)
            else:
                p = (-1, 0, 0, 0.0)
            if len(pending_c) > c_before:
                cc = pending_c[next(reversed(pending_c))]
                c = (cc.apply_step, cc.cmd, cc.seq, cc.speed_ref_rpm)
            else:
                c = (-1, 0, 0, 0.0)
            cols.append((k, p[0], pn.cmd_horizon, p[1], p[2], p[3], *c, cq.ack_seq))
    finally:
        plant.k, cn.next_k = k0, next0
    if cols:
        buf: Any = rows
        v = np.frombuffer(buf, dtype=_SCHEDULED_DTYPE)[n : n + len(cols)]
        for name, col in zip(_SCHEDULED, zip(*cols, strict=True), strict=True):
            v[name] = col
        n += len(cols)
    return rows, n, n_held


def run_pair(
    pn: Any,
    cn: Any,
    cmds: list[tuple[int, can.Message]],
    lead: int,
    *,
    measure: PairRun | None = None,
) -> FrameArray:
    """``run_inprocess``'s loop on the pair (module docstring); every frame in wire order,
    as one :class:`~bench.wire._frames.FrameArray` (a :class:`can.Message` is made only
    where a consumer asks for one).

    ``pn``, ``cn``: the plant and controller nodes as built; ``cmds``: the bench's
    commands by step (:func:`bench.nodes._loops.command_frames`); ``lead``: how far
    ahead of the plant they are fed.  ``measure`` (when given) gets the periods, the
    returns to Python and the seconds spent in C.
    """
    from bench.nodes._counters import feed_steps
    from bench.nodes.native._plant_native import Unit, _fill_config, _Sync
    from bench.nodes.native.controller_node import NativeController

    if not commands_fit([s for s, _ in cmds], lead):
        raise BenchError(
            f"native pair: more bench commands within {lead + 1} periods than it holds"
        )
    dll = _lib()
    #: the frames so far: about four a period
    out = _Rows(4 * pn.n_steps + len(cmds) + 64)
    sent = 0
    at = feed_steps([s for s, _ in cmds], lead)
    while sent < len(cmds) and at[sent] < 0:  # fed before the run
        m = cmds[sent][1]
        out.message(m)
        pn.on_message(m)
        cn.on_message(m)
        sent += 1
    pn.apply_commands()
    u = Unit()
    _fill_config(dll, pn, u, False, False)
    sync = _Sync(pn, u, dll.bn_plant_reject_names().decode().split(","))
    sync.push_all()
    nc = NativeController(cn, realtime=False)
    t_start = time.perf_counter()  # the set-up above is not the loop's
    sched, n_sched, n_held = _schedule(pn, cn, cmds, sent, at)
    # the lists the nodes handed over are the schedule's first rows now (bn_pair.h)
    u.n_cmds = u.cmds_more = 0
    nc.ctl.n_cmds = nc.ctl.cmds_more = 0
    rec = (Frame * RECORD_FRAMES)()
    P = Pair()
    P.p = ctypes.addressof(u)
    P.c = nc.addr
    P.sched = ctypes.addressof(sched)
    P.n_sched = n_sched
    P.n_fed = n_held
    P.rec = ctypes.cast(rec, ctypes.POINTER(Frame))
    P.rec_cap = RECORD_FRAMES
    P.timed = int(measure is not None and measure.timed)
    run = dll.bn_pair_run
    ref = ctypes.byref(P)
    c_s = frames_s = 0.0
    calls = 0

    def flush() -> None:
        nonlocal frames_s
        t0 = time.perf_counter()
        out.recorded(rec, 0, int(P.n_rec))
        P.n_rec = 0
        frames_s += time.perf_counter() - t0

    try:
        while True:
            t0 = time.perf_counter()
            ev = run(ref)
            c_s += time.perf_counter() - t0
            calls += 1
            if ev == DONE:
                break
            if ev == FULL:
                flush()
                continue
            sync.pull()
            if ev == STALL:
                raise RuntimeError(f"in-process loop stalled at step {pn.plant.k}")
            if ev == ERROR and nc.ctl.error != 0:
                nc.handle(7)  # the controller core's error, as its node raises it
            # CMDS (the lists were checked to hold the commands), or a feed where the
            # controller is not at the plant's step: the schedule would not be the loop's
            raise RuntimeError(
                f"native pair: event {ev} at step {pn.plant.k} (controller at {nc.ctl.next_k})"
            )
    finally:
        flush()
        sync.pull()
        nc.merge()
    if P.n_fed != n_sched:
        raise RuntimeError(f"native pair: {P.n_fed} of {n_sched} scheduled commands fed")
    t_end = time.perf_counter()
    if measure is not None:
        measure.steps += int(P.steps)
        measure.c_seconds += c_s
        measure.calls += calls
        measure.wall_seconds += t_end - t_start
        measure.frames_seconds += frames_s
        measure.plant_seconds += 1e-9 * P.plant_ns
        measure.ctl_seconds += 1e-9 * P.ctl_ns
    return out.frames()
