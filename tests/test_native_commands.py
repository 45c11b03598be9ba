"""The controller unit applies the bench commands in C (``bn_ctl_apply_commands``).

The native controller node hands each ``BenchCommand`` frame to Python's
:class:`~bench.nodes._counters.CommandQueue` (de-duplication, seq, late commands)
and gets the pending list back; C applies each command at its step, with no return
to Python.  Its answers must be the Python node's, bit for bit, and the node's state
after the run (the queue, the stop, the speed reference) the same: checked with more
commands pending than the list C holds at a time (the refill, ``EV_CMDS``), a late
command, a repeat, and a stop; and with every command three times, as the bench
sends it: the copies of the commands Python took are dropped in C, counted as
Python counts them (``bn_cmd_seen_t``, bn.h).
"""

from __future__ import annotations

import ctypes
import shutil
from typing import Any

import can
import pytest

from bench import load_scenario
from bench.nodes._controller_node import ControllerNode
from bench.scenarios._setup import build_controller, needs_truth
from bench.wire._codec import Codec
from bench.wire._protocol import CMD_NONE, CMD_START, CMD_STOP
from controller import compiled_controller_missing
from tests.native_helpers import native_answers

pytestmark = pytest.mark.skipif(
    compiled_controller_missing() is not None or not any(shutil.which(c) for c in ("cc", "gcc")),
    reason="needs the compiled controller and a C compiler",
)

CODEC = Codec()
M_STEP = 1 << CODEC.step_bits("PhaseSamples")
M_CMD = 1 << CODEC.step_bits("BenchCommand")


def _node() -> ControllerNode:
    scn = load_scenario("wen-5.1")
    ctrl = build_controller(scn, "tt-dq", None)
    return ControllerNode(CODEC, ctrl, needs_truth=needs_truth("tt-dq"), lockstep_delay=0)


def _cmd(seq: int, step: int, cmd: int, rpm: float) -> can.Message:
    return CODEC.encode(
        "BenchCommand",
        {"cmd": cmd, "seq": seq % 16, "step": step % M_CMD, "speed_ref": rpm, "load_torque": 0.0},
    )


def _sample(k: int) -> can.Message:
    i_a = 0.1 * (k % 7) - 0.3
    return CODEC.encode(
        "PhaseSamples", {"i_a": i_a, "i_b": -1.0, "u_dc": 540.0, "status": 1, "step": k % M_STEP}
    )


N_CMDS = 300  # more than the C list's 256 (bn_ctl.h BN_CTL_CMDS)


def _frames() -> list[can.Message]:
    """A start at 0 and a set-point every period 1..N_CMDS, all sent first; a repeat;
    then the samples, with a late set-point among them and a stop at 350."""
    out = [_cmd(0, 0, CMD_START, 0.0)]
    out += [_cmd(j, j, CMD_NONE, 5.0 * j) for j in range(1, N_CMDS + 1)]
    out.append(_cmd(7, 7, CMD_NONE, 35.0))  # a repeat: rejected as one by the queue
    for k in range(400):
        if k == 320:
            out.append(_cmd(N_CMDS + 1, 310, CMD_NONE, 123.0))  # late: applied at the next step
            out.append(_cmd(N_CMDS + 2, 350, CMD_STOP, 0.0))
        out.append(_sample(k))
    return out


def _python(node: ControllerNode, frames: list[can.Message]) -> list[tuple[int, bytes]]:
    return [(a.arbitration_id, bytes(a.data)) for m in frames for a in node.on_message(m)]


def _native(node: ControllerNode, frames: list[can.Message]) -> tuple[list[tuple[int, bytes]], int]:
    """The answers, and how many times C returned for the pending list (EV_CMDS)."""
    from bench.nodes.native import controller_node as native

    events: list[int] = []
    got = native_answers(node, frames, events.append)
    return got, events.count(native.EV_CMDS)


def test_the_native_node_applies_the_commands_as_the_python_node() -> None:
    frames = _frames()
    py_node, nat_node = _node(), _node()
    want = _python(py_node, frames)
    got, refills = _native(nat_node, frames)
    assert len(want) > 2 * 350
    assert got == want
    # the list ran dry once with the rest pending: C asked for them once, at step 257
    assert refills == 1
    # the node's state after the run is the Python node's
    assert nat_node.stopped and py_node.stopped
    assert nat_node.ctrl.w_m_ref == py_node.ctrl.w_m_ref == 0.0
    for a, b in ((nat_node.commands, py_node.commands),):
        assert (a.applied_seq, a.ack_seq, sorted(a.pending)) == (
            b.applied_seq,
            b.ack_seq,
            sorted(b.pending),
        )
    assert nat_node.counters.as_dict() == py_node.counters.as_dict()
    assert nat_node.counters.late_commands == 1


def test_the_speed_reference_of_each_command_reaches_the_core() -> None:
    # without the stop: the last set-point (the late one, 123 rpm) is in force at the end
    stop = _cmd(N_CMDS + 2, 350, CMD_STOP, 0.0).data
    frames = [m for m in _frames() if m.data != stop]
    py_node, nat_node = _node(), _node()
    want = _python(py_node, frames)
    got, _ = _native(nat_node, frames)
    assert got == want
    assert nat_node.ctrl.w_m_ref == py_node.ctrl.w_m_ref != 0.0
    assert nat_node.ctrl.states()["w_m_ref"] == py_node.ctrl.states()["w_m_ref"]


