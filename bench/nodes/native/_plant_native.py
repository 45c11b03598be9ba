"""The native plant node: the plant's per-period loop in C, set up and reported by Python.

``bench plant`` keeps everything but the loop: the plan, the :class:`plant_rt.Plant`
as built, the :class:`~bench.nodes._plant_node.PlantNode` with its command queue,
the report.  :func:`plant_loop_native` hands the loop to one ctypes call into
the library built here (``bn_plant_loop``, ``bn_plant.h``; the GIL is released
while it runs), which steps the same plant core instance
(:meth:`plant_rt.Plant.core_address`) and returns only on an event it does
not handle: a ``BenchCommand`` or ``CtrlTelemetry`` frame (the node's
:class:`~bench.nodes._counters.CommandQueue` takes it, and the pending
commands go back to C; the copies of a command it took are dropped in C and
counted as its repeats, ``bn_cmd_seen_t`` in bn.h), a poll (a signal, or a while without one), a stall,
the end.  The node's state and counters are taken back at every event, so
its report, its stderr lines and its last ``PlantStatus`` are those of the
Python node.

What needs Python is made before the loop and handed to C once: the sensors'
noise values (:class:`NoiseDraws`, drawn from the plant's own generator in the
sensors' order) and the fault timeline (:class:`NativeFaults`: the plant's
parameter and leg edges from :class:`plant_rt._faults.PlantFaults`, its sensor
windows, and the bus faults' per-instant tables, each entry
:class:`bench.nodes._fault_bus.NodeFaults`' own answer).  The loop allocates
nothing.

:func:`native_missing` says why a plant cannot run natively (one line), or None.
"""

from __future__ import annotations

import ctypes
import os
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import can
import numpy as np

from bench._errors import BenchError
from bench.nodes._counters import REPEATED_COUNTER
from bench.nodes.native import _native
from bench.nodes.native._native import (
    BN_BRS,
    BN_EXT,
    BN_FD,
    CmdSeen,
    Frame,
    Held,
    Sig,
    Stats,
    copy_span,
)
from plant_rt._faults import LEG_KINDS, MACHINE_KINDS, SENSOR_KINDS

__all__ = [
    "Frame",
    "Sig",
    "load_plant_lib",
    "native_missing",
    "open_native_bus",
    "plant_loop_native",
]

#: Transports the native loop speaks (``bn_udp_open``, ``bn_can_open``).
NATIVE_INTERFACES = ("udp_multicast", "socketcan")

RING = 64
CMDS = 256
OUT = 12
HISTORY = 512
SENT = 16
N_REJECT = 8

EV_DONE, EV_FRAME, EV_POLL, EV_STALL, EV_CMDS, EV_TRIPPED, EV_ERROR = range(7)
WAIT_DUTY, WAIT_COMMAND, WAIT_ACK = 1, 2, 3


class Cmd(ctypes.Structure):
    _fields_ = [
        ("step", ctypes.c_int64),
        ("cmd", ctypes.c_int32),
        ("seq", ctypes.c_int32),
        ("load_nm", ctypes.c_double),
    ]


class Duty(ctypes.Structure):
    _fields_ = [
        ("d", ctypes.c_double * 3),
        ("en", ctypes.c_int32),
        ("pad", ctypes.c_int32),
        ("tag", ctypes.c_int64),
    ]


class Prot(ctypes.Structure):
    _fields_ = [
        ("i_trip", ctypes.c_double),
        ("u_dc_trip", ctypes.c_double),
        ("w_m_trip", ctypes.c_double),
    ]


_I32, _I64, _U64, _D = ctypes.c_int32, ctypes.c_int64, ctypes.c_uint64, ctypes.c_double

#: The counters of ``bn_plant_t`` that grow (taken back as differences at every event).
_COUNTERS = (
    "accepted",
    "late_duties",
    "retransmits",
    "overruns",
    "send_errors",
    "frames_lost_on_send",
    "resets",
)


class Noise(ctypes.Structure):
    """``bn_plant_noise_t``: the sensors' noise values, drawn here (:func:`noise_draws`)."""

    _fields_ = [("draws", ctypes.POINTER(ctypes.c_double)), ("n", _I64), ("used", _I64)]


class MachinePars(ctypes.Structure):
    """``plant_machine_pars`` (``plant_rt/core/plant_machine.h``)."""

    _fields_ = [
        *((name, _D) for name in ("n_p", "R_s", "L_d", "L_q", "psi_f", "J", "b", "i_max")),
        *((name, _D) for name in ("sat_sigma", "sat_i_sat", "c_dq")),
        ("saturation", ctypes.c_int),
        ("cross", ctypes.c_int),
    ]


class PlantPars(ctypes.Structure):
    """``plant_pars`` (``plant_rt/core/plant.h``): filled from :meth:`plant_rt.Plant._core_pars`,
    whose order it is (the binding's ``Core(*pars)``)."""

    _fields_ = [
        ("machine", MachinePars),
        ("T_s", _D),
        ("substeps", ctypes.c_int),
        ("t_delay", _D),
        ("switching", ctypes.c_int),
        ("peak", ctypes.c_int),
        *((name, _D) for name in ("u_dc", "t_dead", "v_ce", "v_f", "r_dc", "c_dc")),
    ]

    @classmethod
    def of(cls, values: tuple[float | int | bool, ...]) -> PlantPars:
        p = cls()
        names = [f[0] for f in MachinePars._fields_]
        m, rest = values[: len(names)], values[len(names) :]
        for name, v in zip(names, m, strict=True):
            setattr(p.machine, name, v)
        for f, v in zip(cls._fields_[1:], rest, strict=True):
            setattr(p, f[0], v)
        return p


class Edge(ctypes.Structure):
    """``bn_plant_edge_t``."""

    _fields_ = [
        ("k", _I64),
        ("set_pars", _I32),
        ("set_legs", _I32),
        ("leg", _I32 * 3),
        ("pad", _I32),
        ("pars", PlantPars),
    ]


class SensorFault(ctypes.Structure):
    """``bn_plant_sfault_t``."""

    _fields_ = [
        ("kind", _I32),
        ("phase", _I32),
        ("k0", _I64),
        ("k1", _I64),
        ("value", _D),
        ("held", _I32),
        ("pad", _I32),
        ("hold", _D),
    ]


class Babble(ctypes.Structure):
    """``bn_plant_babble_t``."""

    _fields_ = [("k", _I64), ("to_plant", Frame), ("to_ctrl", Frame)]


