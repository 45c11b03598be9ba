"""The start-up on the drive plant: the bridge's drops bias the polarity test unless compensated.

xue-fig13 on the ``drive`` profile (1.5 V device drops at 1 kHz): the drops
oppose each polarity pulse's rise and aid its return, which leaves a d-axis
current offset of the order of the saturation asymmetry the test measures,
and the test keeps the estimate on the magnet's south (180 degrees).  With the
controller's dead-time and drop feed-forward on (``[controller]
dead_time_compensation``, on by default where the bridge has dead time or
drops), applied to the pulses as to every other voltage, the test decides right.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from bench.nodes._loops import run_inprocess
from bench.runs._analysis import analyze_frames
from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import sample_period
from bench.wire._codec import Codec


def error_after_startup(compensate: bool) -> float:
    """The largest |dtheta| once running; ``compensate``: the drive plant's default
    countermeasures, else the same with only the dead-time feed-forward switched off."""
    scn = load_scenario("xue-fig13").with_overrides(plant_profile="drive", duration=0.6)
    if not compensate:
        scn = dataclasses.replace(scn, controller={"dead_time_compensation": False})
    codec = Codec()
    t = analyze_frames(
        run_inprocess(scn, "square-wave", codec), codec, T_s=sample_period(scn), n_p=4
    ).table
    running = t["mode"] == 3
    assert running.any()
    return float(np.max(np.abs(t["theta_err_deg"][running])))


def test_uncompensated_drops_leave_the_estimate_on_the_south_pole() -> None:
    assert error_after_startup(False) > 170.0


def test_with_the_feed_forward_the_polarity_test_decides_right() -> None:
    assert error_after_startup(True) < 10.0
