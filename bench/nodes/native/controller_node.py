"""The native controller node: the per-period loop of :class:`ControllerNode` in C.

Python keeps the set-up and the report: it builds the node (the plan's
:class:`controller.Controller` on the compiled engine), then hands the loop to
one ctypes call, ``bn_ctl_serve`` (``bn_ctl.c``, GIL released), which receives,
checks, steps the controller core Python built (the same ``cc_foc_t`` and
supervision, by address), encodes and sends, period after period.  It returns
only for what stays Python's:

- a ``BenchCommand`` frame (the rules of :class:`bench.nodes._counters.CommandQueue`
  have one home): Python queues it and hands the pending list to C, which applies
  each command at its step to the core (``bn_ctl_apply_commands``, the rule the
  in-process pair shares; the Python node keeps :meth:`ControllerNode._apply_commands`
  for the Python loop); Python takes back what C applied at its next event
  (:meth:`NativeController.pull_commands`), and is called again when the list
  handed over runs dry with more pending (``EV_CMDS``); the copies of a command
  Python took (each comes three times) are dropped in C and counted as the repeats
  they are there (``bn_cmd_seen_t``, bn.h);
- a real-time sample timeout (:meth:`ControllerNode.sample_timeout`);
- the end: a stop command ran, ``idle_s`` without a frame, or a stop of the
  process. Python's signal handlers run between two calls: a signal ends the
  C wait (``EINTR``), and the call returns at the latest every
  :data:`RETURN_S` for Python to look at its stop flag.

After the run the C counters join the Python node's, so :meth:`ControllerNode.report`
reports what it reports for the Python loop, with ``node_engine = "native"``.
:func:`native_unavailable` says why a node cannot run native, in one line
(:func:`bench.cli._common.choose_node_engine`: ``auto`` then runs the Python
node, ``--engine native`` is refused).
"""

from __future__ import annotations

import ctypes
import os
from collections.abc import Callable
from typing import Any

import can

from bench._errors import BenchError
from bench.nodes._controller_node import ControllerNode
from bench.nodes._counters import (
    REJECT_FUTURE_COUNTER,
    REJECT_STALE_COUNTER,
    REPEATED_COUNTER,
)
from bench.nodes.native import _native
from bench.nodes.native._native import (
    BN_BRS,
    BN_ERR,
    BN_EXT,
    BN_FD,
    BN_RTR,
    Frame,
    Held,
    Sig,
    copy_span,
)
from bench.wire._codec import (
    REJECT_BAD_CRC,
    REJECT_BAD_LENGTH,
    REJECT_DECODE_ERROR,
    REJECT_OUT_OF_RANGE,
)
from bench.wire._protocol import RPM_PER_RAD_S

__all__ = [
    "RETURN_S",
    "CtlBlock",
    "Frame",
    "NativeController",
    "native_controller_loop",
    "native_library",
    "native_unavailable",
]

#: The longest a ``bn_ctl_serve`` call runs before Python looks at its stop flag (s): a
#: stop asked from another thread (no signal) is seen within it, as the Python loop's
#: 50 ms receive poll does.
RETURN_S = 0.05
#: The transports the native loop speaks (python-can's interface names).
NATIVE_INTERFACES = ("udp_multicast", "socketcan")
_INT64_MAX = (1 << 63) - 1

# events (bn_ctl.h)
EV_NONE, EV_COMMAND, EV_CMDS, EV_STOPPED, EV_IDLE, EV_TIMEOUT, EV_POLL, EV_ERROR = range(8)
# bn_frame_t flags (bn.h)
#: The rejection reasons, in the order of bn_ctl.h's BN_CTL_R_*.
REASONS = (
    REJECT_BAD_LENGTH,
    REJECT_DECODE_ERROR,
    REJECT_BAD_CRC,
    REJECT_OUT_OF_RANGE,
    REJECT_STALE_COUNTER,
    REJECT_FUTURE_COUNTER,
    REPEATED_COUNTER,
)
#: The output signals, in the order of bn_ctl.h's BN_CTL_* (message, signal).
SIGNALS = (
    ("PwmDuty", "duty_a"),
    ("PwmDuty", "duty_b"),
    ("PwmDuty", "duty_c"),
    ("PwmDuty", "enable"),
    ("PwmDuty", "step"),
    ("CtrlTelemetry", "theta_hat"),
    ("CtrlTelemetry", "w_hat"),
    ("CtrlTelemetry", "err"),
    ("CtrlTelemetry", "mode"),
    ("CtrlTelemetry", "step"),
    ("CtrlTelemetry", "run_id"),
    ("CtrlTelemetry", "cmd_ack_valid"),
    ("CtrlTelemetry", "cmd_ack"),
)


