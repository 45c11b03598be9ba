"""The step counter's plausibility check (AUTOSAR E2E MaxDeltaCounter style).

A random frame with a DBC identifier and the right length passes the 8-bit E2E
CRC once in 256; its step counter may then fall in the receivers' unwrap
window (half the 10-bit range).  Such a frame must not take the place of the
genuine one of its step:

- a lockstep controller node (Python and native) rejects a sample further
  ahead of its next step than the plant can be
  (:func:`bench.wire._protocol.lockstep_sample_lead`) as ``future_counter``;
- the run's analysis rejects a duty or telemetry ahead of the plant's newest
  step seen before it in the capture (:data:`bench.wire._protocol.ANSWER_LEAD`).
"""

from __future__ import annotations

from typing import Any

import can
import numpy as np
import pytest

from bench import load_scenario
from bench.nodes._controller_node import ControllerNode
from bench.nodes._counters import REJECT_FUTURE_COUNTER
from bench.nodes._loops import run_inprocess
from bench.runs._analysis import Capture, analyze_frames
from bench.scenarios._setup import build_controller, needs_truth, sample_period
from bench.wire._codec import Codec
from bench.wire._protocol import CMD_START, lockstep_sample_lead
from controller import compiled_controller_missing
from tests.native_helpers import native_answers

CODEC = Codec()
M_STEP = 1 << CODEC.step_bits("PhaseSamples")
FORGED_LEAD = 31  # the lead of the forged sample seen in a capture (step 2655 for 2624)


def test_the_lead_is_the_delay_plus_one() -> None:
    # a lockstep plant with duties up to n runs up to period n + delay, whose end is
    # the sample n + delay + 1
    assert [lockstep_sample_lead(d) for d in (0, 1, 3)] == [1, 2, 4]


def _sample(k: int, i_a: float) -> can.Message:
    return CODEC.encode(
        "PhaseSamples", {"i_a": i_a, "i_b": -1.0, "u_dc": 540.0, "status": 1, "step": k % M_STEP}
    )


def _frames(n: int, forged_at: int | None) -> list[can.Message]:
    """A start and samples 0..n-1 in order; with ``forged_at``, before sample
    ``forged_at`` (the node's next step then) a valid-CRC sample for step
    ``forged_at + FORGED_LEAD`` with other currents."""
    out = [
        CODEC.encode(
            "BenchCommand",
            {"cmd": CMD_START, "seq": 0, "step": 0, "speed_ref": 300.0, "load_torque": 0.0},
        )
    ]
    for k in range(n):
        if k == forged_at:
            out.append(_sample(k + FORGED_LEAD, 2.5))
        out.append(_sample(k, 0.1 * (k % 7) - 0.3))
    return out


def _node(delay: int | None) -> ControllerNode:
    scn = load_scenario("wen-5.1")
    ctrl = build_controller(scn, "tt-dq", None)
    return ControllerNode(CODEC, ctrl, needs_truth=needs_truth("tt-dq"), lockstep_delay=delay)


def _python_answers(node: ControllerNode, frames: list[can.Message]) -> list[tuple[int, bytes]]:
    got = []
    for m in frames:
        got += [(a.arbitration_id, bytes(a.data)) for a in node.on_message(m)]
    return got


ENGINES = [
    pytest.param(_python_answers, id="python"),
    pytest.param(
        native_answers,
        id="native",
        marks=pytest.mark.skipif(
            compiled_controller_missing() is not None
            or not any(__import__("shutil").which(c) for c in ("cc", "gcc")),
            reason="needs the compiled controller and a C compiler",
        ),
    ),
]


@pytest.mark.parametrize("answers", ENGINES)
def test_a_forged_sample_31_ahead_is_rejected_and_the_genuine_one_taken(answers: Any) -> None:
    n, at, delay = 200, 100, 0
    frames, clean = _frames(n, at), _frames(n, None)
    want = _python_answers(_node(delay), clean)
    node = _node(delay)
    got = answers(node, frames)
    assert len(want) == 2 * n and got == want  # every duty and telemetry as without it
    rep = node.report()
    assert rep["reject_reasons"] == {REJECT_FUTURE_COUNTER: 1}
    assert rep["duplicates"] == 0 and rep["steps"] == n


@pytest.mark.parametrize("answers", ENGINES)
def test_without_the_plans_delay_the_window_stays_and_the_forgery_wins(answers: Any) -> None:
    # what the check changes: without it the forgery is held for its step, and the
    # genuine sample of that step is then taken for a repeat
    n, at = 200, 100
    frames, clean = _frames(n, at), _frames(n, None)
    node = _node(None)
    got = answers(node, frames)
    assert got != _python_answers(_node(None), clean)
    assert node.report()["reject_reasons"] == {"repeated_counter": 1}


