"""Recorded bench runs shared by the capture tests (analyze, rerun, replay).

Each run is recorded once per test session: two OS processes over
udp_multicast in lockstep, 0.2 s of wen-5.1 (2001 PWM periods at 10 kHz,
about 8000 frames), into pytest's temporary directory.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from bench.runs._metrics import ANGLE_METRICS
from bench.runs._run import run_scenario
from bench.scenarios._schema import load_scenario
from bench.wire._bus import BusSpec
from tests.ports import free_port

#: The metrics that a capture's analysis must reproduce exactly: the angle metrics
#: and the speed tracking, period counts and simulated time.
POSITION_SPEED = (
    *ANGLE_METRICS,
    "speed_track_err_max_rpm",
    "steps",
    "scored_steps",
    "sim_s",
)

_RUNS: dict[str, Path] = {}


def recorded_run(tmp_path_factory: pytest.TempPathFactory, estimator: str) -> Path:
    """Folder of a recorded wen-5.1 run (0.2 s, scored from 0.1 s) with ``estimator``."""
    if estimator not in _RUNS:
        scn = load_scenario("wen-5.1").with_overrides(duration=0.2, score_from_s=0.1)
        port = free_port()  # parallel runs on this host must not hear each other
        out = tmp_path_factory.mktemp(f"run-{estimator}")
        run_scenario(
            scn,
            estimator,
            spec=BusSpec("udp_multicast", "239.74.163.2", port),
            out_dir=out,
            progress=False,
        )
        _RUNS[estimator] = out
    return _RUNS[estimator]