class Out(ctypes.Structure):
    """``cc_out_t`` (controller/core/cc_foc.h)."""

    _fields_ = [
        ("k", ctypes.c_longlong),
        ("d_a", ctypes.c_double),
        ("d_b", ctypes.c_double),
        ("d_c", ctypes.c_double),
        ("enable", ctypes.c_int),
        ("theta_hat", ctypes.c_double),
        ("w_hat", ctypes.c_double),
        ("err", ctypes.c_double),
        ("mode", ctypes.c_longlong),
        ("i_d", ctypes.c_double),
        ("i_q", ctypes.c_double),
    ]


class Counts(ctypes.Structure):
    """``bn_ctl_counts_t``."""

    _fields_ = [
        ("frames_accepted", ctypes.c_uint64),
        ("frames_unknown", ctypes.c_uint64),
        ("reasons", ctypes.c_uint64 * len(REASONS)),
        ("samples_accepted", ctypes.c_uint64),
        ("send_errors", ctypes.c_uint64),
        ("frames_lost_on_send", ctypes.c_uint64),
        ("steps", ctypes.c_uint64),
    ]


#: Pending commands the C list holds (bn_ctl.h's BN_CTL_CMDS).
CMDS = 256


class CtlCmd(ctypes.Structure):
    """``bn_ctl_cmd_t`` (bn_ctl.h)."""

    _fields_ = [
        ("step", ctypes.c_int64),
        ("cmd", ctypes.c_int32),
        ("seq", ctypes.c_int32),
        ("speed_ref_rpm", ctypes.c_double),
    ]


class CtlBlock(ctypes.Structure):
    """The head of ``bn_ctl_t`` up to its counters (bn_ctl.h, field by field); the rest
    (the loop's state and rings) is C's alone. ``bn_ctl_prefix_size`` checks the layout."""

    _fields_ = [
        ("foc", ctypes.c_void_p),
        ("sup", ctypes.c_void_p),
        ("needs_truth", ctypes.c_int32),
        ("realtime", ctypes.c_int32),
        ("n_p", ctypes.c_double),
        ("m_step", ctypes.c_int64),
        ("m_truth", ctypes.c_int64),
        ("m_tel", ctypes.c_int64),
        ("sample_lead", ctypes.c_int64),
        ("truth_lead", ctypes.c_int64),
        ("sig", Sig * len(SIGNALS)),
        ("duty_flags", ctypes.c_uint8),
        ("tel_flags", ctypes.c_uint8),
        ("run_id", ctypes.c_uint32),
        ("rpm_per_rad_s", ctypes.c_double),
        ("ack_seq", ctypes.c_int32),
        ("send_ack", ctypes.c_int32),
        ("stopped", ctypes.c_int32),
        ("faulted", ctypes.c_int32),
        ("n_cmds", ctypes.c_int32),
        ("cmds_more", ctypes.c_int32),
        ("applied_seq", ctypes.c_int32),
        ("has_w_ref", ctypes.c_int32),
        ("applied_upto", ctypes.c_int64),
        ("w_m_ref", ctypes.c_double),
        ("idle_ns", ctypes.c_int64),
        ("sample_timeout_ns", ctypes.c_int64),
        ("poll_ns", ctypes.c_int64),
        ("return_ns", ctypes.c_int64),
        ("next_k", ctypes.c_int64),
        ("error", ctypes.c_int32),
        ("has_last", ctypes.c_int32),
        ("last", Out),
        ("cmd_frame", Frame),
        ("c", Counts),
        ("cmds", CtlCmd * CMDS),
        ("held", Held),
        ("slack", ctypes.c_int32),
    ]


SINK = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.POINTER(Frame))


_DECLARED: list[ctypes.CDLL] = []


def native_library() -> ctypes.CDLL:
    """The native library (:func:`._native.library`: built once per source change into the
    user's cache) with the controller unit's calls declared; :class:`BenchError` when it
    cannot be built."""
    dll = _native.library()
    if not _DECLARED:
        _declare(dll)
        _DECLARED.append(dll)
    return dll


