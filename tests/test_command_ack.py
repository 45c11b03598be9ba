"""Commands cannot be lost silently (DBC 2.2, ``CtrlTelemetry.cmd_ack``).

A controller under test that throws away a share of the ``BenchCommand`` and
``PhaseSamples`` frames it receives (``tests/ext_controller.py --drop``, as an
overflowing receive buffer does) gives, in external lockstep runs, the
``signals.csv`` of the clean run: the plant runs no period whose next sample
needs a command the controller has not acknowledged, and the bench resends
what it lacks.  A controller written to 2.1 still runs, with one line saying
what the bench cannot verify.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench.nodes._counters import CommandQueue, NodeCounters
from bench.runs._pacing import CommandPacer
from bench.wire._codec import Codec
from bench.wire._protocol import ACK_WINDOW
from tests.test_external_controller import ROOT, _run


def _cmd(step: int, seq: int) -> dict[str, float]:
    return {"step": step, "seq": seq, "cmd": 0, "speed_ref": 0.0, "load_torque": 0.0}


def test_the_acknowledgement_stops_at_a_gap_and_a_late_copy_is_a_repeat() -> None:
    q, c = CommandQueue(1 << 16), NodeCounters()
    q.add(_cmd(0, 0), 0, c)
    q.add(_cmd(5, 2), 0, c)  # seq 1 lost
    assert q.ack_seq == 0
    q.add(_cmd(3, 1), 0, c)  # the resend closes the gap
    assert (q.ack_seq, q.ack_step) == (2, 5)
    q.due(100)
    q.add(_cmd(0, 0), 100, c)  # the start's third copy, long after: not late
    assert c.late_commands == 0 and c.duplicates == 1


def test_the_pacer_counts_a_command_held_after_its_step() -> None:
    from tests.trace_helpers import short

    codec = Codec()
    p = CommandPacer(short("wen-5.1", 0.05), codec, mode="realtime", external=True)

    class Sink:
        def send(self, m: object) -> None:
            pass

    p.send_due(Sink(), 0, 0.0)  # type: ignore[arg-type]
    assert p.sent == ACK_WINDOW  # until it says whether it acknowledges
    p.on_telemetry(0, 1, 0, 0.0)  # start held at step 0
    step2 = p.frames[2][0]
    p.on_telemetry(step2, 1, 0, 0.01)  # command 1 and 2 not held by their step
    assert p.late == {1, 2} and p.verification_line() is not None


def test_reports_received_after_the_plant_ended_still_count() -> None:
    """A recorder that lags the plant holds the last acknowledgements after its last
    period: the pacer takes them then, and they are not counted twice."""
    from tests.trace_helpers import short

    p = CommandPacer(short("wen-5.1", 0.05), Codec(), mode="realtime", external=True)

    class Sink:
        def send(self, m: object) -> None:
            pass

    acks: list[tuple[int, int, int]] = [(0, 1, 0)]
    p.send_due(Sink(), 0, 0.0)  # type: ignore[arg-type]
    p.take(acks, 0.0)
    p.send_due(Sink(), 0, 0.0)  # type: ignore[arg-type]
    assert p.sent == 1 + ACK_WINDOW and p.unacknowledged == ACK_WINDOW
    acks.append((0, 1, ACK_WINDOW % 16))  # arrives after the run's loop ended
    p.take(acks, 1.0)
    p.take(acks, 2.0)
    assert p.unacknowledged == 0 and p.reports == 2 and p.verification_line() is None


def test_a_stop_never_acknowledged_changes_no_period_and_is_named_apart() -> None:
    """The stop applies after the plant's last period: not acknowledging it is not a lost
    command (no exit 5), and ``stop_unacknowledged`` says so; a command before it is."""
    from tests.trace_helpers import short

    p = CommandPacer(short("wen-5.1", 0.05), Codec(), mode="realtime", external=True)
    n = len(p.frames)
    p.sent = n  # every command sent
    p.acked = n - 2  # all but the stop acknowledged
    assert p.unacknowledged == 0 and p.stop_unacknowledged and p.verification_line() is None
    p.acked = n - 3  # the last command before the stop too
    assert p.unacknowledged == 1 and p.verification_line() is not None


def test_commands_are_resent_until_the_controller_first_reports() -> None:
    """A controller that opened its bus after the first commands gets them again every
    RESEND_S until its first reporting telemetry; none once it reports."""
    from bench.runs._pacing import RESEND_S
    from tests.trace_helpers import short

    p = CommandPacer(short("wen-5.1", 0.05), Codec(), mode="realtime", external=True)
    sent: list[object] = []

    class Sink:
        def send(self, m: object) -> None:
            sent.append(m)

    p.send_due(Sink(), 0, 100.0)  # type: ignore[arg-type]
    first = len(sent)
    assert first == 2 * ACK_WINDOW
    p.send_due(Sink(), 0, 100.0 + 2 * RESEND_S)  # type: ignore[arg-type]  # starts the clock
    p.send_due(Sink(), 0, 100.0 + 4 * RESEND_S)  # type: ignore[arg-type]
    # the third copy of each (AGAIN_S) and one round of resends
    assert len(sent) == first + 2 * ACK_WINDOW and p.resends == 1
    p.take([(0, 1, ACK_WINDOW - 1)], 100.0 + 4 * RESEND_S)  # every one held
    p.send_due(Sink(), 0, 100.0 + 4.5 * RESEND_S)  # type: ignore[arg-type]
    assert p.resends == 1


def test_each_command_goes_out_a_third_time_a_resend_interval_later() -> None:
    """Two copies at once and one AGAIN_S later: a burst lost by a full receive buffer
    takes both copies of one sending, not the third (a controller that does not
    acknowledge has no other way to get it back)."""
    from bench.runs._pacing import AGAIN_S
    from tests.trace_helpers import short

    p = CommandPacer(short("wen-5.1", 0.05), Codec(), mode="lockstep")
    sent: list[object] = []

    class Sink:
        def send(self, m: object) -> None:
            sent.append(m)

    p.send_due(Sink(), 0, 10.0)  # type: ignore[arg-type]
    n = p.sent
    assert n > 0 and len(sent) == 2 * n
    p.send_due(Sink(), 0, 10.0 + 0.5 * AGAIN_S)  # type: ignore[arg-type]
    assert len(sent) == 2 * n
    p.send_due(Sink(), 0, 10.0 + AGAIN_S)  # type: ignore[arg-type]
    assert len(sent) == 3 * n and sent[2 * n :] == sent[0 : 2 * n : 2]
    p.send_due(Sink(), 0, 10.0 + 3 * AGAIN_S)  # type: ignore[arg-type]
    assert len(sent) == 3 * n  # once only


def test_in_real_time_commands_follow_the_plants_clock_not_the_hosts_lagging_view() -> None:
    """The host's view of the plant's step lags by what its recorder has yet to decode (a
    second on a loaded host): in real time the bench's commands go out by the plant's
    clock since the host first saw it, REALTIME_AHEAD_S ahead, COMMAND_BURST per call,
    so none reaches the controller after its step."""
    from bench.runs._pacing import COMMAND_BURST, REALTIME_AHEAD_S
    from bench.scenarios._schema import load_scenario

    scn = load_scenario("wen-5.1")  # speed ramp from 0.3 s to 0.8 s: a command every 10 periods
    p = CommandPacer(scn, Codec(), mode="realtime")
    T_s = p._T_s
    assert p.lead == round(REALTIME_AHEAD_S / T_s)

    class Sink:
        def send(self, m: object) -> None:
            pass

    p.send_due(Sink(), 0, 10.0)  # type: ignore[arg-type]  # the first sample seen at 10 s
    assert p.sent == COMMAND_BURST  # one burst (the start among it), not the whole lead
    for _ in range(100):  # the view stays at 0 while the plant's clock reaches step 3000
        p.send_due(Sink(), 0, 10.0 + 3000 * T_s)  # type: ignore[arg-type]
    steps = [k for k, _ in p.frames]
    assert p.sent == sum(k <= 3000 + p.lead for k in steps) > COMMAND_BURST
    assert steps[p.sent - 1] <= 3000 + p.lead < steps[p.sent]
    # the view, when it catches up, changes nothing
    sent = p.sent
    p.send_due(Sink(), 3000, 10.0 + 3000 * T_s)  # type: ignore[arg-type]
    assert p.sent == sent


def test_a_controller_under_test_is_paced_by_the_hosts_view_alone() -> None:
    """A plant may wait for a controller under test after its first sample: its step is
    not its clock's, and only what the host sees paces the commands."""
    from bench.scenarios._schema import load_scenario

    p = CommandPacer(load_scenario("wen-5.1"), Codec(), mode="realtime", external=True)
    assert p.plant_step_at(0, 10.0) == 0 and p.plant_step_at(0, 11.0) == 0
    q = CommandPacer(load_scenario("wen-5.1"), Codec(), mode="realtime")
    assert q.plant_step_at(-1, 9.0) == 0  # nothing seen yet: no clock
    assert q.plant_step_at(5, 10.0) == 5 and q.plant_step_at(5, 11.0) == 5 + 10_000


