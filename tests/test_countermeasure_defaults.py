"""The drive's countermeasures follow what the scenario says of the controller's own hardware.

On by default where the bridge has dead time or drops, the sensors an
offset, the magnetics cross-saturation; each switched in ``[controller]``;
the suite's plants set all three themselves; ``meta.json`` and ``bench run``
name those on.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench.cli import main
from bench.runs._results import run_metadata
from bench.scenarios._schema import Scenario, load_scenario
from bench.scenarios._setup import (
    COUNTERMEASURES,
    build_controller,
    countermeasures,
    countermeasures_text,
)
from bench.studies._plants import PLANTS, plant_variant
from controller import CompensationPars

ALL_ON = dict.fromkeys(COUNTERMEASURES, True)
ALL_OFF = dict.fromkeys(COUNTERMEASURES, False)


def mine(tmp_path: Path, text: str, base: str = "wen-5.1") -> Scenario:
    f = tmp_path / "mine.toml"
    f.write_text(f'extends = "{base}"\n' + text)
    return load_scenario(str(f))


def test_the_papers_plant_gets_the_papers_controller() -> None:
    scn = load_scenario("wen-5.1")
    assert countermeasures(scn) == ALL_OFF
    assert build_controller(scn, "tt-dq").pars.compensation == CompensationPars()


def test_the_drive_plant_gets_every_countermeasure_by_default() -> None:
    scn = load_scenario("xue-fig15").with_overrides(plant_profile="drive")
    assert countermeasures(scn) == ALL_ON
    comp = build_controller(scn, "square-wave").pars.compensation
    assert comp.dead_time and comp.cross_saturation and comp.offset_calibration
    assert comp.t_dead == 2e-6 and comp.v_ce == comp.v_f == 1.5  # the plant's bridge


def test_a_users_switching_inverter_with_dead_time_is_compensated(tmp_path: Path) -> None:
    scn = mine(tmp_path, '[inverter]\nmodel = "switching"\nt_dead = 2e-6\n')
    assert countermeasures(scn) == {**ALL_OFF, "dead_time_compensation": True}
    assert build_controller(scn, "tt-dq").pars.compensation.dead_time


@pytest.mark.parametrize(
    ("text", "on"),
    [
        ("[inverter]\nv_f = 0.8\n", "dead_time_compensation"),  # drops alone
        ("[controller]\nt_dead = 1e-6\n", "dead_time_compensation"),  # the controller's own
        ("[sensors]\ncurrent_offset_a = [0.02, 0.0, 0.0]\n", "offset_calibration"),
        ("[magnetics]\ncross_saturation = true\n", "cross_saturation_compensation"),
        ("[controller]\nk_dq = -1e-4\n", "cross_saturation_compensation"),
    ],
)
def test_each_default_follows_its_own_hardware(tmp_path: Path, text: str, on: str) -> None:
    assert countermeasures(mine(tmp_path, text)) == {**ALL_OFF, on: True}


def test_no_cross_saturation_compensation_for_a_flux_map_without_it(tmp_path: Path) -> None:
    scn = mine(tmp_path, "[magnetics]\ncross_saturation = true\nc_dq = 0.0\n")
    assert countermeasures(scn) == ALL_OFF
    # and gains (noise, ADC) alone are nothing to counter
    scn = mine(tmp_path, "[sensors]\nadc_bits = 12\ncurrent_noise_a = 0.01\n")
    assert countermeasures(scn) == ALL_OFF


def test_a_switch_the_scenario_sets_wins(tmp_path: Path) -> None:
    scn = mine(tmp_path, 'plant_profile = "drive"\n[controller]\ndead_time_compensation = false\n')
    assert countermeasures(scn) == {**ALL_ON, "dead_time_compensation": False}
    comp = build_controller(scn, "tt-dq").pars.compensation
    assert not comp.dead_time and comp.offset_calibration and comp.cross_saturation
    scn = mine(tmp_path, "[controller]\noffset_calibration = true\n")  # on an exact sensor
    assert countermeasures(scn) == {**ALL_OFF, "offset_calibration": True}


@pytest.mark.parametrize("plant", PLANTS)
def test_every_suite_plant_sets_all_three_switches(tmp_path: Path, plant: str) -> None:
    # a scenario whose defaults would differ from every column's choice
    base = mine(tmp_path, "[sensors]\ncurrent_offset_a = 0.01\n[controller]\nv_f = 0.5\n")
    scn = plant_variant(base, plant)
    want = plant == "drive"
    assert {k: scn.controller[k] for k in COUNTERMEASURES} == dict.fromkeys(COUNTERMEASURES, want)
    assert countermeasures(scn) == dict.fromkeys(COUNTERMEASURES, want)
    assert scn.controller["v_f"] == 0.5  # the scenario's other values kept
    assert scn.plant_profile == ("ideal" if plant == "ideal" else "drive")


def test_meta_json_and_the_text_name_those_on() -> None:
    scn = load_scenario("wen-5.1").with_overrides(plant_profile="drive")
    meta = run_metadata(scn, "tt-dq", mode="lockstep", transport="x", link=False)
    assert meta["countermeasures"] == ALL_ON
    assert countermeasures_text(meta["countermeasures"]) == (
        "dead-time comp., cross-saturation comp., offset calibration"
    )
    ideal = run_metadata(load_scenario("wen-5.1"), "tt-dq", mode="lockstep", transport="x",
                         link=False)  # fmt: skip
    assert ideal["countermeasures"] == ALL_OFF and countermeasures_text(ALL_OFF) == "none"
    ext = run_metadata(scn, "external", mode="lockstep", transport="x", link=False)
    assert ext["countermeasures"] is None
    assert countermeasures_text(None) == "the controller's own"


def test_bench_run_prints_and_records_the_countermeasures(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run"
    args = ["run", "xue-fig13", "-e", "sensored", "--duration", "0.3", "--out", str(out), "-q"]
    assert main([*args, "--plant-profile", "drive"]) == 0
    text = capsys.readouterr().out
    assert "countermeasures: dead-time comp., cross-saturation comp., offset calibration" in text
    meta = json.loads((out / "meta.json").read_text())
    assert meta["countermeasures"] == ALL_ON