def _declare(dll: ctypes.CDLL) -> None:
    vp = ctypes.c_void_p
    dll.bn_ctl_size.restype = ctypes.c_size_t
    dll.bn_ctl_bus_size.restype = ctypes.c_size_t
    dll.bn_ctl_prefix_size.restype = ctypes.c_size_t
    dll.bn_ctl_reset.argtypes = [vp]
    dll.bn_ctl_reset.restype = None
    dll.bn_ctl_on_frame.argtypes = [vp, ctypes.POINTER(Frame), SINK, vp]
    dll.bn_ctl_on_frame.restype = ctypes.c_int
    dll.bn_ctl_resume.argtypes = [vp, SINK, vp]
    dll.bn_ctl_resume.restype = ctypes.c_int
    dll.bn_ctl_serve.argtypes = [vp, vp]
    dll.bn_ctl_serve.restype = ctypes.c_int
    dll.bn_udp_open.argtypes = [vp, ctypes.c_char_p, ctypes.c_uint16, ctypes.c_int]
    dll.bn_udp_open.restype = ctypes.c_int
    dll.bn_can_open.argtypes = [vp, ctypes.c_char_p, ctypes.c_bool]
    dll.bn_can_open.restype = ctypes.c_int
    dll.bn_close.argtypes = [vp]
    dll.bn_close.restype = None
    dll.bn_ctl_cmd_seen_init.argtypes = [vp, ctypes.c_uint32, ctypes.c_int64]
    dll.bn_ctl_cmd_seen_init.restype = None
    dll.bn_ctl_cmd_taken.argtypes = [vp, ctypes.POINTER(Frame)]
    dll.bn_ctl_cmd_taken.restype = None
    dll.bn_ctl_cmd_copies.argtypes = [vp]
    dll.bn_ctl_cmd_copies.restype = ctypes.c_uint64


def native_unavailable(node: ControllerNode, interface: str | None) -> str | None:
    """None when ``node`` can run native on ``interface`` (None: no transport, in-process),
    else one line saying why not (:func:`bench.cli._common.choose_node_engine` says what
    follows: the Python node, or a refusal)."""
    ctrl = node.ctrl
    if ctrl._core is None:  # a controller without the core: the tests' oracle
        return "the native controller node needs the controller's core"
    if ctrl.external_estimator:
        return f"the {ctrl.pars.estimator} estimator is Python code, which needs the Python process"
    if interface is not None and interface not in NATIVE_INTERFACES:
        return f"--interface {interface}: the native loop speaks {' and '.join(NATIVE_INTERFACES)}"
    try:
        native_library()
    except BenchError as e:
        return str(e)
    return None