def _signals(run_dir: Path) -> str:
    return (run_dir / "signals.csv").read_text()


def test_a_dropping_controller_gives_the_clean_trace(tmp_path: Path) -> None:
    res, clean = _run(tmp_path / "clean")
    assert res.returncode == 0, res.stderr[-2000:]
    ref = _signals(clean)
    meta = json.loads((clean / "meta.json").read_text())
    assert meta["commands"]["commands_verified"] and meta["commands"]["commands_late"] == 0
    assert meta["node_engines"] == {"plant": "native"}  # its acks gate the native loop
    assert json.loads((clean / "metrics.json").read_text())["late_commands"] == 0
    for seed in (1, 2, 3):
        res, d = _run(tmp_path / f"drop{seed}", extra_ctrl=("--drop", "0.1", "--seed", str(seed)))
        assert res.returncode == 0, res.stderr[-2000:]
        assert json.loads((d / "meta.json").read_text())["node_engines"] == {"plant": "native"}
        assert _signals(d) == ref, f"seed {seed}: the trace changed"


def test_a_controller_that_joins_after_the_start_gives_the_clean_trace(tmp_path: Path) -> None:
    """A controller that opened its bus after the start, its first copies and the first
    sample (``--deaf-samples``: it sees nothing until two resends of sample 0 have
    passed) answers no sample before it holds the start (docs/PROTOCOL.md): its first
    answer is computed with it, the plant is gated from that answer on, and the run is
    the clean one, verified, none late.  Whichever of the plant's resent sample and the
    bench's resent commands reaches it first, the rule gives the same run."""
    res, clean = _run(tmp_path / "clean")
    assert res.returncode == 0, res.stderr[-2000:]
    for deaf in (1, 3):
        res, d = _run(tmp_path / f"deaf{deaf}", extra_ctrl=("--deaf-samples", str(deaf)))
        assert res.returncode == 0, res.stderr[-2000:]
        c = json.loads((d / "meta.json").read_text())["commands"]
        assert c["commands_verified"] and c["commands_late"] == 0, c
        assert c["commands_unacknowledged"] == 0, c
        assert _signals(d) == _signals(clean), f"deaf for {deaf} sample(s): the trace changed"


