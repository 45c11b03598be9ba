"""``bench show``: the command schedule in compact form (segments), the start-up and the
scoring start in its text; every frame behind ``--commands`` and in ``--json``."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest

from bench.cli import main
from bench.scenarios._describe import profile_segments, schedule
from bench.scenarios._schema import SHIPPED, Profile, load_scenario
from bench.scenarios._setup import command_schedule


def _value(segs: list[dict], t: float) -> float:
    """A profile's value at ``t`` from its segments alone (a step takes effect at its time)."""
    v = segs[0]["v0"]
    for g in segs:
        if t < g["t0_s"]:
            break
        if g["kind"] == "step" or t >= g["t1_s"]:
            v = g["v1"]
        else:
            frac = (t - g["t0_s"]) / (g["t1_s"] - g["t0_s"])
            v = g["v0"] + (g["v1"] - g["v0"]) * frac
    return float(v)


def test_segments_of_a_profile_with_every_kind() -> None:
    prof = Profile(((0.5, 10.0), (1.0, 10.0), (1.0, 20.0), (2.0, 40.0), (3.0, 40.0), (4.0, 0.0)))
    segs = profile_segments(prof, 3.5)
    assert [(g["kind"], g["t0_s"], g["t1_s"], g["v0"], g["v1"]) for g in segs] == [
        ("constant", 0.0, 1.0, 10.0, 10.0),  # the value before the first point, merged
        ("step", 1.0, 1.0, 10.0, 20.0),
        ("ramp", 1.0, 2.0, 20.0, 40.0),
        ("constant", 2.0, 3.0, 40.0, 40.0),
        ("ramp", 3.0, 3.5, 40.0, 20.0),  # cut by the run's end: the value it reaches there
    ]


@pytest.mark.parametrize("name", SHIPPED)
def test_the_segments_give_the_profiles_and_count_every_frame(name: str) -> None:
    scn = load_scenario(name)
    sc = schedule(scn)
    cmds = command_schedule(scn)
    assert sc["frames"] == len(cmds)
    # lockstep: what `bench run` sends, keep-alives included (each a seq of its own)
    from bench.nodes._loops import command_frames
    from bench.runs._pacing import PACE_EVERY
    from bench.wire._codec import Codec

    assert sc["frames_lockstep"] == len(command_frames(scn, Codec(), PACE_EVERY)) >= len(cmds)
    assert (sc["start_step"], sc["stop_step"]) == (cmds[0].apply_step, cmds[-1].apply_step)
    for key, prof in (("speed_rpm", scn.speed_rpm), ("load_nm", scn.load_nm)):
        segs = sc[key]
        assert segs[0]["t0_s"] == 0.0 and segs[-1]["t1_s"] == scn.duration
        for t in np.linspace(0.0, scn.duration, 997):
            assert _value(segs, float(t)) == pytest.approx(prof(float(t)), abs=1e-9), (key, t)
        # a constant takes no frame; every frame that changes this profile is in a segment
        assert all(g["frames"] == 0 for g in segs if g["kind"] == "constant")
        values = [c.speed_ref_rpm if key == "speed_rpm" else c.load_nm for c in cmds]
        changes = sum(1 for a, b in itertools.pairwise(values[:-1]) if a != b)
        assert sum(g["frames"] for g in segs) == changes


def test_show_text_is_compact_and_names_start_and_scoring(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["show", "wen-5.3"]) == 0
    text = capsys.readouterr().out
    lines = text.splitlines()
    assert len(lines) < 40  # 4602 frames, ten segments
    assert any("ramp 100 -> -100 rpm (2000 frames)" in ln and "2-4 s" in ln for ln in lines)
    assert any("ramp 0 -> 7.5 N m (300 frames)" in ln for ln in lines)
    assert "4602 BenchCommand frames" in text
    scn = load_scenario("wen-5.3")
    assert f"rotor at {scn.theta_e0_deg:g} deg electrical (theta_e0_deg)" in text
    assert "known_initial_angle = false" in text
    assert f"scoring from {scn.score_from_s:g} s (score_from_s)" in text
    assert main(["show", "wen-5.3", "--commands"]) == 0
    every = capsys.readouterr().out.splitlines()
    rows = [ln.split() for ln in every if ln.strip().split()[:1] and ln.split()[0].isdigit()]
    assert len(rows) == 4602 and rows[-1][:2] == ["90000", "stop"]


def test_show_json_keeps_every_frame_and_adds_the_schedule(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    f = tmp_path / "mine.toml"
    f.write_text(
        'extends = "xue-fig17"\ntheta_e0_deg = 12.5\nknown_initial_angle = true\n'
        "score_from_s = 0.7\n"
    )
    assert main(["show", str(f), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    for key in ("scenario", "pwm", "motor", "plant", "commands", "transport", "dbc_version"):
        assert key in d, key
    assert len(d["commands"]) == d["schedule"]["frames"] == 5
    assert d["start"] == {"theta_e0_deg": 12.5, "known_initial_angle": True, "score_from_s": 0.7}
    steps = [g for g in d["schedule"]["speed_rpm"] if g["kind"] == "step"]
    assert [(g["t0_s"], g["v0"], g["v1"]) for g in steps] == [
        (0.3, 0.0, 150.0),
        (1.3, 150.0, 300.0),
        (2.3, 300.0, 100.0),
    ]
    assert main(["show", str(f)]) == 0
    text = capsys.readouterr().out
    assert "known to the controller (known_initial_angle = true)" in text
    assert "rotor at 12.5 deg" in text and "scoring from 0.7 s" in text
