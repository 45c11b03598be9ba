"""What the plant tells a controller author (docs/PROTOCOL.md): PlantStatus on its cycle,
late_frames with the rejected duties, wrong_step, the per-second rejection lines, the
stall line, and the pacing of the bench's commands."""

from __future__ import annotations

import itertools
import json
import shutil
import subprocess
import sys
from pathlib import Path

import can
import pytest

from bench.nodes._counters import RejectionSummary, rejection_text
from bench.nodes._loops import make_plant_node, stall_text, trip_text
from bench.nodes._plant_node import fault_name
from bench.nodes._plant_text import tripped_text
from bench.runs._pacing import COMMAND_BURST, PACE_EVERY, CommandPacer, command_lead
from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import command_schedule
from bench.wire._codec import Codec
from bench.wire._protocol import FAULT_WRONG_STEP, STATE_FAULT, STATE_RUNNING

CODEC = Codec()
STATUS = CODEC.frame_id("PlantStatus")
ROOT = Path(__file__).resolve().parents[1]


def duty(step: int, d_a: float = 0.5) -> can.Message:
    return CODEC.encode(
        "PwmDuty", {"duty_a": d_a, "duty_b": 0.5, "duty_c": 0.5, "enable": 1, "step": step}
    )


def _node(realtime: bool = False):
    node = make_plant_node(load_scenario("wen-5.1").with_overrides(duration=1.0), CODEC)
    node.started = True
    node.realtime = realtime
    return node


@pytest.mark.parametrize("realtime", [False, True])
def test_plant_status_every_100_ms_of_plant_time(realtime: bool) -> None:
    node = _node(realtime)
    assert node.status_every == 1000  # GenMsgCycleTime 100 ms at 10 kHz
    seen = []
    for _ in range(2500):
        node.on_message(duty(node.plant.k + 1))
        out = node.advance_realtime() if realtime else node.advance_lockstep()
        for m in out:
            if m.arbitration_id == STATUS:
                d = CODEC.decode(m)
                assert d is not None and d.ok
                seen.append((node.plant.k, int(d.signals["step"]), int(d.signals["state"])))
    assert seen == [(1000, 1000, STATE_RUNNING), (2000, 2000, STATE_RUNNING)]


def test_late_frames_counts_the_rejected_duties() -> None:
    node = _node()
    bad = bytearray(duty(1).data)
    bad[0] ^= 0xFF  # wrong CRC
    node.on_message(can.Message(arbitration_id=0x10, data=bytes(bad), is_extended_id=False))
    raw = bytearray(duty(1).data)  # a duty above 1: raw 20000 > 16384, CRC made right
    v = int.from_bytes(raw, "little") & ~(0x7FFF << 8) | (20000 << 8)
    raw = bytearray(v.to_bytes(8, "little"))
    from bench.wire._e2e import e2e_crc, e2e_start

    raw[0] = e2e_crc(e2e_start(0x1210), raw, 0)
    node.on_message(can.Message(arbitration_id=0x10, data=bytes(raw), is_extended_id=False))
    node.on_message(duty(5))  # future: the plant is at period 0
    assert node.duty_rejected == {"bad_crc": 1, "out_of_range": 1, "future_counter": 1}
    assert node.late_frames == 3
    d = CODEC.decode(node.status_frame(STATE_RUNNING))
    assert d is not None and d.signals["late_frames"] == 3


def test_a_duty_for_period_zero_trips_wrong_step() -> None:
    """A controller that tags the duty of sample k with k sends step 0 for sample 0."""
    node = _node()
    out = node.advance_lockstep()  # period 0 runs without a duty; sample 1 goes out
    node.on_message(duty(0))
    assert node.fault == FAULT_WRONG_STEP and fault_name(FAULT_WRONG_STEP) == "wrong_step"
    assert node.duty_rejected == {"wrong_step": 1} and node.dut_answered
    node.on_message(duty(1))
    out = node.advance_lockstep()
    st = [CODEC.decode(m) for m in out if m.arbitration_id == STATUS]
    assert st and st[0] is not None and st[0].signals["state"] == STATE_FAULT
    assert st[0].signals["fault_code"] == FAULT_WRONG_STEP
    choices = CODEC.message("PlantStatus").get_signal_by_name("fault_code").choices
    assert choices is not None and choices[5] == "wrong_step"
    assert "step k + 1" in trip_text(FAULT_WRONG_STEP, 1)
    assert node.report()["fault"] == "wrong_step"


