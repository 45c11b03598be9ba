"""Scenario keys of the plant: ``plant_profile``, ``[inverter]``, ``[sensors]``, ``[magnetics]``,
and ``extends``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench._errors import ScenarioError
from bench.cli._common import PLANT_PROFILES
from bench.runs._results import run_metadata
from bench.scenarios._schema import load_scenario, write_effective
from bench.scenarios._setup import build_plant, plant_setup
from plant_rt import PROFILE_NAMES


def scenario(tmp_path: Path, text: str, name: str = "mine.toml") -> Path:
    f = tmp_path / name
    f.write_text(text)
    return f


def test_the_command_line_knows_every_profile() -> None:
    assert PLANT_PROFILES == PROFILE_NAMES


def test_the_ideal_profile_is_the_plant_the_scenarios_had() -> None:
    scn = load_scenario("wen-5.1")
    assert scn.plant_profile == "ideal"
    plant = build_plant(scn)
    assert plant.inverter.model == "average" and plant.inverter.t_dead == 0.0
    assert plant.sensor_pars.bits is None and plant.sensor_pars.offset_abc == (0.0, 0.0, 0.0)
    assert plant.saturation and not plant.cross_saturation


def test_the_drive_profile_and_single_values_changed_by_the_tables(tmp_path: Path) -> None:
    f = scenario(
        tmp_path,
        'extends = "xue-fig13"\nplant_profile = "drive"\n'
        "[inverter]\nt_dead = 1e-6\nr_dc = 0.5\n"
        "[sensors]\ncurrent_offset_a = [0.02, 0.0, -0.02]\nadc_bits = 14\n"
        "[magnetics]\ncross_saturation = false\nc_dq = 0.0\n",
    )
    scn = load_scenario(str(f))
    p, prof = plant_setup(scn)
    assert prof.name == "drive"
    assert prof.inverter.model == "switching"  # from the profile
    assert (prof.inverter.t_dead, prof.inverter.r_dc, prof.inverter.v_ce) == (1e-6, 0.5, 1.5)
    assert prof.sensors.offset_abc == (0.02, 0.0, -0.02) and prof.sensors.bits == 14
    assert prof.sensors.gain_abc == (1.0, 1.005, 0.995)  # the profile's, not changed
    assert not prof.cross_saturation and p.motor.cross.c_dq == 0.0
    plant = build_plant(scn)
    assert plant.inverter == prof.inverter and plant.sensor_pars == prof.sensors
    meta = run_metadata(scn, "square-wave", mode="lockstep", transport="x", link=False)
    assert meta["plant"]["profile"] == "drive" and meta["plant"]["inverter"]["t_dead"] == 1e-6
    # the effective scenario a run hands its nodes keeps every value
    back = load_scenario(str(write_effective(scn, tmp_path / "scenario.json")))
    assert plant_setup(back) == plant_setup(scn)


def test_a_command_line_profile_replaces_the_scenarios() -> None:
    scn = load_scenario("wen-5.1").with_overrides(plant_profile="drive")
    assert plant_setup(scn)[1].inverter.model == "switching"


def test_extends_merges_tables_key_by_key_and_names_the_file_itself(tmp_path: Path) -> None:
    base = load_scenario("wen-5.1")
    f = scenario(
        tmp_path,
        'extends = "wen-5.1"\nduration = 1.5\n[estimator_options]\nV_h = 40.0\n'
        "[paper_result]\ntheta_err_min_deg = -1.0\n",
    )
    scn = load_scenario(str(f))
    assert scn.name == "mine" and scn.duration == 1.5
    assert scn.estimator_options == {"V_h": 40.0}
    assert scn.paper_result["theta_err_max_deg"] == 4.0  # a table of the base's, kept
    assert scn.speed_rpm == base.speed_rpm and scn.seed == base.seed
    assert scn.paper_result == {**base.paper_result, "theta_err_min_deg": -1.0}
    # a chain through a file of the user's, found beside the file that names it
    g = scenario(tmp_path, 'extends = "mine.toml"\nseed = 7\n', "second.toml")
    second = load_scenario(str(g))
    assert (second.seed, second.duration, second.name) == (7, 1.5, "second")


@pytest.mark.parametrize(
    ("text", "field"),
    [
        ('plant_profile = "lab"', "plant_profile"),
        ('[inverter]\nmodel = "svm"', "inverter.model"),
        ("[inverter]\nt_dead = 1e-3", "inverter.t_dead"),
        ("[inverter]\nu_dc = -5.0", "inverter.u_dc"),
        ('[inverter]\nsample_at = "middle"', "inverter.sample_at"),
        ("[inverter]\nvce = 1.0", "inverter.vce"),
        ("[sensors]\ncurrent_offset_a = [0.1, 0.2]", "sensors.current_offset_a"),
        ("[sensors]\nsample_delay_s = 0.5", "sensors.sample_delay_s"),
        ("[sensors]\nadc_bits = 40", "sensors.adc_bits"),
        ("[magnetics]\ncross_saturation = 1", "magnetics.cross_saturation"),
        ("[magnetics]\nsigma = 1.5", "magnetics.sigma"),
    ],
)
def test_a_wrong_plant_value_is_one_line_naming_the_field(
    tmp_path: Path, text: str, field: str
) -> None:
    f = scenario(tmp_path, f'extends = "wen-5.1"\n{text}\n')
    with pytest.raises(ScenarioError) as e:
        load_scenario(str(f))
    assert f"field '{field}'" in str(e.value) and "\n" not in str(e.value)
    assert str(f) in str(e.value)


def test_an_extends_cycle_or_an_unknown_base_is_one_line(tmp_path: Path) -> None:
    scenario(tmp_path, 'extends = "b.toml"\nduration = 1.0\n', "a.toml")
    b = scenario(tmp_path, 'extends = "a.toml"\n', "b.toml")
    with pytest.raises(ScenarioError, match="cycle"):
        load_scenario(str(b))
    c = scenario(tmp_path, 'extends = "wen-9.9"\n', "c.toml")
    with pytest.raises(ScenarioError, match="unknown scenario"):
        load_scenario(str(c))


def test_meta_of_an_ideal_run_names_its_plant() -> None:
    meta = run_metadata(
        load_scenario("xue-fig13"), "square-wave", mode="lockstep", transport="x", link=False
    )
    assert meta["plant"]["profile"] == "ideal"
    assert json.loads(json.dumps(meta, default=str))["plant"]["inverter"]["model"] == "average"


def test_the_controller_table_switches_the_drives_countermeasures(tmp_path: Path) -> None:
    from bench.scenarios._setup import build_controller

    f = scenario(
        tmp_path,
        'extends = "xue-fig15"\nplant_profile = "drive"\n[controller]\n'
        "dead_time_compensation = true\ncross_saturation_compensation = true\n"
        'offset_calibration = true\ncurrent_feedback = "raw"\nv_f = 1.2\n',
    )
    scn = load_scenario(str(f))
    ctrl = build_controller(scn, "square-wave")
    comp = ctrl.pars.compensation
    # the controller's own settings default to the plant's bridge, as a drive is configured
    assert comp.dead_time and comp.t_dead == 2e-6 and comp.v_ce == 1.5 and comp.v_f == 1.2
    assert comp.offset_calibration and comp.adc_lsb == pytest.approx(2 * 40.0 / 4096)
    assert comp.cross_saturation and ctrl.pars.current_feedback == "raw"
    g = ctrl.gains()
    assert g["comp.dead_time"] == 1.0 and g["comp.t_dead"] == 2e-6  # in meta.json's gains
    # k_dq from the plant's flux map at i_d = 0: dpsi_d/di_q = k_dq i_q
    p, _ = plant_setup(scn)
    from plant_rt import flux_dq

    i_q, h = 3.0, 1e-4
    dpsi = (
        flux_dq(p.motor, 0.0, i_q + h, True, True)[0]
        - flux_dq(p.motor, 0.0, i_q - h, True, True)[0]
    )
    assert ctrl.motor.k_dq * i_q == pytest.approx(dpsi / (2 * h), rel=1e-6)
    # off on the ideal plant, which has nothing to counter
    plain = build_controller(load_scenario("xue-fig15"), "square-wave").pars
    assert not (plain.compensation.dead_time or plain.compensation.offset_calibration)
    assert plain.current_feedback == "filtered"


@pytest.mark.parametrize(
    ("text", "field"),
    [
        ("dead_time_compensation = 1", "controller.dead_time_compensation"),
        ('current_feedback = "both"', "controller.current_feedback"),
        ("offset_periods = 0", "controller.offset_periods"),
        ("t_dead = 1.0", "controller.t_dead"),
        ("deadtime = true", "controller.deadtime"),
    ],
)
def test_a_wrong_controller_value_is_one_line(tmp_path: Path, text: str, field: str) -> None:
    f = scenario(tmp_path, f'extends = "xue-fig13"\n[controller]\n{text}\n')
    with pytest.raises(ScenarioError) as e:
        load_scenario(str(f))
    assert f"field '{field}'" in str(e.value)
