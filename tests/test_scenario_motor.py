"""A scenario's ``[motor]`` table: explicit motor parameters instead of the preset's."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench._errors import ScenarioError
from bench.scenarios._schema import load_scenario, write_effective
from bench.scenarios._setup import build_controller, build_plant, get_preset
from plant_rt import preset

ROOT = Path(__file__).resolve().parents[1]
WEN = (ROOT / "bench" / "scenarios" / "wen-5.1.toml").read_text()


def _write(tmp_path: Path, extra: str) -> str:
    f = tmp_path / "m.toml"
    f.write_text(WEN + "\n" + extra)
    return str(f)


def test_motor_table_replaces_the_presets_values_for_plant_and_controller(
    tmp_path: Path,
) -> None:
    scn = load_scenario(_write(tmp_path, "[motor]\nR_s = 1.4\nJ = 0.006\nn_p = 2\n"))
    assert scn.motor == {"n_p": 2, "R_s": 1.4, "J": 0.006}
    p = get_preset(scn)
    base = preset("wen2023").motor
    assert (p.motor.R_s, p.motor.J, p.motor.n_p) == (1.4, 0.006, 2)
    assert (p.motor.L_d, p.motor.L_q, p.motor.psi_f) == (base.L_d, base.L_q, base.psi_f)
    assert "[motor]" in p.doc and "R_s = 1.4" in p.doc  # meta.json says where values came from
    plant = build_plant(scn)
    assert plant.motor.R_s == 1.4 and plant.motor.n_p == 2
    ctrl = build_controller(scn, "tt-dq")
    assert ctrl.pars.motor.R_s == 1.4 and ctrl.pars.motor.n_p == 2  # the controller's copy too


def test_motor_table_survives_the_effective_scenario(tmp_path: Path) -> None:
    scn = load_scenario(_write(tmp_path, "[motor]\nL_q = 0.09\n"))
    back = load_scenario(str(write_effective(scn, tmp_path / "scenario.json")))
    assert back.motor == {"L_q": 0.09} and get_preset(back).motor.L_q == 0.09
    assert json.loads((tmp_path / "scenario.json").read_text())["motor"] == {"L_q": 0.09}
    assert load_scenario("wen-5.1").motor == {}  # shipped scenarios use their presets


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        ("[motor]\nR_s = 0.0\n", "'motor.R_s': must be > 0"),
        ("[motor]\nL_d = -1e-3\n", "'motor.L_d': must be > 0"),
        ("[motor]\nn_p = 0\n", "'motor.n_p'"),
        ("[motor]\nn_p = 2.5\n", "'motor.n_p': expected an integer"),
        ("[motor]\nflux = 0.3\n", "'motor.flux': unknown key"),
        ('[motor]\nJ = "heavy"\n', "'motor.J': expected a number"),
        ("[motor]\npsi_f = -0.1\n", "'motor.psi_f': must be >= 0.0"),
    ],
)
def test_bad_motor_tables_are_one_line(tmp_path: Path, extra: str, needle: str) -> None:
    path = _write(tmp_path, extra)
    with pytest.raises(ScenarioError) as e:
        load_scenario(path)
    msg = str(e.value)
    assert path in msg and needle in msg and "\n" not in msg, msg
