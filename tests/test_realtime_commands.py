"""Real time: the controller applies a bench command at its step, not on arrival.

``bench run`` sends commands ahead of the plant (20 periods in real time);
applied on arrival, the stop command ended the controller 20 periods before
the plant's last period (every real-time run then counted 20 late duties and
20 missing rows) and a set-point change reached the controller early.
"""

from __future__ import annotations

from typing import Any

import can
import pytest

from bench.nodes._controller_node import ControllerNode
from bench.nodes._loops import command_frames, make_controller_node, make_plant_node
from bench.nodes._plant_node import PlantNode
from bench.scenarios._schema import Profile, load_scenario
from bench.wire._codec import Codec
from bench.wire._protocol import CMD_STOP

CODEC = Codec()


def _answer_steps(node: ControllerNode, pn: PlantNode, n: int) -> list[int]:
    """Feed ``n`` periods of samples to ``node``; the steps of the duties it answered."""
    steps = []
    for _ in range(n):
        for m in pn.frames_now():
            for o in node.on_message(m):
                d = CODEC.decode(o)
                if d is not None and d.name == "PwmDuty":
                    steps.append(int(d.signals["step"]))
                    pn.on_message(o)
        pn.advance_lockstep()
    return steps


def test_stop_sent_early_takes_effect_at_its_step() -> None:
    scn = load_scenario("xue-fig13").with_overrides(duration=0.05)  # 50 periods at 1 kHz
    node = make_controller_node(scn, "sensored", CODEC)
    node.realtime = True
    pn = make_plant_node(scn, CODEC)
    cmds = command_frames(scn, CODEC)
    stop_step, stop_msg = cmds[-1]
    assert CODEC.decode(stop_msg).signals["cmd"] == CMD_STOP  # type: ignore[union-attr]
    # every command, the stop included, arrives before the first sample
    for _, m in cmds:
        pn.on_message(m)
        assert node.on_message(m) == []
    pn.apply_commands()
    assert not node.stopped
    steps = _answer_steps(node, pn, stop_step)
    # answered every period up to the stop's step, then stopped
    assert steps == list(range(1, stop_step + 1))
    assert not node.stopped
    _answer_steps(node, pn, 1)
    assert node.stopped


def test_speed_step_sent_early_reaches_the_controller_at_its_step() -> None:
    scn = load_scenario("xue-fig13").with_overrides(duration=0.05)
    scn = scn.with_overrides(speed_rpm=Profile(((0.0, 0.0), (0.02, 0.0), (0.0201, 300.0))))
    node = make_controller_node(scn, "sensored", CODEC)
    node.realtime = True
    pn = make_plant_node(scn, CODEC)
    cmds = command_frames(scn, CODEC)
    for _, m in cmds:
        pn.on_message(m)
        node.on_message(m)
    pn.apply_commands()
    change = next(s for s, m in cmds if CODEC.decode(m).signals["speed_ref"] > 0)  # type: ignore[union-attr]
    _answer_steps(node, pn, change)  # samples 0 .. change - 1
    assert node.ctrl.w_m_ref == 0.0
    _answer_steps(node, pn, 1)  # sample ``change``
    assert node.ctrl.w_m_ref > 0.0


def test_lost_last_sample_still_stops_the_controller_on_its_timeout() -> None:
    """The plant's last sample (the stop's step) lost: the sample timeout ends the run."""
    scn = load_scenario("xue-fig13").with_overrides(duration=0.05)
    cmds = command_frames(scn, CODEC)
    stop_step = cmds[-1][0]
    for lost_from, stops in ((stop_step, True), (stop_step - 10, False)):
        node = make_controller_node(scn, "sensored", CODEC)
        node.realtime = True
        pn = make_plant_node(scn, CODEC)
        for _, m in cmds:
            pn.on_message(m)
            node.on_message(m)
        pn.apply_commands()
        _answer_steps(node, pn, lost_from)  # samples 0 .. lost_from - 1 arrive
        node.sample_timeout()
        # only a stop due with the missing sample ends it; earlier, samples just stopped
        assert node.stopped is stops and node.faulted


def test_late_commands_keep_their_order_and_the_newest_set_point() -> None:
    """Two different commands arriving after their steps: both applied, the newer last."""
    scn = load_scenario("xue-fig13").with_overrides(duration=0.05)
    node = make_controller_node(scn, "sensored", CODEC)
    node.realtime = True
    pn = make_plant_node(scn, CODEC)
    cmds = command_frames(scn, CODEC)
    for _, m in cmds[:1]:  # the start
        pn.on_message(m)
        node.on_message(m)
    pn.apply_commands()
    _answer_steps(node, pn, 10)

    def command(step: int, rpm: float, seq: int) -> can.Message:
        sig = {"cmd": 0, "seq": seq, "step": step, "speed_ref": rpm, "load_torque": 0.0}
        return CODEC.encode("BenchCommand", sig)

    for m in (command(5, 50.0, 7), command(8, 100.0, 8)):  # both late, newest last
        node.on_message(m)
        node.on_message(m)  # the second copy of each is a repeat, not a new command
    assert node.counters.late_commands == 2
    assert node.counters.reject_reasons == {"repeated_counter": 2}
    _answer_steps(node, pn, 3)
    assert node.ctrl.w_m_ref * 60.0 / (2.0 * 3.141592653589793) == pytest.approx(100.0, rel=1e-3)


def test_the_commands_are_sent_with_a_short_switch_interval(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """bench run's thread that sends the commands shares the GIL with the recorder's, which
    hands every frame to Python: while it sends in real time, the interpreter's switch
    interval is SEND_SWITCH_INTERVAL_S (each send gives the GIL up, and waited up to 5 ms
    for it back), in lockstep as it was; the interval before is restored afterwards, also
    when the loop raises."""
    import contextlib
    import sys

    from bench.runs import _run

    before = sys.getswitchinterval()
    assert before > _run.SEND_SWITCH_INTERVAL_S
    with _run._switch_interval(_run.SEND_SWITCH_INTERVAL_S):
        # the interpreter keeps it in whole microseconds
        assert sys.getswitchinterval() == pytest.approx(_run.SEND_SWITCH_INTERVAL_S, rel=1e-6)
    assert sys.getswitchinterval() == before
    with pytest.raises(KeyboardInterrupt), _run._switch_interval(1e-4):
        raise KeyboardInterrupt
    assert sys.getswitchinterval() == before
    with _run._switch_interval(None):
        assert sys.getswitchinterval() == before

    asked: list[float | None] = []

    @contextlib.contextmanager
    def record(seconds: float | None) -> Any:
        asked.append(seconds)
        yield

    monkeypatch.setattr(_run, "_switch_interval", record)
    nothing: Any = None
    for lockstep in (True, False):  # no recording: the loop fails at once, after the ask
        with pytest.raises(AttributeError):
            _run._drive(nothing, nothing, [], nothing, 0, False, nothing, None, lockstep)
    assert asked == [None, _run.SEND_SWITCH_INTERVAL_S]