def test_a_21_controller_runs_and_is_told_unverified(tmp_path: Path) -> None:
    res, d = _run(tmp_path, extra_ctrl=("--protocol", "2.1"))
    assert res.returncode == 0, res.stderr[-2000:]
    assert "cannot verify that it received its BenchCommand frames" in res.stderr
    assert not json.loads((d / "meta.json").read_text())["commands"]["commands_verified"]


@pytest.mark.slow
def test_twenty_external_runs_on_a_default_socket_are_identical(tmp_path: Path) -> None:
    """Issue 26: xue-fig13 (502 commands, a ramp of one per period) twenty times in
    external lockstep with the test controller's default receive buffer: one
    ``signals.csv``, every run verified, none late."""
    scn = ROOT / "bench" / "scenarios" / "xue-fig13.toml"
    traces = set()
    for i in range(20):
        res, d = _run(tmp_path / f"r{i}", scenario=scn)
        assert res.returncode == 0, res.stderr[-2000:]
        c = json.loads((d / "meta.json").read_text())["commands"]
        assert c["commands_verified"] and c["commands_late"] == 0, c
        assert c["commands_unacknowledged"] == 0, c
        traces.add(_signals(d))
    assert len(traces) == 1


def test_a_trip_is_named_with_its_own_period_not_the_newest_status(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A run that printed "tripped watchdog in period 20000" (its last PlantStatus)
    while the plant tripped in period 6776: the line takes the trip's own frame."""
    import can

    from bench.runs._recorder import Recorder
    from bench.runs._run import DutWatch

    codec = Codec()

    class Drop(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            pass

    rec = Recorder(codec, Drop(), 1)
    for state, code, step in ((1, 0, 6000), (2, 1, 6776), (2, 1, 7000), (0, 1, 20000)):
        rec.on_message_received(
            codec.encode(
                "PlantStatus",
                {"state": state, "fault_code": code, "overruns": 0, "late_frames": 0, "step": step},
            )
        )

    class Rec:
        def __init__(self) -> None:
            self.recorders = [rec]
            self.duty_watch = rec

    DutWatch(Rec(), 5.0, "bus").check(20000)  # type: ignore[arg-type]
    assert "tripped watchdog in period 6776," in capsys.readouterr().err


def test_the_dut_timeout_counts_from_the_nodes_readiness() -> None:
    """--dut-timeout is the controller's time to answer: the nodes' start-up (seconds on a
    loaded host) before ``start`` does not count."""
    import can

    from bench.runs._recorder import Recorder
    from bench.runs._run import DutWatch

    class Drop(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            pass

    class Rec:
        def __init__(self) -> None:
            r = Recorder(Codec(), Drop(), 1)
            self.recorders = [r]
            self.duty_watch = r

    late = DutWatch(Rec(), 2.0, "bus")  # type: ignore[arg-type]
    late.t0 -= 10.0  # the nodes took 10 s to start
    assert late.check(0) is True  # counted from construction: timed out before a period
    ready = DutWatch(Rec(), 2.0, "bus")  # type: ignore[arg-type]
    ready.t0 -= 10.0
    ready.start()
    assert ready.check(0) is False


@pytest.mark.parametrize("engine", ["native", "python"])
def test_a_duty_drop_paces_the_plant_on_a_controller_under_test(
    tmp_path: Path, engine: str
) -> None:
    """Lockstep, the duties dropped for 50 ms (a [[faults]] drop of PwmDuty, expect trip):
    the plant does not apply them, but it still waits for each to arrive before the next
    period, as for any duty.  Without that wait it ran the 500 periods at its own pace, a
    controller under test (a Python one, a default receive buffer) lost samples in the
    burst, stopped answering, and the run ended at the fault's end with 999 rows missing.
    Now the run is whole: the trip expected and met, every period a row."""
    scn = tmp_path / "duty-drop.toml"
    scn.write_text(
        (ROOT / "tests" / "data" / "firmware-100rpm.toml")
        .read_text()
        .replace("duration = 0.3", "duration = 0.4")
        + '\n[[faults]]\nkind = "drop"\nmessage = "PwmDuty"\nprob = 1.0\nat_s = 0.25\n'
        'duration_s = 0.05\nexpect = "trip"\n'
    )
    res, d = _run(tmp_path / "drop", "--engine", engine, scenario=scn)
    assert res.returncode == 0, res.stderr[-2000:]
    assert json.loads((d / "meta.json").read_text())["node_engines"] == {"plant": engine}
    m = json.loads((d / "metrics.json").read_text())
    (f,) = m["faults"]
    assert f["met"] and f["detected_by"] == "watchdog", f
    assert m["steps_missing"] == 0 and m["steps"] == 4001, (m["steps"], m["steps_missing"])
    assert "no row in signals.csv" not in res.stderr
