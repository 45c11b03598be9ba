"""The monitor's model without a terminal: frames encoded by the codec in, numbers out."""

from __future__ import annotations

import math

import can
import numpy as np
import pytest

from bench.monitor._model import MonitorModel, MonitorPars, Trace, envelope
from bench.monitor._reader import BusReader, receive_time
from bench.wire._busload import frame_time_us
from bench.wire._codec import Codec
from tests import monitor_helpers as known


@pytest.fixture(scope="module")
def codec() -> Codec:
    return Codec()


def feed(model: MonitorModel, frames: list[can.Message], t: float) -> None:
    for m in frames:
        model.on_frame(t, m)


def run_periods(model: MonitorModel, codec: Codec, ks: range, t0: float, dt: float, **kw) -> float:
    t = t0
    for k in ks:
        t = t0 + (k - ks.start) * dt
        feed(model, known.period_frames(codec, k, **kw), t)
    return t


def test_decoded_values_of_a_known_run(codec: Codec) -> None:
    model = MonitorModel(codec, MonitorPars(n_p=known.N_P))
    t = run_periods(model, codec, range(0, 50), 100.0, 1e-3, fault_code=2)
    model.update(t)
    n = model.numbers(t)
    assert n.status == "live"
    # names from the DBC's value tables, not numbers
    assert (n.state, n.fault, n.ctrl_mode) == ("running", "over_current", "run")
    assert n.step == 49
    assert n.speed_ref == pytest.approx(known.SPEED_RPM, abs=0.05)  # LSB 0.1 rpm
    assert n.speed == pytest.approx(known.SPEED_RPM, abs=0.1)  # LSB 0.01 rad/s
    assert n.speed_hat == pytest.approx(known.SPEED_RPM, abs=0.01)
    # one LSB of each angle: 2 pi / 65536 = 0.0055 deg
    assert n.theta_err == pytest.approx(known.ERR_DEG, abs=0.012)
    assert n.i_abc == (known.I_A, known.I_B, -known.I_A - known.I_B)
    assert n.duties == known.DUTIES
    assert (n.overruns, n.late_frames) == (known.OVERRUNS, known.LATE_FRAMES)
    assert n.tau_L == pytest.approx(known.LOAD_NM, abs=0.002)
    assert n.duty_age == 1
    assert n.rejected == {} and n.dropped == 0


def test_position_error_is_wrapped(codec: Codec) -> None:
    """True angle just past 0, estimate just below 2 pi: +1.72 deg, not -358."""
    model = MonitorModel(codec)
    model.on_frame(
        1.0,
        codec.encode(
            "PlantTruth",
            {"theta_e": 0.01, "w_m": 0.0, "tau_e": 0, "tau_L": 0, "step": 7, "duty_age": 0},
        ),
    )
    model.on_frame(
        1.0,
        codec.encode(
            "CtrlTelemetry",
            {"theta_hat": 2 * math.pi - 0.02, "w_hat": 0, "err": 0, "mode": 3, "step": 7},
        ),
    )
    model.update(1.0)
    assert model.numbers(1.0).theta_err == pytest.approx(math.degrees(0.03), abs=0.012)


def test_estimate_paired_with_truth_of_its_own_period(codec: Codec) -> None:
    """Telemetry of period 5 arriving after truth of period 6 is scored against truth 5."""
    model = MonitorModel(codec)

    def truth(k: int, th: float) -> can.Message:
        return codec.encode(
            "PlantTruth",
            {"theta_e": th, "w_m": 0.0, "tau_e": 0, "tau_L": 0, "step": k, "duty_age": 0},
        )

    model.on_frame(1.0, truth(5, 1.0))
    model.on_frame(1.0, truth(6, 2.0))
    model.on_frame(
        1.0,
        codec.encode(
            "CtrlTelemetry", {"theta_hat": 0.9, "w_hat": 0, "err": 0, "mode": 3, "step": 5}
        ),
    )
    model.update(1.0)
    assert model.numbers(1.0).theta_err == pytest.approx(math.degrees(0.1), abs=0.012)


def test_speed_reference_changes_at_its_apply_step(codec: Codec) -> None:
    """Commands are sent ahead: the reference changes when the plant reaches the step."""
    model = MonitorModel(codec)
    t = run_periods(model, codec, range(0, 10), 1.0, 1e-3)
    model.on_frame(
        t,
        codec.encode(
            "BenchCommand",
            {"cmd": 0, "seq": 5, "step": 40, "speed_ref": 300.0, "load_torque": 0.0},
        ),
    )
    t = run_periods(model, codec, range(10, 40), t, 1e-3, status=False)
    model.update(t)
    assert model.numbers(t).speed_ref == pytest.approx(known.SPEED_RPM)
    t = run_periods(model, codec, range(40, 41), t + 1e-3, 1e-3, status=False)
    model.update(t)
    assert model.numbers(t).speed_ref == pytest.approx(300.0)


