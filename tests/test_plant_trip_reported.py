"""A protection trip of the plant is reported: a warning, ``metrics.json``, exit status 3.

A load far above the motor's rating runs the wen2023 machine backwards
past its over-speed limit within a tenth of a second; the plant trips and
runs the rest of the scenario in the safe state.  That run is not a
scenario result, and ``bench run`` must say so rather than print its table
as if nothing happened; ``bench analyze`` finds the same trip in the capture.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import can
import pytest

from bench._errors import EXIT_PLANT_TRIPPED
from bench.cli import main
from bench.runs._results import plant_fault
from bench.wire._codec import Codec
from plant_rt import FAULT_OVER_VOLTAGE
from tests.ports import free_port

CODEC = Codec()


def test_trip_is_a_warning_a_metric_and_an_exit_status(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scn = tmp_path / "load30.toml"
    scn.write_text(
        'preset = "wen2023"\nduration = 0.1\nknown_initial_angle = true\nload_nm = [[0.0, 30.0]]\n'
    )
    out = tmp_path / "run"
    argv = ["run", str(scn), "-e", "sensored", "--out", str(out), "--quiet"]
    assert main([*argv, "--port", str(free_port())]) == EXIT_PLANT_TRIPPED == 3
    err = capsys.readouterr().err
    plant = json.loads((out / "plant.json").read_text())
    assert plant["fault"] == "over_speed"
    k = plant["fault_step"]
    assert f"tripped its over_speed protection in period {k} " in err
    m = json.loads((out / "metrics.json").read_text())
    assert (m["plant_fault"], m["plant_fault_step"]) == ("over_speed", k)
    # the same trip, found offline in the capture's PlantStatus frames alone
    # (a copy without meta.json, so without the plant's report)
    lone = tmp_path / "lone"
    lone.mkdir()
    shutil.copy(out / "capture.blf", lone / "capture.blf")
    again = tmp_path / "again"
    argv = ["analyze", str(lone / "capture.blf"), "--scenario", str(scn), "--out", str(again)]
    assert main(argv) == EXIT_PLANT_TRIPPED  # bench analyze gives bench run's status
    m2 = json.loads((again / "metrics.json").read_text())
    assert (m2["plant_fault"], m2["plant_fault_step"]) == ("over_speed", k)


def test_a_run_without_trip_says_none(tmp_path: Path) -> None:
    out = tmp_path / "run"
    argv = ["run", "wen-5.1", "-e", "sensored", "--duration", "0.05", "--out", str(out), "-q"]
    assert main([*argv, "--port", str(free_port())]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert (m["plant_fault"], m["plant_fault_step"]) == ("none", -1)


def _truth(k: int, channel: int) -> can.Message:
    sig = {"theta_e": 0.0, "w_m": 0.0, "tau_e": 0.0, "tau_L": 0.0, "duty_age": 1, "step": k}
    m = CODEC.encode("PlantTruth", sig)
    m.channel = channel
    return m


def _status(k: int, code: int) -> can.Message:
    sig = {"state": 2, "fault_code": code, "overruns": 0, "late_frames": 0, "step": k % 65536}
    return CODEC.encode("PlantStatus", sig)


def test_trip_period_past_the_status_counters_wrap_on_two_buses() -> None:
    """The 16-bit status step is placed by the plant's 32-bit truth step, not by counting frames.

    A two-bus capture (a link run) carries every truth frame twice, and a
    trip after period 65,536 needs the wrap resolved.
    """
    k_trip = 70_000
    frames = [_truth(k, ch) for k in range(k_trip - 5, k_trip) for ch in (1, 2)]
    frames += [_status(k_trip, FAULT_OVER_VOLTAGE), _status(k_trip + 3, FAULT_OVER_VOLTAGE)]
    assert plant_fault(frames, CODEC) == ("over_voltage", k_trip)
    # a capture that starts mid-run: the same
    assert plant_fault(frames[6:], CODEC) == ("over_voltage", k_trip)
    # status frames without a fault (state reports) are not trips
    assert plant_fault([*frames[:4], _status(k_trip, 0)], CODEC) == ("none", -1)