#: ``bn_plant_faults_t.clock_ns``: the clock of the frames' receive stamps (ns); NULL:
#: CLOCK_REALTIME, the clock of python-can's timestamps (:attr:`PlantNode.clock`).
CLOCK_NS = ctypes.CFUNCTYPE(ctypes.c_int64)
#: ``bn_plant_faults_t.released`` of a duty not held.
NOT_HELD = -(1 << 63)


class Faults(ctypes.Structure):
    """``bn_plant_faults_t``."""

    _fields_ = [
        ("on", _I32),
        ("n_edges", _I32),
        ("next_edge", _I32),
        ("n_sensor", _I32),
        ("edges", ctypes.POINTER(Edge)),
        ("sensor", ctypes.POINTER(SensorFault)),
        ("last", _D * 3),
        ("last_k", _I64),
        ("n_k", _I64),
        ("fate", ctypes.POINTER(ctypes.c_int8)),
        ("shift_ls", ctypes.POINTER(_I32)),
        ("shift_rt", ctypes.POINTER(_I32)),
        ("nosend", ctypes.POINTER(ctypes.c_uint8)),
        ("babble", ctypes.POINTER(Babble)),
        ("n_babble", _I32),
        ("next_babble", _I32),
        ("duties_lost", _U64),
        ("not_sent", _U64 * 2),
        ("babbled", _U64),
        ("history", Duty * HISTORY),
        ("withheld", ctypes.POINTER(Frame)),
        ("wh_cap", _I64),
        ("wh_n", _I64),
        ("wh_sent", _I64),
        ("out_wh", _I64 * 2),
        ("out_wh_at", _I32),
        ("pad_wh", _I32),
        ("sent_wh", (_I64 * 2) * SENT),
        ("hold_ns", ctypes.POINTER(_I64)),
        ("released", _I64 * RING),
        ("clock_ns", CLOCK_NS),
    ]


class Unit(ctypes.Structure):
    """``bn_plant_t`` (``bn_plant.h``), field for field."""

    _fields_ = [
        ("pl", ctypes.c_void_p),
        ("n_steps", _I64),
        ("delay", _I32),
        ("truth_every", _I32),
        ("status_every", _I32),
        ("encoder_every", _I32),
        ("encoder_delay_s", _D),
        ("encoder_counts", _I64),
        ("prot", Prot),
        ("has_prot", _I32),
        ("watchdog_periods", _I32),
        ("watchdog_rounds", _I32),
        ("realtime", _I32),
        ("external", _I32),
        ("run_id", _I32),
        ("m_samples", _I64),
        ("m_truth", _I64),
        ("m_status", _I64),
        ("m_step", _I64),
        ("sig", Sig * 28),
        ("msg_flags", _I32 * 5),
        ("pad_flags", _I32),
        ("noise", Noise),
        ("faults", Faults),
        ("k", _I64),
        ("meas_k", _I64),
        ("started", _I32),
        ("stopped", _I32),
        ("fault", _I32),
        ("dut_answered", _I32),
        ("fault_step", _I64),
        ("last_duty_k", _I64),
        ("rounds_waiting", _I64),
        ("latest_duty_step", _I64),
        ("dropped_upto", _I64),
        ("latest", _D * 3),
        ("latest_en", _I32),
        ("duty_age", _I32),
        ("load_changed", _I32),
        ("ctrl_ack", _I32),
        ("cmd_horizon", _I64),
        ("applied_upto", _I64),
        ("applied_seq", _I32),
        ("n_cmds", _I32),
        ("cmds_more", _I32),
        ("pace_every", _I32),
        ("applied", Duty),
        ("cmds", Cmd * CMDS),
        ("duties", Duty * RING),
        ("accepted", _U64),
        ("rejected", _U64 * N_REJECT),
        ("duty_rejected", _U64 * N_REJECT),
        ("late_duties", _U64),
        ("retransmits", _U64),
        ("overruns", _U64),
        ("send_errors", _U64),
        ("frames_lost_on_send", _U64),
        ("trips", _U64 * 8),
        ("resets", _U64),
        ("late_frames_base", _U64),
        ("out", Frame * OUT),
        ("n_out", _I32),
        ("n_outbox", _I32),
        ("outbox", Frame * 4),
        ("sent", (Frame * OUT) * SENT),
        ("n_sent", _I32 * SENT),
        ("sent_head", _I64),
    ]


class Clock(ctypes.Structure):
    """``bn_clock_t`` (``bn.h``)."""

    _fields_ = [
        ("period_ns", _I64),
        ("busy_tail_ns", _I64),
        ("stall_ns", _I64),
        ("t0_ns", _I64),
        ("woke_ns", _I64),
        ("n", _U64),
        ("st", Stats),
        ("busy", ctypes.POINTER(ctypes.c_uint32)),
        ("busy_cap", ctypes.c_size_t),
    ]


class Loop(ctypes.Structure):
    """``bn_plant_loop_t`` (``bn_plant.h``)."""

    _fields_ = [
        ("u", ctypes.POINTER(Unit)),
        ("bus", ctypes.c_void_p),
        ("ids", ctypes.c_uint32 * 4),
        ("event_ids", ctypes.c_uint32 * 4),
        ("retransmit_s", _D),
        ("stall_s", _D),
        ("first_s", _D),
        ("poll_s", _D),
        ("last_answer_s", _D),
        ("period_ns", _I64),
        ("busy_tail_ns", _I64),
        ("stall_ns", _I64),
        ("busy", ctypes.POINTER(ctypes.c_uint32)),
        ("busy_cap", _U64),
        ("late", ctypes.POINTER(ctypes.c_uint32)),
        ("late_cap", _U64),
        ("n_late", _U64),
        ("clock", Clock),
        ("rt_started", _I32),
        ("phase", _I32),
        ("stall_what", _I32),
        ("t_progress", _I64),
        ("t_quiet", _I64),
        ("t_poll", _I64),
        ("last_phase", _I32),
        ("t_last_end", _I64),
        ("t_first_sent", _I64),
        ("ev_frame", Frame),
        ("err", _I32),
        ("parts", ctypes.POINTER(ctypes.c_uint32)),
        ("part_ns", _I64 * 3),
        ("held_margin_ns", _I64),
        ("held", Held),
        ("cmd_seen", CmdSeen),
    ]


# ------------------------------------------------------------------ build