def test_rates_and_bus_load_per_message(codec: Codec) -> None:
    """1000 duty and 1000 truth frames in one second: their rates and the wire time of each."""
    model = MonitorModel(codec, MonitorPars(bitrate=1e6, data_bitrate=5e6))
    model.update(10.0)
    duty = known.period_frames(codec, 1)[-1]
    truth = known.period_frames(codec, 1)[1]
    assert duty.arbitration_id == codec.frame_id("PwmDuty")
    assert truth.arbitration_id == codec.frame_id("PlantTruth")
    for i in range(1000):
        model.on_frame(10.0 + (i + 1) * 1e-3, duty)
        model.on_frame(10.0 + (i + 1) * 1e-3, truth)
    model.update(11.0)
    n = model.numbers(11.0)
    rates = {m.name: m for m in n.messages}
    assert rates["PwmDuty"].rate_hz == pytest.approx(1000.0)
    assert rates["PlantTruth"].rate_hz == pytest.approx(1000.0)
    t_duty = frame_time_us(8, fd=False, bitrate=1e6)  # 135 us with worst-case stuffing
    t_truth = frame_time_us(16, fd=True, bitrate=1e6, data_bitrate=5e6)
    assert rates["PwmDuty"].load == pytest.approx(1000 * t_duty * 1e-6)
    assert rates["PlantTruth"].load == pytest.approx(1000 * t_truth * 1e-6)
    assert n.total_load == pytest.approx(1000 * (t_duty + t_truth) * 1e-6)
    assert n.bus_name == "FD 1M/5M"
    # a classic reference bus carries the 16-byte FD frame as two 8-byte frames
    classic = MonitorModel(codec, MonitorPars(bitrate=500e3, data_bitrate=None))
    classic.update(0.0)
    classic.on_frame(0.5, truth)
    classic.update(1.0)
    (rate,) = classic.numbers(1.0).messages
    assert rate.load == pytest.approx(2 * frame_time_us(8, fd=False, bitrate=500e3) * 1e-6)


def _samples(codec: Codec, k: int) -> can.Message:
    return codec.encode(
        "PhaseSamples", {"i_a": 0.0, "i_b": 0.0, "u_dc": 540.0, "status": 1, "step": k}
    )


def test_stalls_are_gaps_much_longer_than_the_pwm_period(codec: Codec) -> None:
    model = MonitorModel(codec)
    t, k = 50.0, 0
    for _ in range(300):  # 1 kHz: 10 periods = 10 ms, so the 20 ms floor holds
        t += 1e-3
        k += 1
        model.on_frame(t, _samples(codec, k))
    assert model.numbers(t).period_s == pytest.approx(1e-3)
    for gap in (0.015, 0.05, 0.12, 0.003):  # 15 ms is under the floor: no stall
        # during the gap: "stalled" once over the threshold
        model.update(t + gap / 2)
        assert model.numbers(t + gap / 2).status == ("stalled" if gap / 2 > 0.02 else "live")
        t += gap
        k += 1
        model.on_frame(t, _samples(codec, k))
    model.update(t)
    n = model.numbers(t)
    assert n.stalls == 2
    assert n.longest_stall_s == pytest.approx(0.12)
    # a pause of the whole bench beyond 2 s: "stopped", and not a stall
    assert model.numbers(t + 2.5).status == "stopped"
    assert "stopped: no bench frames for 2.5 s" in model.numbers(t + 2.5).status_line
    model.on_frame(t + 3.0, _samples(codec, k + 1))
    n = model.numbers(t + 3.0)
    assert (n.stalls, n.restarts) == (2, 1)


def test_stall_threshold_follows_a_slow_pwm(codec: Codec) -> None:
    """At 100 Hz, 10 periods are 100 ms: a 50 ms gap is no stall, a 150 ms gap is."""
    model = MonitorModel(codec)
    t = 0.0
    for k in range(300):
        t += 0.01
        model.on_frame(t, _samples(codec, k))
    for gap in (0.05, 0.15):
        t += gap
        model.on_frame(t, _samples(codec, 300))
    assert model.numbers(t).stalls == 1