def test_stall_text_names_the_skipped_sample_and_the_rejections() -> None:
    node = _node()
    node.advance_lockstep()  # at period 1, waiting for duty 1
    node.on_message(duty(2))  # the answer to sample 1 came, not the one to sample 0
    bad = bytearray(duty(1).data)
    bad[0] ^= 0x55
    node.on_message(can.Message(arbitration_id=0x10, data=bytes(bad), is_extended_id=False))
    s = stall_text(node, 5.0)
    assert "no valid PwmDuty for step 1 (the answer to sample 0) in 5 s" in s
    assert "skipped sample 0" in s and "PwmDuty: 1 rejected (bad_crc)" in s


def test_a_tripped_plant_names_the_time_it_waited_on_one_clock() -> None:
    """Both plant loops build the watchdog trip's line with ``tripped_text``: the time since
    the plant's last progress on the monotonic clock (the native loop's ``bn_now_ns``)."""
    import time

    node = _node()
    assert "in 5 s" in tripped_text(node, 100.0, 105.2)
    assert "in 0 ms" in tripped_text(node, time.monotonic())  # now: the same clock
    assert "in 52 ms" in tripped_text(node, 100.0, 100.052)  # under a second: in ms
    # the native loop passes its t_progress (CLOCK_MONOTONIC ns) as seconds
    t_ns = time.monotonic_ns() - 3_000_000_000
    assert "in 3 s" in tripped_text(node, t_ns * 1e-9)


def test_rejection_summary_once_a_second_with_what_is_new() -> None:
    s = RejectionSummary("PwmDuty")
    assert s.poll({"bad_crc": 5}, 100.0) is None  # starts the clock
    assert s.poll({"bad_crc": 500}, 100.5) is None
    assert s.poll({"bad_crc": 722}, 101.0) == "PwmDuty: 722 rejected (bad_crc) in the last second"
    assert s.poll({"bad_crc": 722}, 102.0) is None  # nothing new
    line = s.poll({"bad_crc": 730, "out_of_range": 2}, 105.0)
    assert line == "PwmDuty: 10 rejected (bad_crc 8, out_of_range 2) in the last 3 s"
    assert s.poll({"bad_crc": 731, "out_of_range": 2}, 105.1, force=True) is not None
    assert rejection_text({"bad_crc": 3}) == "3 rejected (bad_crc)"


class _Sink(can.BusABC):
    def __init__(self) -> None:
        self.sent: list[can.Message] = []
        super().__init__(channel="sink")

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.sent.append(msg)

    def _recv_internal(self, timeout: float | None) -> tuple[None, bool]:
        return None, False


def test_command_pacer_sends_each_command_twice_a_lead_ahead() -> None:
    scn = load_scenario("wen-5.2")
    pacer = CommandPacer(scn, CODEC, mode="lockstep")
    assert pacer.pace_every == PACE_EVERY and pacer.lead == command_lead(1e-4, "lockstep") == 5000
    assert command_lead(1e-3, "realtime") == 20 and command_lead(1e-4, "realtime") == 200
    bus = _Sink()
    n = pacer.send_due(bus, 0)
    steps = [s for s, _ in pacer.frames]
    # a lead ahead, but never more than COMMAND_BURST beyond the plant's step
    assert sum(s <= 5000 for s in steps) > 1 + COMMAND_BURST
    assert n == 1 + COMMAND_BURST and len(bus.sent) == 2 * n
    assert bus.sent[0].data == bus.sent[1].data  # the same command twice, same seq
    # keep-alives at least every PACE_EVERY periods, the scenario's own commands among them
    assert all(b - a <= PACE_EVERY for a, b in itertools.pairwise(steps))
    assert {c.apply_step for c in command_schedule(scn)} <= set(steps)
    k = steps[n - 1]  # the plant reaches the newest command sent: 32 more
    assert pacer.send_due(bus, k) == COMMAND_BURST
    assert sum(s > k for s in steps[: pacer.sent]) == COMMAND_BURST
    before = len(bus.sent)
    pacer.resend_all(bus)
    assert len(bus.sent) - before == pacer.sent
    pacer.send_stop(bus)
    d = CODEC.decode(bus.sent[-1])
    assert d is not None and d.signals["cmd"] == 2  # stop
    assert CommandPacer(scn, CODEC, mode="realtime").pace_every == 0