def load_plant_lib(path: Path | None = None) -> ctypes.CDLL:
    """The native library (:func:`._native.library`, or the one at ``path``) with the
    argument types of the calls made here; checks the struct layouts."""
    dll = _native.library() if path is None else _native.load(path)
    dll.bn_plant_sizeof.restype = ctypes.c_size_t
    dll.bn_plant_loop_sizeof.restype = ctypes.c_size_t
    dll.bn_plant_signal_names.restype = ctypes.c_char_p
    dll.bn_plant_reject_names.restype = ctypes.c_char_p
    dll.bn_plant_edge_sizeof.restype = ctypes.c_size_t
    dll.bn_plant_sfault_sizeof.restype = ctypes.c_size_t
    for name, want in (
        ("bn_plant_sizeof", Unit),
        ("bn_plant_loop_sizeof", Loop),
        ("bn_plant_edge_sizeof", Edge),
        ("bn_plant_sfault_sizeof", SensorFault),
    ):
        if getattr(dll, name)() != ctypes.sizeof(want):
            raise BenchError(f"native plant: {path}: {name} differs from {want.__name__}")
    check_plant_layout(dll)
    dll.bn_plant_on_duty.argtypes = [ctypes.POINTER(Unit), ctypes.POINTER(Frame)]
    dll.bn_plant_advance.argtypes = [ctypes.POINTER(Unit)]
    dll.bn_plant_frames_now.argtypes = [ctypes.POINTER(Unit)]
    dll.bn_plant_loop.argtypes = [ctypes.POINTER(Loop)]
    dll.bn_plant_loop.restype = ctypes.c_int
    dll.bn_udp_open.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_uint16, ctypes.c_int]
    dll.bn_can_open.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_bool]
    dll.bn_bus_size.restype = ctypes.c_size_t
    dll.bn_recv.argtypes = [ctypes.c_void_p, ctypes.POINTER(Frame), ctypes.c_int64]
    dll.bn_send.argtypes = [ctypes.c_void_p, ctypes.POINTER(Frame)]
    dll.bn_plant_send.argtypes = [ctypes.POINTER(Unit), ctypes.c_void_p, ctypes.POINTER(Frame)]
    dll.bn_close.argtypes = [ctypes.c_void_p]
    dll.bn_clock_stats.argtypes = [ctypes.POINTER(Clock), ctypes.POINTER(Stats)]
    return dll


def library_plant_layout(dll: ctypes.CDLL) -> tuple[str, tuple[int, ...]]:
    """``(names, numbers)`` of the plant instance as the library compiled it
    (``plant_layout``, ``plant_rt/core/plant_layout.h``)."""
    dll.plant_layout.argtypes = [ctypes.POINTER(ctypes.c_size_t), ctypes.c_size_t]
    dll.plant_layout.restype = ctypes.c_size_t
    dll.plant_layout_names.restype = ctypes.c_char_p
    n = int(dll.plant_layout(None, 0))
    out = (ctypes.c_size_t * n)()
    dll.plant_layout(out, n)
    return dll.plant_layout_names().decode(), tuple(int(v) for v in out)


def check_plant_layout(
    dll: ctypes.CDLL, extension: tuple[str, tuple[int, ...]] | None = None
) -> None:
    """Refuse a library whose plant struct is not the extension's.

    The library steps the instance that ``plant_rt._cplant`` allocated, by its address
    (:meth:`plant_rt.Plant.core_address`); both compile ``plant_rt/core/`` but at
    different times (the extension when the package is installed, the library once per
    source change), so a stale extension beside a fresh library would be stepped with
    the wrong offsets. Both export ``sizeof(plant)``, the sizes of the blocks it embeds
    and the offset of each member (``plant_layout.h``); a difference is a
    :class:`BenchError` of one line naming both files, the first number that differs
    and what to rebuild. ``extension``: the extension's ``_cplant.layout()`` (a test's
    fake); None asks the extension.
    """
    from plant_rt import _cplant

    ext_file = getattr(_cplant, "__file__", "plant_rt._cplant")
    lib_file = getattr(dll, "_name", "the native library")
    rebuild = (
        f"rebuild the extension from the present sources (make .venv/.installed, or "
        f"pip install -e .), or delete {lib_file} if it is the stale one"
    )
    if extension is None:
        layout = getattr(_cplant, "layout", None)
        if layout is None:
            raise BenchError(
                f"native plant: {ext_file} exports no plant layout (built before "
                f"plant_rt/core/plant_layout.h); it cannot be checked against {lib_file}: {rebuild}"
            )
        extension = layout()
    ext_names, ext_nums = extension
    lib_names, lib_nums = library_plant_layout(dll)
    if (ext_names, ext_nums) == (lib_names, lib_nums):
        return
    names_e, names_l = ext_names.split(";"), lib_names.split(";")
    for ne, nl, ve, vl in zip(names_e, names_l, ext_nums, lib_nums, strict=False):
        if ne != nl or ve != vl:
            what = f"{ne} {ve} against {nl} {vl}" if ne != nl else f"{ne} is {ve} against {vl}"
            break
    else:
        what = f"{len(ext_nums)} numbers against {len(lib_nums)}"
    raise BenchError(
        f"native plant: the plant struct differs between {ext_file} and {lib_file} "
        f"({what}): {rebuild}"
    )


_LIB: ctypes.CDLL | None = None


def _lib() -> ctypes.CDLL:
    global _LIB
    if _LIB is None:
        _LIB = load_plant_lib()
    return _LIB


# ------------------------------------------------------------ eligibility


def native_missing(node: Any, interface: str) -> str | None:
    """Why ``node`` cannot run on the native loop (one line), or None when it can.

    Building the library (once per source change) is part of the answer: no C
    compiler, or a failed build, is a reason.
    """
    plant = node.plant
    if interface not in NATIVE_INTERFACES:
        return f"the native loop speaks {' and '.join(NATIVE_INTERFACES)}, not {interface}"
    if node.faults is not None:
        other = sorted({f.kind for f, _ in node.faults.windows} - set(NATIVE_FAULT_KINDS))
        if other:
            return f"the faults {', '.join(other)} are applied by the Python node only"
        if node.n_steps <= 0:
            # the bus faults' tables are made before the loop, one entry per period it runs
            return "[[faults]] in a run without a step count (n_steps 0) are applied by the Python node only"
    # A load profile needs no check: every bench command sets a constant load
    # (PlantNode.apply_commands), the start command before the first period, so a
    # profile the plant was built with never acts in a node's period, Python or native.
    # The energy meter integrates in the core, whoever steps it (Plant.adopt_core reads it).
    sp = plant.sensor_pars
    if (sp.noise_i > 0.0 or sp.noise_u > 0.0) and node.n_steps <= 0:
        # the noise values are drawn before the loop, one set per period it will run
        return "sensor noise in a run without a step count (n_steps 0) is drawn by the Python node only"
    try:
        _lib()
    except BenchError as e:
        return str(e)
    return None