@pytest.mark.parametrize("answers", ENGINES)
@pytest.mark.parametrize("delay", [0, 2])
def test_a_sample_at_the_lead_is_held_one_beyond_is_rejected(answers: Any, delay: int) -> None:
    lead = lockstep_sample_lead(delay)
    start = CODEC.encode(
        "BenchCommand",
        {"cmd": CMD_START, "seq": 0, "step": 0, "speed_ref": 300.0, "load_torque": 0.0},
    )
    # sample 0 lost: the plant can have sent up to sample lead, never lead + 1
    frames = [start, *(_sample(k, 0.2) for k in range(1, lead + 2)), _sample(0, 0.2)]
    node = _node(delay)
    got = answers(node, frames)
    assert node.report()["reject_reasons"] == {REJECT_FUTURE_COUNTER: 1}
    assert len(got) == 2 * (lead + 1) and node.next_k == lead + 1


def test_real_time_keeps_the_unwrap_window() -> None:
    node = _node(0)
    node.realtime = True
    assert node.sample_lead() is None and node.truth_lead() is None
    got = _python_answers(node, [_sample(40, 0.1)])
    assert len(got) == 2 and node.next_k == 41  # skipped ahead to the newest sample


def test_a_fault_timeline_leaves_the_truth_its_window() -> None:
    node = ControllerNode(
        CODEC, _node(1).ctrl, needs_truth=True, lockstep_delay=1, truth_may_lead=True
    )
    assert node.sample_lead() == 2 and node.truth_lead() is None


def _truth(k: int, theta: float) -> can.Message:
    return CODEC.encode(
        "PlantTruth",
        {
            "theta_e": theta,
            "w_m": 30.0,
            "tau_e": 0.0,
            "tau_L": 0.0,
            "duty_age": 1,
            "step": k,
            "run_id": 7,
        },
    )


@pytest.mark.parametrize("answers", ENGINES)
def test_a_forged_truth_31_ahead_is_rejected_in_the_sensored_baseline(answers: Any) -> None:
    def frames(forged: bool) -> list[can.Message]:
        out = _frames(120, None)[:1]
        for k in range(120):
            if forged and k == 60:
                out.append(_truth(k + FORGED_LEAD, 3.0))
            out += [_sample(k, 0.2), _truth(k, 0.01 * k)]
        return out

    scn = load_scenario("wen-5.1")

    def node() -> ControllerNode:
        ctrl = build_controller(scn, "sensored", None)
        return ControllerNode(CODEC, ctrl, needs_truth=True, lockstep_delay=0)

    want = _python_answers(node(), frames(False))
    n = node()
    assert answers(n, frames(True)) == want and len(want) == 240
    assert n.report()["reject_reasons"] == {REJECT_FUTURE_COUNTER: 1}


# ---------------------------------------------------------------- the run's analysis
@pytest.fixture(scope="module")
def capture() -> tuple[list[can.Message], float]:
    """A clean lockstep capture of 0.15 s (wire order, as a recorder sees it)."""
    scn = load_scenario("wen-5.1", {"duration": 0.15, "score_from_s": 0.1})
    got = run_inprocess(scn, "tt-dq", CODEC)
    return [got[i] for i in range(len(got))], sample_period(scn)


def _step(m: can.Message) -> int:
    d = CODEC.decode(m)
    assert d is not None
    return int(d.signals["step"])


def _forge_after_sample(
    frames: list[can.Message], newest: int, name: str, step: int, values: dict[str, Any]
) -> list[can.Message]:
    """``frames`` with a valid-CRC ``name`` frame tagged ``step`` inserted just after the
    plant's sample ``newest`` (its first sending)."""
    sid = CODEC.frame_id("PhaseSamples")
    at = next(
        j for j, m in enumerate(frames) if m.arbitration_id == sid and _step(m) == newest % M_STEP
    )
    m = 1 << CODEC.step_bits(name)
    forged = CODEC.encode(name, {**values, "step": step % m})
    return [*frames[: at + 1], forged, *frames[at + 1 :]]


def _assert_only_the_forgery_left_out(got: Capture, clean: Capture) -> None:
    """One frame rejected as ``future_counter``, and the clean capture's table."""
    assert got.rejected == {REJECT_FUTURE_COUNTER: 1}
    for col, v in clean.table.items():
        np.testing.assert_array_equal(got.table[col], v, err_msg=col)