class NativeController:
    """The C block of one :class:`ControllerNode` (module docstring)."""

    def __init__(self, node: ControllerNode, *, realtime: bool) -> None:
        if node.ctrl._core is None:
            raise BenchError("native controller node: the controller has no compiled core")
        self.node = node
        self.dll = dll = native_library()
        self._mem = ctypes.create_string_buffer(int(dll.bn_ctl_size()))
        if ctypes.sizeof(CtlBlock) != dll.bn_ctl_prefix_size():
            raise BenchError("native controller node: bn_ctl_t and its Python mirror differ")
        self.ctl = CtlBlock.from_buffer(self._mem)
        self.addr = ctypes.addressof(self._mem)
        dll.bn_ctl_reset(self.addr)
        c = self.ctl
        foc, sup = node.ctrl._core.address()
        c.foc, c.sup = foc, sup or None
        c.needs_truth = int(node.needs_truth)
        c.realtime = int(realtime)
        node.realtime = realtime
        c.n_p = float(node.ctrl.pars.motor.n_p)
        c.m_step, c.m_truth, c.m_tel = node.m_step, node.m_truth, node.m_tel
        s_lead, t_lead = node.sample_lead(), node.truth_lead()  # after node.realtime is set
        c.sample_lead = -1 if s_lead is None else s_lead
        c.truth_lead = -1 if t_lead is None else t_lead
        codec = node.codec
        for j, (msg, name) in enumerate(SIGNALS):
            lo, hi, scale, offset, mod, chk_lo, chk_hi = codec.signal_table(msg)[name]
            c.sig[j] = Sig(lo, hi, scale, offset, int(mod), chk_lo, chk_hi)
        for attr, msg in (("duty_flags", "PwmDuty"), ("tel_flags", "CtrlTelemetry")):
            spec = codec._spec(msg)
            setattr(c, attr, (BN_FD if spec.is_fd else 0) | (BN_BRS if spec.brs else 0))
        c.run_id = node.run_id
        c.rpm_per_rad_s = RPM_PER_RAD_S  # the node's speed_ref in rad/s (_apply_commands)
        self._newest = -1  # the last step of the pending list handed to C
        # the copies of the bench commands Python took are dropped in C (bn.h)
        dll.bn_ctl_cmd_seen_init(
            self.addr, codec.frame_id("BenchCommand"), copy_span(node.commands.modulus)
        )
        self._copies_merged = 0
        self._sync_commands()

    # -- what stays Python's --------------------------------------------------
    def _sync_commands(self, n_before: int | None = None) -> None:
        """The Python queue's state to C: the acknowledgement, the stop and fault flags,
        and the pending list (its first :data:`CMDS`, in step order; ``cmds_more`` when
        it holds more).  ``n_before``: the pending commands before one command frame was
        queued, when C's list was the queue's but for what C applied: a repeat leaves the
        list as it is, and a command beyond every other goes to its end (rewriting the
        list for each of the ramp's frames took longer than a 10 kHz period)."""
        node, c = self.node, self.ctl
        q = node.commands
        c.ack_seq = q.ack_seq
        c.stopped = int(node.stopped)
        c.faulted = int(node.faulted)
        c.applied_upto = q.applied_upto
        c.applied_seq = q.applied_seq
        if n_before is not None and len(q.pending) == n_before:
            return
        if n_before is not None and len(q.pending) == n_before + 1:
            top = max(q.pending)
            if top > self._newest:
                self._newest = top
                if c.cmds_more or c.n_cmds >= CMDS:
                    c.cmds_more = 1
                else:
                    cmd, e = q.pending[top], c.cmds[c.n_cmds]
                    e.step, e.cmd, e.seq, e.speed_ref_rpm = top, cmd.cmd, cmd.seq, cmd.speed_ref_rpm
                    c.n_cmds += 1
                return
        pending = sorted(q.pending.items())
        self._newest = pending[-1][0] if pending else -1
        for j, (s, cmd) in enumerate(pending[:CMDS]):
            e = c.cmds[j]
            e.step, e.cmd, e.seq, e.speed_ref_rpm = s, cmd.cmd, cmd.seq, cmd.speed_ref_rpm
        c.n_cmds = min(len(pending), CMDS)
        c.cmds_more = int(len(pending) > CMDS)

    def pull_commands(self) -> None:
        """What C applied back into the Python node: the queue's applied commands
        (:meth:`CommandQueue.due`, nothing applied again), the stop and fault flags (the
        speed reference is the core's, which the controller reads)."""
        node, c = self.node, self.ctl
        if c.applied_upto >= 0:
            node.commands.due(c.applied_upto)
        node.stopped = bool(c.stopped)
        node.faulted = bool(c.faulted)

    def _command(self) -> None:
        """A BenchCommand frame: ControllerNode.on_message's command branch."""
        node, c = self.node, self.ctl
        f = c.cmd_frame
        self.pull_commands()
        node.next_k = c.next_k
        if c.next_k > 0:  # the steps C ran count as applied (CommandQueue.due)
            node.commands.applied_upto = max(node.commands.applied_upto, c.next_k - 1)
        msg = can.Message(
            arbitration_id=f.id,
            is_extended_id=bool(f.flags & BN_EXT),
            is_remote_frame=bool(f.flags & BN_RTR),
            is_error_frame=bool(f.flags & BN_ERR),
            is_fd=bool(f.flags & BN_FD),
            bitrate_switch=bool(f.flags & BN_BRS),
            data=bytes(f.data[: f.len]),
            check=False,
        )
        before, n_before = node.commands.ack_seq, len(node.commands.pending)
        taken = node.commands.taken
        node.last_output = None  # the telemetry is C's (send_ack)
        node.on_message(msg)
        if node.commands.taken != taken:
            self.dll.bn_ctl_cmd_taken(self.addr, ctypes.byref(f))
        if node.commands.ack_seq != before and c.has_last:
            c.send_ack = 1
        self._sync_commands(n_before)

    def _more_commands(self) -> None:
        """The list handed over ran dry with more pending: the next ones."""
        self.pull_commands()
        self._sync_commands()

    def _timeout(self) -> None:
        node = self.node
        self.pull_commands()
        node.next_k = self.ctl.next_k
        node.sample_timeout()
        self._sync_commands()

    def handle(self, ev: int) -> None:
        """Hand event ``ev`` (not an end) to Python's node."""
        if ev == EV_COMMAND:
            self._command()
        elif ev == EV_CMDS:
            self._more_commands()
        elif ev == EV_TIMEOUT:
            self._timeout()
        elif ev == EV_ERROR:
            err = self.ctl.error
            if err == -2:  # CC_ERR_U_DC: as the Python step raises
                raise ZeroDivisionError("float division by zero (u_dc = 0)")
            if err < 0:
                raise BenchError(f"native controller node: the core's step failed ({err})")
            raise OSError(err, f"native controller node: bus: {os.strerror(err)}")

    # -- the loop ---------------------------------------------------------------
    def serve(
        self,
        bus: Any,
        *,
        stop: Callable[[], bool],
        idle_s: float,
        sample_timeout_s: float,
    ) -> None:
        """``controller_loop`` on the C bus ``bus`` (a ``bn_bus_t`` block)."""
        c = self.ctl
        c.idle_ns = round(min(idle_s, 1e9) * 1e9)
        c.sample_timeout_ns = round(sample_timeout_s * 1e9)
        poll = min(0.05, sample_timeout_s / 4) if c.realtime else 0.05
        c.poll_ns = round(poll * 1e9)
        c.return_ns = round(RETURN_S * 1e9)
        try:
            while True:
                ev = self.dll.bn_ctl_serve(self.addr, ctypes.addressof(bus))
                if ev in (EV_STOPPED, EV_IDLE):
                    return
                if ev != EV_POLL:
                    self.handle(ev)
                # after every event: in real time without samples every call ends in a
                # sample timeout, never in a poll, and a stop must still be seen
                if stop():
                    return
        finally:
            self.merge()

    def merge(self) -> None:
        """The C counters into the Python node's (its report), once, after the loop."""
        node, c = self.node, self.ctl
        self.pull_commands()
        n = node.counters
        n.frames_accepted += c.c.frames_accepted
        n.frames_unknown += c.c.frames_unknown
        for reason, count in zip(REASONS, c.c.reasons, strict=True):
            n.reject(reason, count)
        # the copies of bench commands C dropped (bn.h): repeats, as CommandQueue counts them
        copies = int(self.dll.bn_ctl_cmd_copies(self.addr))
        n.reject(REPEATED_COUNTER, copies - self._copies_merged)
        self._copies_merged = copies
        n.send_errors += c.c.send_errors
        n.frames_lost_on_send += c.c.frames_lost_on_send
        node.samples_accepted += c.c.samples_accepted
        node.next_k = c.next_k
        node.node_engine = "native"
        if c.realtime:
            node.commands_held = {
                "held": int(c.held.total),
                "held_max": int(c.held.max),
                "held_full": int(c.held.full),
            }
        c.c = Counts()