# ------------------------------------------------------------------- loop


class NativeBus:
    """A ``bn_bus_t`` on the node's bus (python-can's udp_multicast wire format, or SocketCAN)."""

    def __init__(self, dll: ctypes.CDLL, spec: Any) -> None:
        from bench.wire._bus import RECEIVE_BUFFER, UDP_DEFAULT_PORT

        self.dll = dll
        self.buf = (ctypes.c_uint64 * ((dll.bn_bus_size() + 7) // 8))()  # room for bn_bus_t
        self.ptr = ctypes.cast(self.buf, ctypes.c_void_p)
        if spec.interface == "udp_multicast":
            port = spec.port if spec.port is not None else UDP_DEFAULT_PORT
            rc = dll.bn_udp_open(self.ptr, spec.channel.encode(), port, RECEIVE_BUFFER)
        else:
            rc = dll.bn_can_open(self.ptr, spec.channel.encode(), True)
        if rc != 0:
            raise BenchError(f"native plant: {spec.interface} {spec.channel}: {os.strerror(-rc)}")
        self.open = True

    def recv(self, timeout_s: float) -> Frame | None:
        f = Frame()
        r = self.dll.bn_recv(self.ptr, ctypes.byref(f), int(timeout_s * 1e9))
        if r < 0:
            raise BenchError(f"native plant: receive: {os.strerror(-r)}")
        return f if r > 0 else None

    def close(self) -> None:
        if self.open:
            self.dll.bn_close(self.ptr)
            self.open = False


def open_native_bus(spec: Any) -> NativeBus:
    """The native loop's bus on ``spec`` (:class:`bench.wire._bus.BusSpec`)."""
    return NativeBus(_lib(), spec)


def to_message(f: Frame) -> can.Message:
    return can.Message(
        arbitration_id=f.id,
        is_extended_id=bool(f.flags & BN_EXT),
        is_fd=bool(f.flags & BN_FD),
        bitrate_switch=bool(f.flags & BN_BRS),
        data=bytes(f.data[: f.len]),
        check=False,
    )


def to_frame(m: can.Message) -> Frame:
    f = Frame()
    f.id = m.arbitration_id
    f.len = len(m.data)
    f.flags = (
        (BN_EXT if m.is_extended_id else 0)
        | (BN_FD if m.is_fd else 0)
        | (BN_BRS if m.bitrate_switch else 0)
    )
    ctypes.memmove(f.data, bytes(m.data), f.len)
    return f


class _Sync:
    """The node's state handed to C and taken back, and C's counters added to the node's."""

    def __init__(self, node: Any, u: Unit, reasons: list[str]) -> None:
        self.node = node
        self.u = u
        self.reasons = reasons
        self.seen = {name: 0 for name in _COUNTERS}
        self.seen_rej = [0] * N_REJECT
        self.seen_duty_rej = [0] * N_REJECT
        self.seen_trips = [0] * 8
        # the pending list and the duty ring as numpy views of the unit's memory: one
        # vector copy a return instead of a ctypes access per slot
        self.cmds = np.ctypeslib.as_array(u.cmds)
        self.duties = np.ctypeslib.as_array(u.duties)

    def push_all(self) -> None:
        node, u = self.node, self.u
        p = node.plant
        u.k = p.k
        u.meas_k = p.meas_step()
        u.started, u.stopped = int(node.started), int(node.stopped)
        u.fault, u.fault_step = node.fault, node.fault_step
        u.dut_answered = int(node.dut_answered)
        u.last_duty_k, u.rounds_waiting = node.last_duty_k, node.rounds_waiting
        u.latest_duty_step = node.latest_duty_step
        u.dropped_upto = node.dropped_upto
        d_a, d_b, d_c, en = node.latest_duty
        u.latest[0], u.latest[1], u.latest[2], u.latest_en = d_a, d_b, d_c, int(en)
        u.duty_age = node.duty_age
        u.late_frames_base = node.late_frames
        u.overruns = 0
        for j in range(RING):
            u.duties[j].tag = -1
        # status frames the node queued before the loop (a trip while it waited for the start)
        queued = node._outbox[: len(u.outbox)]
        for j, m in enumerate(queued):
            u.outbox[j] = to_frame(m)
        u.n_outbox = len(queued)
        node._outbox = []
        for t, (a, b, c, e) in node.duties.items():
            slot = u.duties[t % RING]
            slot.d[0], slot.d[1], slot.d[2], slot.en, slot.tag = a, b, c, int(e), t
        (a, b, c, e), t = node.applied
        ap = u.applied
        ap.d[0], ap.d[1], ap.d[2], ap.en, ap.tag = a, b, c, int(e), t
        for j in range(RING):
            u.faults.released[j] = NOT_HELD
        for t, at in node.released_at.items():
            u.faults.released[t % RING] = round(at * 1e9)
        self.push_commands()

    def push_commands(self, changed: bool = True) -> None:
        """The queue's state to C; ``changed=False``: its pending list is C's but for what C
        applied (a command frame the queue took as a repeat): the scalars only, not the
        list (sorting and copying 500 pending commands took 55 us, half a 10 kHz period)."""
        node, u = self.node, self.u
        q = node.commands
        if changed:
            pending = sorted(q.pending.items())
            head = pending[:CMDS]
            if head:
                v = self.cmds[: len(head)]
                v["step"] = [s for s, _ in head]
                v["cmd"] = [c.cmd for _, c in head]
                v["seq"] = [c.seq for _, c in head]
                v["load_nm"] = [c.load_nm for _, c in head]
            u.n_cmds = min(len(pending), CMDS)
            u.cmds_more = int(len(pending) > CMDS)
        u.applied_seq = q.applied_seq
        u.applied_upto = q.applied_upto
        u.cmd_horizon = node.cmd_horizon
        u.ctrl_ack = -1 if node.ctrl_ack is None else node.ctrl_ack

    def pull_poll(self) -> None:
        """What a poll of a real-time loop reads (its trip line and the rejected-duty
        summary): the fault and the duties rejected.  :meth:`pull` takes the rest at
        the next event and at the end; the whole of it in the slack of a 10 kHz period
        took longer than the period."""
        node, u = self.node, self.u
        node.fault, node.fault_step = u.fault, u.fault_step
        for j, reason in enumerate(self.reasons):
            n = int(u.duty_rejected[j]) - self.seen_duty_rej[j]
            self.seen_duty_rej[j] += n
            if n:
                node.duty_rejected[reason] = node.duty_rejected.get(reason, 0) + n

    def push_newest(self) -> None:
        """The queue's state to C after it took one command beyond every other it knew
        (``node.cmd_horizon``): that command goes to the end of C's list, or stays with
        the ones Python holds beyond it; the list is not rewritten."""
        node, u = self.node, self.u
        s = node.cmd_horizon
        if u.cmds_more or u.n_cmds >= CMDS:
            u.cmds_more = 1
        else:
            c = node.commands.pending[s]
            v = self.cmds[u.n_cmds]
            v["step"], v["cmd"], v["seq"], v["load_nm"] = s, c.cmd, c.seq, c.load_nm
            u.n_cmds += 1
        self.push_commands(changed=False)

    def pull_command(self) -> None:
        """What a command frame's handling in a real-time loop reads: the poll's, the plant's
        step (the command's unwrap), the commands C applied and the start and stop.
        :meth:`pull` takes the rest at the next event and at the end."""
        node, u = self.node, self.u
        self.pull_poll()
        node.plant.adopt_core(u.k, u.meas_k)
        if u.applied_upto >= 0:
            node.commands.due(u.applied_upto)  # the ones C applied
        node.started, node.stopped = bool(u.started), bool(u.stopped)

    def pull(self) -> None:
        from bench.nodes._plant_node import fault_name

        node, u = self.node, self.u
        self.pull_command()
        node.dut_answered = bool(u.dut_answered)
        node.last_duty_k, node.rounds_waiting = u.last_duty_k, u.rounds_waiting
        node.latest_duty_step = u.latest_duty_step
        node.dropped_upto = u.dropped_upto
        node.latest_duty = (u.latest[0], u.latest[1], u.latest[2], bool(u.latest_en))
        node.duty_age = u.duty_age
        live = self.duties[self.duties["tag"] >= 0]  # in slot order, as the ring
        node.duties = {
            t: (d[0], d[1], d[2], bool(e))
            for t, d, e in zip(
                live["tag"].tolist(), live["d"].tolist(), live["en"].tolist(), strict=True
            )
        }
        ap = u.applied
        node.applied = ((ap.d[0], ap.d[1], ap.d[2], bool(ap.en)), int(ap.tag))
        node.released_at = {
            int(s.tag): u.faults.released[j] * 1e-9
            for j, s in enumerate(u.duties)
            if s.tag >= 0 and u.faults.released[j] != NOT_HELD
        }
        c = node.counters
        delta = {}
        for name in _COUNTERS:
            v = int(getattr(u, name))
            delta[name] = v - self.seen[name]
            self.seen[name] = v
        c.frames_accepted += delta["accepted"]
        c.late_duties += delta["late_duties"]
        c.retransmits += delta["retransmits"]
        c.overruns += delta["overruns"]
        c.send_errors += delta["send_errors"]
        c.frames_lost_on_send += delta["frames_lost_on_send"]
        node.resets += delta["resets"]
        for j, reason in enumerate(self.reasons):
            n = int(u.rejected[j]) - self.seen_rej[j]
            self.seen_rej[j] += n
            for _ in range(n):
                c.reject(reason)
        for code in range(8):
            n = int(u.trips[code]) - self.seen_trips[code]
            self.seen_trips[code] += n
            if n:
                name = fault_name(code)
                node.trips[name] = node.trips.get(name, 0) + n


def noise_values(plant: Any) -> Iterator[float]:
    """The values the plant's sensors take from its generator, in their order.

    ``plant_sensors_measure`` (``plant_rt/core/plant_sensors.c``) calls the
    generator of :class:`plant_rt._sensors.Sensors` once per phase current
    (with ``noise_i > 0``), then once for the DC-link voltage (``noise_u > 0``),
    as ``gauss(0.0, sd)``; this iterator makes the same calls on the same
    generator, so the native run's samples are the Python node's.
    """
    sp = plant.sensor_pars
    gauss = plant.noise_generator().gauss
    while True:
        if sp.noise_i > 0.0:
            yield gauss(0.0, sp.noise_i)
            yield gauss(0.0, sp.noise_i)
            yield gauss(0.0, sp.noise_i)
        if sp.noise_u > 0.0:
            yield gauss(0.0, sp.noise_u)


class NoiseDraws:
    """The noise values of a native run, drawn before it (``bn_plant_noise_t``).

    One set per sample the loop will measure (instants ``k`` to ``n_steps``);
    after the run the generator is put where the Python node's would be: at
    its state before the draws, advanced by the values the run used.
    """

    def __init__(self, node: Any, u: Unit) -> None:
        import itertools

        plant = node.plant
        sp = plant.sensor_pars
        self.plant = plant
        self.active = sp.noise_i > 0.0 or sp.noise_u > 0.0
        self.u = u
        if not self.active:
            return
        per = (3 if sp.noise_i > 0.0 else 0) + (1 if sp.noise_u > 0.0 else 0)
        n = (node.n_steps - plant.k + 1) * per
        self.state = plant.noise_generator().getstate()
        self.buf = (ctypes.c_double * n)(*itertools.islice(noise_values(plant), n))
        u.noise.draws = ctypes.cast(self.buf, ctypes.POINTER(ctypes.c_double))
        u.noise.n, u.noise.used = n, 0

    def restore(self) -> None:
        """The generator as the Python node would leave it."""
        import itertools

        if not self.active:
            return
        self.plant.noise_generator().setstate(self.state)
        for _ in itertools.islice(noise_values(self.plant), int(self.u.noise.used)):
            pass


#: The sensor fault kinds of :class:`plant_rt._faults.PlantFaults` as ``BN_SF_*`` (bn_plant.h).
_SENSOR_CODES = {
    "current_offset": 0,
    "current_gain": 1,
    "current_stuck": 2,
    "current_lost": 3,
    "dc_voltage_offset": 4,
    "position_sensor_lost": 5,
}
#: The parameter each sensor kind applies (``BN_SF_*``'s ``value``).
_SENSOR_VALUE = {"current_offset": "a", "current_gain": "factor", "dc_voltage_offset": "v"}
#: The bus fault kinds (:mod:`bench.nodes._fault_bus`), applied from NativeFaults' tables.
BUS_KINDS = ("drop", "delay", "corrupt", "silence", "babble")
#: The fault kinds the native node applies: every kind of the timeline.
NATIVE_FAULT_KINDS = (*MACHINE_KINDS, *LEG_KINDS, *SENSOR_KINDS, *BUS_KINDS)


class NativeFaults:
    """The scenario's plant and sensor faults as the unit's tables (``bn_plant_faults_t``).

    The edges are :class:`plant_rt._faults.PlantFaults`'s own answers
    (:meth:`~plant_rt._faults.PlantFaults.parameters`,
    :meth:`~plant_rt._faults.PlantFaults.leg_faults`) at every window's start
    and end, kept where they change, as its ``before_period`` applies them.
    """

    def __init__(self, node: Any, u: Unit) -> None:
        from plant_rt._plant import LEG_FAULTS

        nf = node.faults
        self.nf = nf
        if nf is None:
            return
        pf = nf.plant
        plant = node.plant
        nominal = plant._core_pars()
        state, legs = (pf.R_s, pf.psi_f, pf.u_dc), ("none", "none", "none")
        edges: list[Edge] = []
        ends = {w.k1 for w in pf.windows if w.k1 is not None}
        for k in sorted({w.k0 for w in pf.windows} | ends):
            now, now_legs = pf.parameters(k), pf.leg_faults(k)
            if now == state and now_legs == legs:
                continue
            e = Edge()
            e.k = k
            if now != state:
                R, psi, u_src = now
                e.set_pars = 1
                e.pars = PlantPars.of(nominal)
                e.pars.machine.R_s, e.pars.machine.psi_f, e.pars.u_dc = R, psi, u_src
            if now_legs != legs:
                e.set_legs = 1
                for x in range(3):
                    e.leg[x] = LEG_FAULTS.index(now_legs[x])
            edges.append(e)
            state, legs = now, now_legs
        self.edges = (Edge * max(1, len(edges)))(*edges)
        sensor = []
        for w in pf.sensor:
            f = SensorFault()
            f.kind = _SENSOR_CODES[w.kind]
            f.phase = "abc".index(str(w.params.get("phase", "a")))
            f.k0, f.k1 = w.k0, -1 if w.k1 is None else w.k1
            if w.kind in _SENSOR_VALUE:
                f.value = float(w.params[_SENSOR_VALUE[w.kind]])
            sensor.append(f)
        self.sensor = (SensorFault * max(1, len(sensor)))(*sensor)
        F = u.faults
        F.on = 1
        F.n_edges, F.next_edge, F.n_sensor = len(edges), 0, len(sensor)
        F.edges = ctypes.cast(self.edges, ctypes.POINTER(Edge))
        F.sensor = ctypes.cast(self.sensor, ctypes.POINTER(SensorFault))
        F.last_k = -1
        for h in F.history:
            h.tag = -1
        self._bus_tables(node, F)
        self.seen = [0, 0, 0, 0]

    def _bus_tables(self, node: Any, F: Faults) -> None:
        """NodeFaults' answers for every instant the run can ask (``bn_plant_faults_t``)."""
        nf = self.nf
        assert nf is not None
        kinds = {f.kind for f, _ in nf.windows}
        if not kinds & {*BUS_KINDS, "position_sensor_lost"}:  # the ones NodeFaults answers
            return
        n = node.n_steps + node.delay + 2
        F.n_k = n
        self.clock_ns = node_clock_ns(node)  # kept alive while C may call it
        F.clock_ns = self.clock_ns
        # outside every window each answer is "no fault": only the windows' instants are asked
        inside = sorted(
            {
                k
                for f, w in nf.windows
                if f.kind in (*BUS_KINDS, "position_sensor_lost")
                for k in range(max(0, w.k0), min(n, n if w.k1 is None else w.k1))
            }
        )
        fate = (ctypes.c_int8 * n)()
        code = {"lost": 1, "corrupt": 2}
        for k in inside:
            f = nf.duty_fate(k)
            if f is not None:
                fate[k] = code[f]
        self.fate = fate
        F.fate = ctypes.cast(fate, ctypes.POINTER(ctypes.c_int8))
        if "delay" in kinds:
            self.shift_ls, self.shift_rt = (_I32 * n)(), (_I32 * n)()
            self.hold_ns = (_I64 * n)()
            for k in inside:
                self.shift_ls[k] = nf.duty_shift(k)
                self.shift_rt[k] = nf.duty_shift(k, realtime=True)
                self.hold_ns[k] = round(nf.duty_hold_s(k) * 1e9)
            F.shift_ls = ctypes.cast(self.shift_ls, ctypes.POINTER(_I32))
            F.shift_rt = ctypes.cast(self.shift_rt, ctypes.POINTER(_I32))
            if any(self.hold_ns[k] for k in inside):
                F.hold_ns = ctypes.cast(self.hold_ns, ctypes.POINTER(_I64))
        # sends() and babble() count what they did: asked here, their counts are C's
        not_sent, babbled = dict(nf.not_sent), nf.babbled
        nosend = (ctypes.c_uint8 * n)()
        babble: list[Babble] = []
        for k in inside:
            ps = nf.sends("PhaseSamples", k)
            pos = nf.sends("PositionSensor", k)
            nosend[k] = (0 if ps else 1) | (0 if pos else 2)
            to_plant, to_ctrl = nf.babble(k, node.codec)
            if to_plant is not None and to_ctrl is not None:
                babble.append(Babble(k, to_frame(to_plant), to_frame(to_ctrl)))
        nf.not_sent, nf.babbled = not_sent, babbled
        if not node.realtime:
            # lockstep: each PhaseSamples lost on its first sending is kept to be sent again
            # (PlantNode.withheld): room for every one the table loses
            n_lost = sum(nosend[k] & 1 for k in inside)
            if n_lost:
                self.withheld = (Frame * n_lost)()
                F.withheld = ctypes.cast(self.withheld, ctypes.POINTER(Frame))
                F.wh_cap = n_lost
        self.nosend = nosend
        F.nosend = ctypes.cast(nosend, ctypes.POINTER(ctypes.c_uint8))
        self.babble = (Babble * max(1, len(babble)))(*babble)
        F.babble = ctypes.cast(self.babble, ctypes.POINTER(Babble))
        F.n_babble, F.next_babble = len(babble), 0

    def pull(self, u: Unit, plant: Any) -> None:
        """The node's fault report: duties lost, frames not sent, frames babbled."""
        nf = self.nf
        if nf is None:
            return
        F = u.faults
        now = [int(F.duties_lost), int(F.not_sent[0]), int(F.not_sent[1]), int(F.babbled)]
        d = [a - b for a, b in zip(now, self.seen, strict=True)]
        self.seen = now
        nf.duties_lost += d[0]
        for msg, n in (("PhaseSamples", d[1]), ("PositionSensor", d[2])):
            if n:
                nf.not_sent[msg] = nf.not_sent.get(msg, 0) + n
        nf.babbled += d[3]

    def finish(self, plant: Any) -> None:
        """The Python plant's parameters and legs as the core has them at its present instant."""
        if self.nf is not None:
            self.nf.plant.before_period(plant)


def node_clock_ns(node: Any) -> Any:
    """``bn_plant_faults_t.clock_ns`` for ``node``: NULL while its clock is ``time.time``
    (CLOCK_REALTIME, which C reads itself), else its clock in ns (a test's fake clock)."""
    if node.clock is time.time:
        return CLOCK_NS()
    clock = node.clock
    return CLOCK_NS(lambda: round(clock() * 1e9))


def _fill_config(dll: ctypes.CDLL, node: Any, u: Unit, realtime: bool, external: bool) -> None:
    codec = node.codec
    plant = node.plant
    u.pl = plant.core_address()
    u.n_steps = node.n_steps
    u.delay = node.delay
    u.truth_every = node.truth_every
    u.status_every = node.status_every
    u.encoder_every = node.encoder_every
    u.encoder_delay_s = float(plant.sensor_pars.encoder_delay_s)
    u.encoder_counts = int(plant.sensor_pars.encoder_counts)
    if node.protection is not None:
        pp = node.protection.pars
        u.prot.i_trip, u.prot.u_dc_trip, u.prot.w_m_trip = pp.i_trip, pp.u_dc_trip, pp.w_m_trip
        u.has_prot = 1
    u.watchdog_periods = node.watchdog_periods
    u.watchdog_rounds = node.watchdog_rounds
    u.realtime = int(realtime)
    u.external = int(external)
    u.run_id = node.run_id
    u.m_samples, u.m_truth, u.m_status, u.m_step = (
        node.m_samples,
        node.m_truth,
        node.m_status,
        node.m_step,
    )
    u.pace_every = node.pace_every
    tables: dict[str, dict[str, tuple[float, ...]]] = {}
    names = dll.bn_plant_signal_names().decode().split(",")
    for j, full in enumerate(names):
        msg, sig = full.split(".")
        if msg not in tables:
            tables[msg] = codec.signal_table(msg)
        lo, hi, scale, offset, mod, chk_lo, chk_hi = tables[msg][sig]
        s = u.sig[j]
        s.lo, s.hi, s.scale, s.offset = lo, hi, scale, offset
        s.modulus, s.chk_lo, s.chk_hi = int(mod), chk_lo, chk_hi
    msgs = ("PhaseSamples", "PositionSensor", "PlantTruth", "PlantStatus", "PlantCurrents")
    for j, msg in enumerate(msgs):
        fd, brs = codec.frame_kind(msg)
        u.msg_flags[j] = (BN_FD if fd else 0) | (BN_BRS if brs else 0)


def _jitter(
    dll: ctypes.CDLL,
    loop: Loop,
    busy: ctypes.Array[ctypes.c_uint32],
    late: ctypes.Array[ctypes.c_uint32],
    parts: ctypes.Array[ctypes.c_uint32],
) -> dict[str, float]:
    """The Python node's ``jitter`` (:class:`bench.nodes._clock.JitterStats`, us) of the run,
    and the native loop's split of the busy time: ``send_median`` (the instant's frames out),
    ``recv_median`` (draining the socket, checking and decoding what came) and
    ``step_median`` (the model's step and the next frames' encoding), each period's, us."""
    import numpy as np

    st = Stats()
    dll.bn_clock_stats(ctypes.byref(loop.clock), ctypes.byref(st))  # sorts the busy buffer
    n_busy = int(min(st.periods, loop.busy_cap))
    b = np.frombuffer(memoryview(busy), dtype=np.uint32, count=n_busy).astype(float) * 1e-3
    lt = (
        np.frombuffer(memoryview(late), dtype=np.uint32, count=int(loop.n_late)).astype(float)
        * 1e-3
    )
    stall = lt[lt > 1e-3 * loop.stall_ns]
    cap = int(loop.busy_cap)
    raw = np.frombuffer(memoryview(parts), dtype=np.uint32, count=3 * cap).reshape(3, cap)
    pt = raw[:, :n_busy].astype(float) * 1e-3

    def q(x: Any, p: float) -> float:
        return float(np.quantile(x, p)) if len(x) else 0.0

    return {
        "n": float(st.periods),
        "median": q(lt, 0.5),
        "p99": q(lt, 0.99),
        "max": float(lt.max()) if len(lt) else 0.0,
        "busy_median": q(b, 0.5),
        "busy_p99": q(b, 0.99),
        "busy_max": float(b.max()) if len(b) else 0.0,
        "send_median": q(pt[0], 0.5),
        "recv_median": q(pt[1], 0.5),
        "step_median": q(pt[2], 0.5),
        "stalls": float(st.stalls),
        "stall_total": float(stall.sum()),
        "stall_max": float(stall.max()) if len(stall) else 0.0,
        "skipped": float(st.skipped),
        # command frames held from a period's receive to its slack, the most at once, and
        # the ones handed over at once by a full ring (bn_held_t)
        "commands_held": float(loop.held.total),
        "commands_held_max": float(loop.held.max),
        "commands_held_full": float(loop.held.full),
    }


def plant_loop_native(
    spec: Any,
    node: Any,
    *,
    realtime: bool,
    on_ready: Callable[[], None] | None = None,
    stop: Callable[[], bool] = lambda: False,
    watchdog_s: float,
    dut_timeout_s: float = 0.0,
    retransmit_s: float,
    bus: NativeBus | None = None,
) -> None:
    """:func:`bench.nodes._loops.plant_loop` with the loop in C (module docstring).

    ``bus``: the native bus, opened by the caller (:func:`open_native_bus`)
    where the Python node opens its own, so that it holds every frame sent
    from then on (a command sent before the node is ready included); closed
    here.  The node's python-can bus stays open beside it and is not read.
    """
    from bench.nodes._clock import default_spin_s, default_stall_s
    from bench.nodes._plant_text import (
        LAST_ANSWER_S,
        STATE_DONE,
        PlantDiagnostics,
        stall_text,
        trip_text,
        tripped_text,
    )

    dll = _lib()
    node.realtime = realtime
    node.external = dut_timeout_s > 0
    codec = node.codec
    names = ["PwmDuty", "BenchCommand"]
    if node.external and not realtime:
        names.append("CtrlTelemetry")
    ids = {codec.frame_id(n) for n in names}
    if bus is None:
        bus = NativeBus(dll, spec)
    try:
        # what Python hands over once, made before the node says it is ready (seconds for a
        # long run with faults; none of it waits for the start command)
        u = Unit()
        noise = NoiseDraws(node, u)
        faults = NativeFaults(node, u)
        if on_ready:
            on_ready()
        t_idle = time.monotonic()
        while not node.started:  # _wait_for_start, on the native bus
            if stop():
                noise.restore()
                return
            f = bus.recv(0.05)
            if f is not None and f.id in ids and not f.flags & BN_EXT:
                node.on_message(to_message(f))
                node.apply_commands()
            if time.monotonic() - t_idle > 3600.0:
                raise BenchError("plant: no start command within an hour")
        _fill_config(dll, node, u, realtime, node.external)
        reasons = dll.bn_plant_reject_names().decode().split(",")
        sync = _Sync(node, u, reasons)
        sync.push_all()
        loop = Loop()
        loop.u = ctypes.pointer(u)
        loop.bus = bus.ptr
        loop.ids[0] = codec.frame_id("PwmDuty")
        for j, name in enumerate(names[1:]):
            loop.ids[j + 1] = codec.frame_id(name)
            loop.event_ids[j] = codec.frame_id(name)
        # the copies of the bench commands Python took are dropped in C (bn.h)
        seen = ctypes.byref(loop.cmd_seen)
        dll.bn_cmd_seen_init(seen, codec.frame_id("BenchCommand"), copy_span(node.commands.modulus))
        loop.retransmit_s = retransmit_s
        loop.stall_s = watchdog_s
        loop.first_s = dut_timeout_s
        loop.poll_s = 0.2
        loop.last_answer_s = LAST_ANSWER_S
        busy: ctypes.Array[ctypes.c_uint32] | None = None
        late: ctypes.Array[ctypes.c_uint32] | None = None
        parts: ctypes.Array[ctypes.c_uint32] | None = None
        if realtime:
            T = node.plant.T_s
            n = max(1, node.n_steps if node.n_steps > 0 else 1_000_000)
            busy = (ctypes.c_uint32 * n)()
            loop.period_ns = round(T * 1e9)
            loop.busy_tail_ns = round(default_spin_s(T) * 1e9)
            loop.stall_ns = round(default_stall_s(T) * 1e9)
            loop.busy = ctypes.cast(busy, ctypes.POINTER(ctypes.c_uint32))
            loop.busy_cap = n
            late = (ctypes.c_uint32 * n)()
            loop.late = ctypes.cast(late, ctypes.POINTER(ctypes.c_uint32))
            loop.late_cap = n
            parts = (ctypes.c_uint32 * (3 * n))()
            loop.parts = ctypes.cast(parts, ctypes.POINTER(ctypes.c_uint32))
            # a command frame met before a step goes to Python after it while half a
            # period is left: Python's handling of one took 10-26 us (docs/REALTIME.md)
            loop.held_margin_ns = loop.period_ns // 2
        diag = PlantDiagnostics(node)
        t_loop = time.perf_counter()
        said_fault = node.fault
        try:
            while True:
                ev = dll.bn_plant_loop(ctypes.byref(loop))
                if ev == EV_POLL and realtime:
                    sync.pull_poll()
                elif ev == EV_FRAME and realtime:
                    sync.pull_command()  # in the slack of a period (bn_plant_loop.c)
                else:
                    sync.pull()
                    faults.pull(u, node.plant)
                if node.fault != said_fault:
                    said_fault = node.fault
                    if node.fault:
                        print(f"plant: {trip_text(node.fault, node.fault_step)}", file=sys.stderr)
                        diag.fault = node.fault
                if ev == EV_DONE:
                    break
                if ev == EV_FRAME:
                    n_pending, horizon = len(node.commands.pending), node.cmd_horizon
                    taken = node.commands.taken
                    node.on_message(to_message(loop.ev_frame))
                    if node.commands.taken != taken:
                        dll.bn_cmd_seen_take(seen, ctypes.byref(loop.ev_frame), u.k)
                    if len(node.commands.pending) == n_pending:
                        sync.push_commands(changed=False)  # a repeat, or no command
                    elif node.cmd_horizon > horizon and node.cmd_horizon in node.commands.pending:
                        sync.push_newest()
                    else:
                        sync.push_commands()
                elif ev == EV_CMDS:
                    sync.push_commands()
                elif ev == EV_POLL:
                    diag.poll()
                    if stop():
                        break
                elif ev == EV_STALL:
                    what = loop.stall_what
                    if what == WAIT_DUTY:
                        limit = (
                            dut_timeout_s
                            if dut_timeout_s > 0 and not node.dut_answered
                            else watchdog_s
                        )
                        raise BenchError(f"plant: {stall_text(node, limit)}")
                    if what == WAIT_COMMAND:
                        raise BenchError(
                            f"plant: no bench command for step {node.plant.k} in {watchdog_s:.0f} s "
                            "(paced by bench run: has its recorder stopped?)"
                        )
                    raise BenchError(
                        f"plant: the controller has not acknowledged BenchCommand seq "
                        f"{node.needed_ack()} (needed for sample {node.plant.k + 1}) in "
                        f"{watchdog_s:.0f} s; its newest CtrlTelemetry.cmd_ack is {node.ctrl_ack}"
                    )
                elif ev == EV_TRIPPED:
                    print(f"plant: {tripped_text(node, loop.t_progress * 1e-9)}", file=sys.stderr)
                    break
                else:
                    raise BenchError(f"plant: native loop: {os.strerror(-loop.err)}")
        finally:
            # in real time from the clock's start: a controller under test's first answer,
            # which the plant waits for before it (up to --dut-timeout), is start-up
            node.loop_s = (
                (time.monotonic_ns() - loop.clock.t0_ns) * 1e-9
                if realtime and loop.rt_started
                else time.perf_counter() - t_loop
            )
            node.counters.reject(REPEATED_COUNTER, int(loop.cmd_seen.copies))
            if realtime and loop.rt_started and busy and late and parts:
                u.overruns = loop.clock.st.missed  # also when a stop ended the loop
                node.jitter = _jitter(dll, loop, busy, late, parts)
            sync.pull()
            faults.pull(u, node.plant)
            faults.finish(node.plant)
            noise.restore()
            diag.poll(force=True)
        final = to_frame(node.status_frame(STATE_DONE, node.fault))
        dll.bn_plant_send(ctypes.byref(u), bus.ptr, ctypes.byref(final))
        sync.pull()  # its send errors
    finally:
        bus.close()