def _with_copies(frames: list[can.Message]) -> list[can.Message]:
    """Each command twice at once and once more four frames later, as the bench sends
    them (bench/runs/_pacing.py: twice, then again after AGAIN_S)."""
    out: list[can.Message] = []
    again: list[tuple[int, can.Message]] = []
    for m in frames:
        out.append(m)
        if m.arbitration_id == CODEC.frame_id("BenchCommand"):
            out.append(m)
            again.append((len(out) + 4, m))
        while again and again[0][0] <= len(out):
            out.append(again.pop(0)[1])
    out += [m for _, m in again]
    return out


def test_the_copies_of_a_command_are_dropped_in_c_as_python_counts_them() -> None:
    """The copies of the commands Python took never reach Python (bn.h, bn_cmd_seen_t):
    the answers, the queue and every counter (the copies among the duplicates) are the
    Python node's, and Python sees each command once."""
    from bench.nodes.native import controller_node as native

    frames = _with_copies(_frames())
    n_cmd = sum(m.arbitration_id == CODEC.frame_id("BenchCommand") for m in _frames())
    py_node, nat_node = _node(), _node()
    want = _python(py_node, frames)
    events: list[int] = []
    got = native_answers(nat_node, frames, events.append)
    assert got == want
    assert nat_node.counters.as_dict() == py_node.counters.as_dict()
    # 2 copies of each command, and the _frames' own repeat of seq 7
    assert py_node.counters.duplicates == 2 * n_cmd + 1
    # Python saw each command it took once; the repeat of seq 7 (other bytes: another
    # set-point) it did not take, so its copies reach Python too, and are counted there
    assert events.count(native.EV_COMMAND) == (n_cmd - 1) + 3
    assert (nat_node.commands.ack_seq, sorted(nat_node.commands.pending)) == (
        py_node.commands.ack_seq,
        sorted(py_node.commands.pending),
    )


def _seen_ring() -> tuple[Any, Any]:
    from bench.nodes.native import _native

    dll = _native.library()
    seen = _native.CmdSeen()
    dll.bn_cmd_seen_init(
        ctypes.byref(seen), CODEC.frame_id("BenchCommand"), _native.copy_span(M_CMD)
    )
    return dll, seen


def _frame(msg: can.Message) -> Any:
    from bench.nodes.native import _native

    f = _native.Frame(id=msg.arbitration_id, len=len(msg.data), flags=0)
    f.data[: len(msg.data)] = list(msg.data)
    return f


def test_a_copy_is_dropped_only_within_its_span_and_while_kept() -> None:
    from bench.nodes.native import _native

    dll, seen = _seen_ring()
    span = _native.copy_span(M_CMD)
    a = _frame(_cmd(3, 40, CMD_NONE, 10.0))
    dll.bn_cmd_seen_take(ctypes.byref(seen), ctypes.byref(a), 100)
    assert dll.bn_cmd_seen_copy(ctypes.byref(seen), ctypes.byref(a), 100) == 1
    assert dll.bn_cmd_seen_copy(ctypes.byref(seen), ctypes.byref(a), 100 + span) == 1
    # later than the span: the step might unwrap elsewhere; Python decides
    assert dll.bn_cmd_seen_copy(ctypes.byref(seen), ctypes.byref(a), 101 + span) == 0
    assert dll.bn_cmd_seen_copy(ctypes.byref(seen), ctypes.byref(a), 99) == 0  # before it
    # one bit else is another frame; another identifier is not a command
    b = _frame(_cmd(3, 40, CMD_NONE, 10.1))
    assert dll.bn_cmd_seen_copy(ctypes.byref(seen), ctypes.byref(b), 100) == 0
    s = _frame(_sample(40))
    dll.bn_cmd_seen_take(ctypes.byref(seen), ctypes.byref(s), 100)
    assert dll.bn_cmd_seen_copy(ctypes.byref(seen), ctypes.byref(s), 100) == 0
    assert seen.copies == 2
    # the ring keeps the last CMD_SEEN taken: the first is then forgotten
    for j in range(_native.CMD_SEEN):
        f = _frame(_cmd(j + 4, 41 + j, CMD_NONE, 0.0))
        dll.bn_cmd_seen_take(ctypes.byref(seen), ctypes.byref(f), 100)
    assert dll.bn_cmd_seen_copy(ctypes.byref(seen), ctypes.byref(a), 100) == 0


def test_the_kept_commands_are_among_the_keys_the_queue_remembers() -> None:
    """bn.h's argument: a kept frame's key is still in CommandQueue.recent, and a copy
    within the span unwraps to the same step as a command the queue took (not stale:
    no more than a quarter of the modulus before the node's step)."""
    from bench.nodes._counters import CommandQueue
    from bench.nodes.native import _native

    assert (CommandQueue(M_CMD).recent.maxlen or 0) >= _native.CMD_SEEN
    span = _native.copy_span(M_CMD)
    assert M_CMD // 4 + span < M_CMD // 2
