"""A protection trip of the plant is reported: a warning, ``metrics.json``, exit status 3.

A load far above the motor's rating runs the wen2023 machine backwards
past its over-speed limit within a tenth of a second; the plant trips and
runs the rest of the scenario in the safe state.  That run is not a
scenario result, and ``bench run`` must say so rather than print its table
as if nothing happened; ``bench analyze`` finds the same trip in the capture.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench.cli import EXIT_PLANT_TRIPPED, main
from tests.ports import free_port


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
    # the same trip, found offline in the capture's PlantStatus frames
    again = tmp_path / "again"
    assert main(["analyze", str(out / "capture.blf"), "--out", str(again)]) == 0
    m2 = json.loads((again / "metrics.json").read_text())
    assert (m2["plant_fault"], m2["plant_fault_step"]) == ("over_speed", k)


def test_a_run_without_trip_says_none(tmp_path: Path) -> None:
    out = tmp_path / "run"
    argv = ["run", "wen-5.1", "-e", "sensored", "--duration", "0.05", "--out", str(out), "-q"]
    assert main([*argv, "--port", str(free_port())]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert (m["plant_fault"], m["plant_fault_step"]) == ("none", -1)
