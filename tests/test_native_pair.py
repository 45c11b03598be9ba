"""The in-process native pair (issue 29, item 4): run_inprocess's loop in C.

``bench.nodes.native._pair.run_pair`` steps the plant unit and the controller unit
for many periods per call, with the frames passed in memory.  Its frames must be
the Python loop's, bit for bit and in the same order, on the same cores: checked
on wen-5.1 with tt-dq, a square-wave scenario and the drive plant, and on the
runs' traces.  The fallbacks (lockstep latency, Python between periods) run the
Python loop, and asking for the C loop where it cannot serve names the reason.
"""

from __future__ import annotations

import shutil
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import can
import numpy as np
import pytest

import bench.nodes._loops as loops
from bench._errors import BenchError
from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import n_steps
from bench.studies._plants import plant_variant
from bench.studies._reliability import run_trace
from bench.wire._codec import Codec
from bench.wire._frames import FrameArray
from controller import compiled_controller_missing

pytestmark = [
    pytest.mark.skipif(
        not any(shutil.which(c) for c in ("cc", "gcc")), reason="needs a C compiler"
    ),
    pytest.mark.skipif(
        compiled_controller_missing() is not None, reason="needs the compiled controller"
    ),
]


def _key(m: can.Message) -> tuple[int, bool, bool, bool, bytes]:
    return (m.arbitration_id, m.is_extended_id, m.is_fd, m.bitrate_switch, bytes(m.data))


def _both(scn: Any, estimator: str) -> tuple[Sequence[can.Message], Sequence[can.Message]]:
    codec = Codec()
    py = loops.run_inprocess(scn, estimator, codec, loop="python")
    native = loops.run_inprocess(scn, estimator, codec, loop="native")
    return py, native


CASES = [
    ("wen-5.1", "tt-dq", "shipped", 0.4),
    ("xue-fig13", "square-wave", "shipped", 1.0),
    ("wen-5.1", "tt-dq", "drive", 0.3),
    ("wen-5.2", "sfhf", "drive", 0.3),
    ("xue-fig14", "sensored", "shipped", 1.0),
]


@pytest.mark.parametrize(("name", "estimator", "plant", "duration"), CASES)
def test_the_pair_gives_the_python_loops_frames_bit_for_bit(
    name: str, estimator: str, plant: str, duration: float
) -> None:
    scn = load_scenario(name)
    if plant != "shipped":
        scn = plant_variant(scn, plant)
    scn = scn.with_overrides(duration=duration)
    py, native = _both(scn, estimator)
    assert len(py) > 2 * n_steps(scn)  # a sample and a duty in every period at least
    kp, kn = [_key(m) for m in py], [_key(m) for m in native]
    first = next((j for j, (a, b) in enumerate(zip(kp, kn, strict=False)) if a != b), None)
    assert first is None, f"frame {first} differs: {py[first]} against {native[first]}"
    assert len(kp) == len(kn)
    # the commands are in their places too (they are fed at the Python loop's points)
    cmd = Codec().frame_id("BenchCommand")
    assert [j for j, m in enumerate(py) if m.arbitration_id == cmd] == [
        j for j, m in enumerate(native) if m.arbitration_id == cmd
    ]
    # and the trace the suite scores is the same, array for array
    tp, tn = run_trace(py, scn), run_trace(native, scn)
    assert tp.keys() == tn.keys()
    for col in tp:
        assert np.array_equal(tp[col], tn[col], equal_nan=True), col


def test_run_inprocess_runs_the_pair_by_default(monkeypatch: pytest.MonkeyPatch) -> None:
    from bench.nodes.native import _pair

    calls: list[int] = []
    real = _pair.run_pair

    def counted(*a: Any, **k: Any) -> Sequence[can.Message]:
        calls.append(1)
        return real(*a, **k)

    monkeypatch.setattr(_pair, "run_pair", counted)
    scn = load_scenario("wen-5.1").with_overrides(duration=0.05)
    loops.run_inprocess(scn, "tt-dq", Codec())
    assert calls == [1]
    # Python between periods (observe, plant_times): the Python loop
    seen: list[float] = []
    loops.run_inprocess(scn, "tt-dq", Codec(), plant_times=seen)
    assert calls == [1] and len(seen) >= 400


