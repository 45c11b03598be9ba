"""``bench rerun``: recorded samples through an estimator, offline, scored against truth.

The controller node is deterministic and sees the recorded (DBC-quantized)
samples and commands at the same steps as the live one, so the estimator
that made the capture must reproduce its logged telemetry byte for byte;
another estimator must give another trace, scored the same way.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import can
import numpy as np
import pytest

from bench.captures._read import (
    read_capture,
)
from bench.captures._rerun import rerun_capture
from bench.cli import main
from bench.runs._analysis import read_csv
from bench.wire._codec import Codec
from tests.replay_helpers import recorded_run

CODEC = Codec()


def quiet(_: str) -> None:
    pass


@pytest.fixture(scope="module")
def ttdq(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return recorded_run(tmp_path_factory, "tt-dq")


@pytest.mark.parametrize("estimator", ["tt-dq", "sensored"])
def test_rerun_with_the_recording_estimator_is_bit_exact(
    estimator: str, tmp_path_factory: pytest.TempPathFactory, tmp_path: Path
) -> None:
    run = recorded_run(tmp_path_factory, estimator)
    res = rerun_capture(run / "capture.blf", estimator, out_dir=tmp_path, plots=False, echo=quiet)
    est = res.report["estimate"]
    assert est["steps_compared"] == 2001
    assert est["steps_identical"] == 2001
    assert est["reproduces_recorded_bit_for_bit"]
    live = json.loads((run / "metrics.json").read_text())
    for key in ("theta_err_max_deg", "theta_err_min_deg", "theta_err_rms_deg", "speed_err_max_rpm"):
        assert res.metrics[key] == live[key], key
    a = read_csv(str(run / "signals.csv"))
    b = read_csv(str(tmp_path / "signals.csv"))
    for col in ("theta_hat", "w_hat_rpm", "est_err", "d_a", "d_b", "d_c"):
        np.testing.assert_array_equal(a[col], b[col], err_msg=col)


def test_rerun_with_another_estimator_is_scored_on_the_same_data(
    ttdq: Path, tmp_path: Path
) -> None:
    res = rerun_capture(ttdq, "sfhf", out_dir=tmp_path, plots=True, echo=quiet)
    est = res.report["estimate"]
    assert est["steps_compared"] == 2001
    assert est["steps_identical"] < 100
    assert not est["reproduces_recorded_bit_for_bit"]
    assert est["max_theta_hat_difference_deg"] > 1.0
    assert "fair comparison" in res.report["comparison"]
    assert res.report["recorded_estimator"] == "tt-dq"
    # scored against the recorded truth: the table's error is truth minus the new estimate
    t = read_csv(str(tmp_path / "signals.csv"))
    live = read_csv(str(ttdq / "signals.csv"))
    np.testing.assert_array_equal(t["theta_e"], live["theta_e"])
    np.testing.assert_array_equal(t["i_a"], live["i_a"])
    assert not np.array_equal(t["theta_hat"], live["theta_hat"])
    err = np.degrees((t["theta_e"] - t["theta_hat"] + np.pi) % (2 * np.pi) - np.pi)
    sel = t["t"] >= 0.1
    assert res.metrics["theta_err_max_deg"] == pytest.approx(float(np.max(err[sel])), abs=1e-5)
    assert res.metrics["theta_err_rms_deg"] != res.report["recorded_metrics"]["theta_err_rms_deg"]
    assert (tmp_path / "run.png").is_file() and (tmp_path / "rerun.json").is_file()


def test_rerun_of_a_capture_cut_mid_run_and_with_a_gap(ttdq: Path, tmp_path: Path) -> None:
    frames, _ = read_capture(ttdq / "capture.blf")
    sid = CODEC.frame_id("PhaseSamples")
    part = [
        m for i, m in enumerate(frames[4400:]) if not (2000 <= i < 2400 and m.arbitration_id == sid)
    ]
    with can.Logger(str(tmp_path / "part.blf")) as w:
        for m in part:
            w.on_message_received(m)
    shutil.copy(ttdq / "meta.json", tmp_path / "meta.json")
    res = rerun_capture(
        tmp_path / "part.blf", "tt-dq", out_dir=tmp_path / "o", plots=False, echo=quiet
    )
    r = res.report
    assert r["first_step"] > 1024
    assert r["sample_gap_steps"] > 50  # the missing samples were skipped, not waited for
    assert res.metrics["rerun_steps"] > 2001 - r["first_step"] - r["sample_gap_steps"] - 5


def test_cli_rerun(ttdq: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    rc = main(
        ["rerun", str(ttdq / "capture.blf"), "-e", "tt-ab", "--out", str(tmp_path), "--no-plots"]
    )
    out = capsys.readouterr().out
    assert rc == 0
    assert "note: open loop" in out and "theta_err_rms_deg" in out
    rc = main(["rerun", str(ttdq / "capture.blf"), "-e", "nope"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith("bench: error: --estimator")
    rc = main(["rerun", str(tmp_path / "missing.blf"), "-e", "tt-dq"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "missing.blf" in err[0]


def test_cli_rerun_that_loses_the_rotor_exits_4(
    ttdq: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """square-wave on a tt-dq capture sees no square-wave response and loses the angle:
    the status is bench run's for the same metrics (4), with its warning line."""
    rc = main(
        [
            "rerun",
            str(ttdq / "capture.blf"),
            "-e",
            "square-wave",
            "--out",
            str(tmp_path),
            "--no-plots",
        ]
    )
    err = capsys.readouterr().err
    m = json.loads((tmp_path / "metrics.json").read_text())
    assert m["lock_lost"] is True
    assert rc == 4
    assert "lost the rotor angle" in err
