"""The in-process loop runs scenarios longer than the command counter's window.

``BenchCommand.step`` is 16 bits: 6.5 s at 10 kHz.  The loop hands the
commands to the nodes as ``bench run`` paces them (``INPROCESS_LEAD``
periods ahead), so a 7 s wen-5.3 (a reversal under full load) runs to its
end: without the pacing its later commands wrapped onto early steps and the
plant tripped over-speed at 0.19 s.
"""

from __future__ import annotations

import numpy as np
import pytest

from bench.nodes._counters import MAX_PENDING_COMMANDS
from bench.nodes._loops import INPROCESS_LEAD, run_inprocess
from bench.runs._analysis import analyze_frames
from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import get_preset, n_steps, sample_period
from bench.wire._codec import Codec


@pytest.mark.slow
def test_a_run_past_the_command_counters_window_runs_to_its_end() -> None:
    scn = load_scenario("wen-5.3").with_overrides(duration=7.0)
    codec = Codec()
    assert n_steps(scn) > 1 << codec.step_bits("BenchCommand")
    cap = analyze_frames(
        run_inprocess(scn, "tt-dq", codec),
        codec,
        T_s=sample_period(scn),
        n_p=get_preset(scn).motor.n_p,
    )
    t = cap.table
    assert int(t["step"][-1]) == n_steps(scn)
    assert not np.any(t["mode"] == 4)  # MODE_FAULT: no protection trip
    scored = t["t"] >= scn.score_from_s
    # the reversal under load is followed: down to -100 rpm, and the ramp back
    # (its reference commands come after the counter's wrap) is tracked to the end
    assert np.min(t["w_m_rpm"][scored]) < -90.0
    ref_end = scn.speed_rpm(float(t["t"][-1]))
    assert ref_end > -50.0 and abs(t["w_m_rpm"][-1] - ref_end) < 20.0
    # locked all along (the paper's own bound is the suite's business)
    assert np.max(np.abs(t["theta_err_deg"][scored])) < 30.0


def test_the_lead_fits_the_counter_and_the_queue() -> None:
    codec = Codec()
    assert (1 << codec.step_bits("BenchCommand")) // 2 > INPROCESS_LEAD
    assert INPROCESS_LEAD < MAX_PENDING_COMMANDS
