"""The in-process native pair: :func:`bench.nodes._loops.run_inprocess` with its loop in C.

The plant node and the controller node are built by Python as for the Python
loop (the same plant core and controller core, by address); :func:`run_pair`
hands the loop to ``bn_pair_run`` (``bn_pair.h``), which steps both units for
many periods per call with the frames passed in memory and no Python per
period.  It returns only to feed the nodes a bench command (the same schedule
as the Python loop: :data:`bench.nodes._loops.INPROCESS_LEAD` periods ahead),
to apply a command due at the controller, to take the recorded frames when
their buffer is full, and at the end.  The frames it returns are those of the
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
import time
from typing import Any

import can
import numpy as np
import numpy.typing as npt

from bench._errors import BenchError
from bench.nodes.native._native import BN_BRS, BN_EXT, BN_FD, Frame
from bench.wire._frames import FRAME_DTYPE, FrameArray

__all__ = ["PairRun", "pair_unavailable", "run_pair"]

DONE, FEED, DUE, CMDS, FULL, STALL, ERROR = range(7)
#: Frames the record buffer holds between two returns (80 bytes each: 5 MB).
RECORD_FRAMES = 1 << 16
_INT64_MAX = (1 << 63) - 1
_REPLIES = 16


class Pair(ctypes.Structure):
    """``bn_pair_t`` (``bn_pair.h``), field for field."""

    _fields_ = [
        ("p", ctypes.c_void_p),
        ("c", ctypes.c_void_p),
        ("lead", ctypes.c_int64),
        ("feed_step", ctypes.c_int64),
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
        if dll.bn_pair_sizeof() != ctypes.sizeof(Pair):
            raise BenchError("native pair: bn_pair_t and its Python mirror differ")
        dll.bn_pair_run.argtypes = [ctypes.POINTER(Pair)]
        dll.bn_pair_run.restype = ctypes.c_int
        _DECLARED.append(dll)
    return dll


def pair_unavailable(pn: Any, cn: Any, *, latency: bool) -> str | None:
    """Why the nodes ``pn`` and ``cn`` cannot run as a native pair (one line), or None."""
    from bench.nodes.native._plant_native import NATIVE_INTERFACES, native_missing
    from bench.nodes.native.controller_node import native_unavailable

    if latency:
        return "the lockstep latency model is Python's (bench.nodes._link.LockstepLink)"
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
    ahead of the plant they are fed.  ``measure`` (when given) gets the periods and
    the seconds spent in C.
    """
    from bench.nodes.native._plant_native import Unit, _fill_config, _Sync
    from bench.nodes.native.controller_node import EV_DUE, NativeController

    dll = _lib()
    #: the frames so far (the commands fed in between as theirs): about four a period
    out = _Rows(4 * pn.n_steps + len(cmds) + 64)
    frames_s = 0.0  # seconds spent in flush (PairRun.frames_seconds)
    sent = 0
    #: commands fed while frames wait in the record buffer: (frames before them, command)
    fed: list[tuple[int, can.Message]] = []

    def feed(up_to: int) -> None:
        nonlocal sent
        while sent < len(cmds) and cmds[sent][0] <= up_to:
            m = cmds[sent][1]
            if nc is None:
                out.message(m)
            else:
                fed.append((int(P.n_rec), m))
            pn.on_message(m)
            _ctl_command(m)
            sent += 1

    def flush() -> None:
        """The recorded frames into ``out``, with the commands fed among them."""
        nonlocal frames_s
        t0 = time.perf_counter()
        at = 0
        for pos, m in fed:
            out.recorded(rec, at, pos)
            out.message(m)
            at = pos
        out.recorded(rec, at, int(P.n_rec))
        fed.clear()
        P.n_rec = 0
        frames_s += time.perf_counter() - t0

    nc: NativeController | None = None

    def _ctl_command(m: can.Message) -> None:
        if nc is None:  # before the hand-over: the Python node as the Python loop
            cn.on_message(m)
            return
        c = nc.ctl
        cn.next_k = c.next_k
        if c.next_k > 0:  # the steps C ran count as applied (CommandQueue.due)
            cn.commands.applied_upto = max(cn.commands.applied_upto, c.next_k - 1)
        cn.last_output = None  # run_inprocess drops the telemetry a command answers
        cn.on_message(m)
        nc._sync_commands()

    feed(lead)
    pn.apply_commands()
    u = Unit()
    _fill_config(dll, pn, u, False, False)
    sync = _Sync(pn, u, dll.bn_plant_reject_names().decode().split(","))
    sync.push_all()
    nc = NativeController(cn, realtime=False)
    rec = (Frame * RECORD_FRAMES)()
    P = Pair()
    P.p = ctypes.addressof(u)
    P.c = nc.addr
    P.lead = lead
    P.feed_step = cmds[sent][0] if sent < len(cmds) else _INT64_MAX
    P.rec = ctypes.cast(rec, ctypes.POINTER(Frame))
    P.rec_cap = RECORD_FRAMES
    P.timed = int(measure is not None and measure.timed)
    t_start = time.perf_counter()
    run = dll.bn_pair_run
    ref = ctypes.byref(P)
    c_s = 0.0
    calls = 0
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
            if ev == DUE:
                nc.handle(EV_DUE)
            elif ev == FEED:
                sync.pull()
                feed(pn.plant.k + lead)
                sync.push_commands()
                P.feed_step = cmds[sent][0] if sent < len(cmds) else _INT64_MAX
            elif ev == CMDS:
                sync.pull()
                sync.push_commands()
            elif ev == STALL:
                sync.pull()
                raise RuntimeError(f"in-process loop stalled at step {pn.plant.k}")
            else:
                nc.handle(7)  # the controller core's error, as its node raises it
                raise BenchError(f"native pair: controller error {nc.ctl.error}")
    finally:
        flush()
        sync.pull()
        nc.merge()
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
