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


def test_the_pair_returns_to_python_only_at_commands_and_the_end() -> None:
    from bench.nodes.native._pair import PairRun, run_pair

    scn = load_scenario("wen-5.1").with_overrides(duration=0.3)
    codec = Codec()
    pn = loops.make_plant_node(scn, codec)
    cn = loops.make_controller_node(scn, "tt-dq", codec)
    cmds = loops.command_frames(scn, codec)
    m = PairRun()
    frames = run_pair(pn, cn, cmds, loops.INPROCESS_LEAD, measure=m)
    assert m.steps == pn.plant.k == n_steps(scn)
    # at most: one feed and one due command per command, the buffer's returns, the end
    assert m.calls <= 2 * len(cmds) + len(frames) // (1 << 16) + 2
    assert m.calls < m.steps / 10
    # the frames come back as one array, timed apart from C and the rest
    assert isinstance(frames, FrameArray) and len(frames) >= 3 * m.steps
    assert 0 < m.frames_seconds < m.wall_seconds - m.c_seconds


def test_asking_for_the_pair_where_it_cannot_serve_names_why() -> None:
    scn = load_scenario("wen-5.1").with_overrides(duration=0.05)
    lat = replace(scn, latency=replace(scn.latency, sample_delay_steps=1))
    with pytest.raises(BenchError, match="latency"):
        loops.run_inprocess(lat, "tt-dq", Codec(), loop="native")
    # auto falls back to the Python loop, which runs the latency model
    assert loops.run_inprocess(lat, "tt-dq", Codec())
    with pytest.raises(BenchError, match="loop 'fast'"):
        loops.run_inprocess(scn, "tt-dq", Codec(), loop="fast")