def test_no_bench_frames_nothing_or_only_foreign(codec: Codec) -> None:
    model = MonitorModel(codec)
    model.update(5.0)
    n = model.numbers(8.0)
    assert n.status == "waiting"
    assert n.status_line == "no bench frames on the bus: nothing received for 3 s"
    for i in range(20):
        model.on_frame(8.0 + i * 0.01, known.foreign_frame(0x123 if i % 2 else 0x7FF))
    model.update(8.5)
    n = model.numbers(8.5)
    assert n.status == "foreign"
    assert n.status_line.startswith("no bench frames on the bus: only foreign IDs (0x123, 0x7FF")
    assert [m.name for m in n.messages] == ["foreign"] and n.messages[0].frames == 20
    assert n.rejected == {}  # foreign frames are not rejections
    # bench frames then silence: stopped, and foreign traffic named as such
    feed(model, known.period_frames(codec, 0), 9.0)
    model.update(9.0)
    assert model.numbers(9.0).status == "live"
    model.on_frame(11.5, known.foreign_frame())
    n = model.numbers(11.6)
    assert n.status == "stopped"
    assert "the bus carries only foreign IDs now" in n.status_line


def test_rejections_by_reason(codec: Codec) -> None:
    model = MonitorModel(codec)
    good = known.period_frames(codec, 3)[-1]  # PwmDuty
    bad_crc = can.Message(
        arbitration_id=good.arbitration_id,
        data=bytes([good.data[0] ^ 1, *good.data[1:]]),
        is_extended_id=False,
    )
    short = can.Message(
        arbitration_id=good.arbitration_id, data=bytes(good.data[:7]), is_extended_id=False
    )
    for m in (good, bad_crc, bad_crc, short):
        model.on_frame(1.0, m)
    model.update(1.0)
    n = model.numbers(1.0)
    assert n.rejected == {"PwmDuty": {"bad_crc": 2, "bad_length": 1}}
    assert n.duties == known.DUTIES  # the good frame's values, not the corrupted ones
    assert n.decoded == 4


def test_frames_the_view_cannot_take_are_dropped_and_counted(codec: Codec) -> None:
    model = MonitorModel(codec, MonitorPars(max_view_frames=10))
    model.update(0.0)
    duties = [
        codec.encode(
            "PwmDuty", {"duty_a": i / 100, "duty_b": 0.5, "duty_c": 0.5, "enable": 1, "step": i}
        )
        for i in range(25)
    ]
    for i, m in enumerate(duties):
        model.on_frame(0.5 + i * 1e-3, m)
    model.update(1.0)
    n = model.numbers(1.0)
    assert (n.dropped, n.decoded) == (15, 10)
    assert n.duties is not None and n.duties[0] == pytest.approx(0.24, abs=3.1e-5)  # the newest
    (rate,) = n.messages
    assert rate.frames == 25 and rate.rate_hz == pytest.approx(25.0)  # the rate counts them all
    # a full queue drops at the reader, counted the same way
    full = MonitorModel(codec, MonitorPars(queue_frames=5))
    for i, m in enumerate(duties[:8]):
        full.on_frame(i * 1e-3, m)
    full.update(1.0)
    n = full.numbers(1.0)
    assert (n.dropped, n.decoded) == (3, 5)


def test_reset_zeroes_the_statistics(codec: Codec) -> None:
    model = MonitorModel(codec, MonitorPars(n_p=known.N_P))
    t = run_periods(model, codec, range(0, 20), 1.0, 1e-3)
    bad = can.Message(arbitration_id=codec.frame_id("PwmDuty"), data=bytes(8), is_extended_id=False)
    model.on_frame(t, bad)
    model.update(t)
    assert model.numbers(t).rejected
    model.reset(t)
    t = run_periods(model, codec, range(100, 101), t + 1e-3, 1e-3)
    model.update(t)
    n = model.numbers(t)
    assert n.rejected == {} and n.stalls == 0
    assert (n.overruns, n.late_frames) == (0, 0)  # the plant's counters since the reset
    assert n.speed == pytest.approx(known.SPEED_RPM, abs=0.1)  # values stay


def test_pole_pairs_inferred_from_estimated_over_true_speed(codec: Codec) -> None:
    model = MonitorModel(codec)
    t = run_periods(model, codec, range(0, 30), 1.0, 1e-3)
    model.update(t)
    assert model.numbers(t).n_p is None and model.numbers(t).speed_hat is None
    t = run_periods(model, codec, range(30, 80), t, 1e-3)
    model.update(t)
    n = model.numbers(t)
    assert (n.n_p, n.n_p_inferred) == (known.N_P, True)
    assert n.speed_hat == pytest.approx(known.SPEED_RPM, abs=0.01)


def test_envelope_keeps_the_peaks_of_a_fast_signal() -> None:
    """A 1 kHz sine sampled at 10 kHz, drawn in 50 columns: each column spans the ripple."""
    t = np.arange(10000) * 1e-4
    v = np.sin(2 * np.pi * 1000.0 * t + 0.3)
    x, y = envelope(t, v, 0.0, 1.0, 50)
    lo, hi = y[0::2], y[1::2]
    assert len(x) == 100
    assert np.all(lo < -0.95) and np.all(hi > 0.95)
    assert np.all(np.diff(x) >= 0)
    # few points are drawn as they are
    x, y = envelope(t[:20], v[:20], 0.0, 1.0, 50)
    assert np.array_equal(y, v[:20])


