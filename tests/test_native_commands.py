"""The controller unit applies the bench commands in C (``bn_ctl_apply_commands``).

The native controller node hands each ``BenchCommand`` frame to Python's
:class:`~bench.nodes._counters.CommandQueue` (de-duplication, seq, late commands)
and gets the pending list back; C applies each command at its step, with no return
to Python.  Its answers must be the Python node's, bit for bit, and the node's state
after the run (the queue, the stop, the speed reference) the same: checked with more
commands pending than the list C holds at a time (the refill, ``EV_CMDS``), a late
command, a repeat, and a stop.
"""

from __future__ import annotations

import shutil

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