def test_a_forged_duty_138_ahead_takes_no_part_in_the_table(
    capture: tuple[list[can.Message], float],
) -> None:
    frames, T_s = capture
    newest = 1018
    duty = {"duty_a": 0.9, "duty_b": 0.1, "duty_c": 0.5, "enable": 1}
    forged = _forge_after_sample(frames, newest, "PwmDuty", newest + 138 + 1, duty)
    clean = analyze_frames(frames, CODEC, T_s=T_s, n_p=4)
    got = analyze_frames(forged, CODEC, T_s=T_s, n_p=4)
    assert clean.rejected == {}
    _assert_only_the_forgery_left_out(got, clean)
    assert got.duplicates == clean.duplicates and got.out_of_order == clean.out_of_order
    # the genuine duty of that step is in the table, not the forged one
    row = int(np.searchsorted(clean.table["step"], newest + 138))
    assert clean.table["step"][row] == newest + 138 and clean.table["d_a"][row] != 0.9


def test_a_duty_answering_the_newest_sample_is_kept(
    capture: tuple[list[can.Message], float],
) -> None:
    # the bound is exact: a duty for the sample just seen is the controller's answer
    frames, T_s = capture
    newest = 1018
    duty = {"duty_a": 0.9, "duty_b": 0.1, "duty_c": 0.5, "enable": 1}
    cut = [m for m in frames if m.arbitration_id != CODEC.frame_id("PwmDuty")]
    got = analyze_frames(
        _forge_after_sample(cut, newest, "PwmDuty", newest + 1, duty), CODEC, T_s=T_s, n_p=4
    )
    assert got.rejected == {}
    row = int(np.searchsorted(got.table["step"], newest))
    assert got.table["d_a"][row] == pytest.approx(0.9, abs=1e-3)
    too_far = analyze_frames(
        _forge_after_sample(cut, newest, "PwmDuty", newest + 2, duty), CODEC, T_s=T_s, n_p=4
    )
    assert too_far.rejected == {REJECT_FUTURE_COUNTER: 1}


def test_a_forged_telemetry_ahead_is_counted_and_takes_no_part(
    capture: tuple[list[can.Message], float],
) -> None:
    # a telemetry carries a wide counter, which anchors the narrow ones: dropped, the
    # steps are unwrapped again without it
    frames, T_s = capture
    newest = 1018
    clean = analyze_frames(frames, CODEC, T_s=T_s, n_p=4)
    tel = {"theta_hat": 1.0, "w_hat": 10.0, "err": 0.0, "mode": 3, "run_id": clean.run_id,
           "cmd_ack_valid": 0, "cmd_ack": 0}  # fmt: skip
    forged = _forge_after_sample(frames, newest, "CtrlTelemetry", newest + 5000, tel)
    got = analyze_frames(forged, CODEC, T_s=T_s, n_p=4, run_id=clean.run_id)
    _assert_only_the_forgery_left_out(got, clean)


def test_a_forged_sample_31_ahead_takes_no_part_in_the_table(
    capture: tuple[list[can.Message], float],
) -> None:
    # the capture of the first defect: the forged sample came before the genuine one of
    # its step, and i_a of that step was the forgery's
    frames, T_s = capture
    newest = 1018
    smp = {"i_a": 2.5, "i_b": -1.0, "u_dc": 540.0, "status": 1}
    forged = _forge_after_sample(frames, newest, "PhaseSamples", newest + FORGED_LEAD, smp)
    clean = analyze_frames(frames, CODEC, T_s=T_s, n_p=4)
    got = analyze_frames(forged, CODEC, T_s=T_s, n_p=4)
    _assert_only_the_forgery_left_out(got, clean)


def test_a_sample_after_frames_the_recorder_lost_is_kept(
    capture: tuple[list[can.Message], float],
) -> None:
    # the plant's frames of instants 500..504 lost: sample 505 is 6 ahead of the newest
    # plant step before it, and its own truth after it vouches for it
    frames, T_s = capture
    plant = {CODEC.frame_id("PhaseSamples"), CODEC.frame_id("PlantTruth")}
    gap = [m for m in frames if not (m.arbitration_id in plant and 500 <= _step(m) % M_STEP < 505)]
    clean = analyze_frames(frames, CODEC, T_s=T_s, n_p=4)
    got = analyze_frames(gap, CODEC, T_s=T_s, n_p=4)
    assert got.rejected == {}
    assert len(got.table["step"]) == len(clean.table["step"]) - 5
    assert 505 in got.table["step"] and 504 not in got.table["step"]