def test_trace_ring_keeps_the_newest_points_in_order() -> None:
    tr = Trace(8, min_dt=0.0)
    for i in range(20):
        tr.append(float(i), float(10 * i))
    t, v = tr.arrays()
    assert t.tolist() == [float(i) for i in range(12, 20)]
    assert v.tolist() == [10.0 * i for i in range(12, 20)]
    t, v = tr.window(14.0, 16.0)
    assert t.tolist() == [14.0, 15.0, 16.0]
    thin = Trace(100, min_dt=0.5)
    for i in range(10):
        thin.append(i * 0.2, 0.0)
    assert thin.arrays()[0].tolist() == pytest.approx([0.0, 0.6, 1.2, 1.8])


def test_receive_time_takes_the_kernel_stamp_only_when_it_is_this_clock() -> None:
    assert receive_time(99.7, 100.0) == 99.7
    assert receive_time(75.0, 100.0) == 75.0  # read 25 s late: still the kernel's stamp
    assert receive_time(12.0, 100.0) == 100.0  # an adapter's own clock
    assert receive_time(101.5, 100.0) == 100.0


class _ListenOnlyBus(can.BusABC):
    """Gives a fixed list of frames; any send fails the test."""

    def __init__(self, frames: list[can.Message]) -> None:
        self.frames = list(frames)
        super().__init__(channel="test")

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self.frames:
            return self.frames.pop(0), False
        return None, False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        raise AssertionError("the monitor sent a frame")


def test_reader_thread_feeds_every_frame_and_never_sends(codec: Codec) -> None:
    frames = [m for k in range(200) for m in known.period_frames(codec, k)]
    bus = _ListenOnlyBus(frames)
    model = MonitorModel(codec)
    reader = BusReader(bus, model)
    reader.start()
    try:
        import time

        deadline = time.monotonic() + 20.0
        while bus.frames and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        reader.stop()
        bus.shutdown()
    assert reader.error is None
    model.update(time.time())
    n = model.numbers(time.time())
    assert sum(m.frames for m in n.messages) == len(frames)
    assert n.step == 199


def test_screenshot_renders_the_view_of_known_frames(codec: Codec, tmp_path) -> None:
    """docs/USAGE.md's picture: the view drawn headless to SVG holds the decoded numbers."""
    from bench.monitor._screenshot import paced, screenshot

    frames = [m for k in range(400) for m in known.period_frames(codec, k)]
    timed = paced(frames, codec, 1e-3)
    assert timed[-1][0] == pytest.approx(0.4)
    out = screenshot(
        timed,
        tmp_path / "view.svg",
        at=0.4,
        codec=codec,
        pars=MonitorPars(n_p=known.N_P),
        title="known run",
        size=(150, 45),
    )
    svg = out.read_text().replace("&#160;", " ")
    for text in ("known run", "running", "150.0 rpm", "+3.0 deg el.", "+1.25 -0.50 -0.75 A"):
        assert text in svg, text


def test_without_a_terminal_one_line_error() -> None:
    import subprocess
    import sys

    out = subprocess.run(
        [sys.executable, "-m", "bench.cli.monitor", "-i", "udp_multicast", "--port", "9"],
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2
    assert (
        out.stderr == "bench: error: monitor: needs a terminal (standard input, output and error)\n"
    )


def test_periods_not_received_from_gaps_in_the_step_counter(codec: Codec) -> None:
    """Steps 1-3, 7, 8 (4-6 never came), a retransmitted 5, a repeated 8, a wrap past 1023."""
    model = MonitorModel(codec)
    t = 0.0
    for k in (1, 2, 3, 7, 5, 8, 8, *range(9, 1024), 1024, 1025):
        t += 1e-3
        model.on_frame(t, _samples(codec, k))
    assert model.numbers(t).missed == 3
    # another run after a pause: its steps start again, nothing is missed
    for k in (0, 1, 2):
        t += 3.0 if k == 0 else 1e-3
        model.on_frame(t, _samples(codec, k))
    assert model.numbers(t).missed == 3
    model.reset(t)
    assert model.numbers(t).missed == 0


def test_bench_run_monitor_without_a_terminal_is_one_line(
    capsys: pytest.CaptureFixture[str],
) -> None:
    from bench.cli import main

    assert main(["run", "wen-5.1", "--duration", "0.1", "--monitor"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--monitor: needs a terminal" in err[0]