def _pair_run(scn: Any, monkeypatch: pytest.MonkeyPatch, record: int) -> tuple[Any, Any, Any]:
    """run_pair on ``scn`` (square-wave) with a record buffer of ``record`` frames."""
    from bench.nodes.native import _pair

    monkeypatch.setattr(_pair, "RECORD_FRAMES", record)
    codec = Codec()
    pn = loops.make_plant_node(scn, codec)
    cn = loops.make_controller_node(scn, "square-wave", codec)
    cmds = loops.command_frames(scn, codec)
    m = _pair.PairRun()
    frames = _pair.run_pair(pn, cn, cmds, loops.INPROCESS_LEAD, measure=m)
    return m, frames, cmds


def test_the_pair_returns_to_python_only_for_a_full_buffer_and_the_end(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # xue-fig13: a command every period from step 301, more pending at a time than
    # the C lists hold (they wait for room); each was two returns before the schedule
    scn = load_scenario("xue-fig13").with_overrides(duration=1.0)
    m, frames, cmds = _pair_run(scn, monkeypatch, 1 << 16)
    assert m.steps == n_steps(scn) and len(cmds) > 500
    assert len(frames) < (1 << 16)
    assert m.calls == 1  # the frames fit: the end, and nothing else
    # a buffer of 1,000 frames: one return per buffer filled (an instant's frames, at
    # most 28, go in whole, so a return leaves between 972 and 1,000 frames), and the end
    m, frames, _ = _pair_run(scn, monkeypatch, 1000)
    recorded = len(frames) - 1  # the start command, fed by Python before the run
    assert recorded // 1000 + 1 <= m.calls <= recorded // 972 + 1
    # the frames come back as one array, timed apart from C and the rest
    assert isinstance(frames, FrameArray) and len(frames) >= 3 * m.steps
    assert 0 < m.frames_seconds < m.wall_seconds - m.c_seconds


def test_a_stop_command_ends_the_pair_where_it_ends_the_python_loop(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # wen-5.1: a set-point every 10 periods from step 3010, fed 1,000 ahead; one made a
    # stop at 3,500: the commands fed before it applies are recorded, the later ones
    # never fed (the schedule leaves them out), and the run ends with it
    from bench.scenarios._setup import command_schedule
    from bench.wire._protocol import CMD_STOP

    scn = load_scenario("wen-5.1").with_overrides(duration=0.6)
    stop_at = 3500
    plan = [
        replace(c, cmd=CMD_STOP) if c.apply_step == stop_at else c for c in command_schedule(scn)
    ]
    real = loops.command_frames
    monkeypatch.setattr(loops, "command_frames", lambda s, c, *a, **k: real(s, c, schedule=plan))
    py, native = _both(scn, "tt-dq")
    assert [_key(m) for m in py] == [_key(m) for m in native]
    codec = Codec()
    fed = [m for m in native if m.arbitration_id == codec.frame_id("BenchCommand")]
    d = codec.decode(fed[-1])
    assert d is not None
    last = d.signals["step"]
    assert last == stop_at + loops.INPROCESS_LEAD - 10  # fed at 3,490: the last before it
    duties = sum(m.arbitration_id == codec.frame_id("PwmDuty") for m in native)
    assert duties == stop_at + 1  # periods 0 to 3,500 answered, none after


def test_asking_for_the_pair_where_it_cannot_serve_names_why() -> None:
    scn = load_scenario("wen-5.1").with_overrides(duration=0.05)
    lat = replace(scn, latency=replace(scn.latency, sample_delay_steps=1))
    with pytest.raises(BenchError, match="latency"):
        loops.run_inprocess(lat, "tt-dq", Codec(), loop="native")
    # auto falls back to the Python loop, which runs the latency model
    assert loops.run_inprocess(lat, "tt-dq", Codec())
    with pytest.raises(BenchError, match="loop 'fast'"):
        loops.run_inprocess(scn, "tt-dq", Codec(), loop="fast")