def test_show_gives_transport_port_and_dbc_version() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "bench", "show", "wen-5.1", "--json", "--interface",
         "udp_multicast"],
        cwd=ROOT, capture_output=True, text=True, check=True,
    )  # fmt: skip
    d = json.loads(out.stdout)
    assert d["transport"]["port"] == 43113 and d["transport"]["channel"]
    assert d["dbc_version"] == CODEC.version == "2.4"


@pytest.mark.skipif(shutil.which("cc") is None, reason="needs a C compiler")
def test_codegen_scenario_header_compiles_with_the_scenarios_values(tmp_path: Path) -> None:
    subprocess.run(
        [sys.executable, "-m", "bench", "codegen", str(tmp_path), "--scenario", "xue-fig17",
         "--commands"],
        cwd=ROOT, capture_output=True, text=True, check=True,
    )  # fmt: skip
    main = tmp_path / "main.c"
    main.write_text(
        '#include <stdio.h>\n#include "bench_scenario.h"\n'
        "static const bench_scn_command_t cmds[] = BENCH_SCN_COMMANDS;\n"
        "int main(void) {\n"
        '    printf("%g %g %ld %d %g %ld %u\\n", BENCH_SCN_PWM_FREQ_HZ, BENCH_SCN_MOTOR_L_D,\n'
        "           BENCH_SCN_PERIODS, (int)BENCH_SCN_N_COMMANDS, cmds[0].speed_ref_rpm,\n"
        "           cmds[BENCH_SCN_N_COMMANDS - 1].step, cmds[BENCH_SCN_N_COMMANDS - 1].cmd);\n"
        "    return 0;\n}\n"
    )
    exe = tmp_path / "main"
    subprocess.run(
        ["cc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-I", str(tmp_path), "-o", str(exe),
         str(main)],
        check=True,
    )  # fmt: skip
    got = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout.split()
    from bench.scenarios._describe import describe

    d = describe(load_scenario("xue-fig17"))
    cmds = d["commands"]
    assert float(got[0]) == d["pwm"]["f_sw_hz"] and float(got[1]) == pytest.approx(
        d["motor"]["L_d"]
    )
    assert int(got[2]) == d["pwm"]["periods"] and int(got[3]) == len(cmds)
    assert float(got[4]) == cmds[0]["speed_ref_rpm"]
    assert int(got[5]) == cmds[-1]["step"] and int(got[6]) == 2  # the stop at the end


def test_a_scenario_for_an_external_controller_needs_no_estimator(tmp_path: Path) -> None:
    """Without ``estimator`` keys the default (tt-dq) is not checked against the motor:
    a machine without saliency loads (an external controller brings its own estimator);
    naming an injection estimator for it still fails."""
    text = (
        'preset = "wen2023"\nduration = 0.1\nspeed_rpm = [[0.0, 100.0]]\n'
        "[motor]\nL_d = 0.07\nL_q = 0.07\n"
    )
    f = tmp_path / "spm.toml"
    f.write_text(text)
    assert load_scenario(str(f)).motor["L_q"] == 0.07
    f.write_text('estimator = "tt-dq"\n' + text)
    with pytest.raises(Exception, match=r"saliency|L_d"):
        load_scenario(str(f))


def test_controller_label_marks_an_external_controller() -> None:
    from bench.runs._plots import controller_label

    assert controller_label({"estimator": "tt-dq", "controller": "bench"}) == "tt-dq"
    assert controller_label({"controller": "external"}) == "external controller"
    ext = {"controller": "external", "controller_name": "fw-1.2"}
    assert controller_label(ext) == "external controller fw-1.2"