def open_bus(dll: ctypes.CDLL, spec: Any) -> ctypes.Array[ctypes.c_char]:
    """The C transport of bus ``spec`` (:class:`bench.wire._bus.BusSpec`): a ``bn_bus_t``
    block; :class:`BenchError` with one line when it cannot be opened."""
    from bench.wire._bus import UDP_DEFAULT_PORT

    bus = ctypes.create_string_buffer(int(dll.bn_ctl_bus_size()))
    if spec.interface == "udp_multicast":
        port = spec.port or UDP_DEFAULT_PORT
        rc = dll.bn_udp_open(bus, spec.channel.encode(), port, 4 << 20)
    elif spec.interface == "socketcan":
        rc = dll.bn_can_open(bus, spec.channel.encode(), True)
    else:
        raise BenchError(f"native controller node: --interface {spec.interface}: not spoken")
    if rc != 0:
        raise BenchError(
            f"native controller node: {spec.interface} {spec.channel}: {os.strerror(-rc)}"
        )
    return bus


def native_controller_loop(
    spec: Any,
    node: ControllerNode,
    *,
    realtime: bool,
    on_ready: Callable[[], None] | None = None,
    stop: Callable[[], bool] = lambda: False,
    idle_s: float = 3600.0,
    sample_timeout_s: float = 0.05,
) -> None:
    """:func:`bench.nodes._loops.controller_loop` with the per-period loop in C, on the bus
    ``spec`` names (opened here by the C transport)."""
    native = NativeController(node, realtime=realtime)
    bus = open_bus(native.dll, spec)
    try:
        if on_ready:
            on_ready()
        native.serve(bus, stop=stop, idle_s=idle_s, sample_timeout_s=sample_timeout_s)
    finally:
        native.dll.bn_close(bus)
