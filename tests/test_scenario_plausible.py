"""Scenario mistakes that used to run silently: implausible motors, orphan injection settings.

- Every motor is checked against physics on load (:mod:`bench.scenarios._plausible`):
  a value typed in another unit (mH for H, rpm for rad/s, ...) is one line
  naming the field and the unit it looks like; the papers' motors and every
  shipped and example scenario pass.
- ``[estimator_options]`` in a file of its own without ``[motor]`` is an error.
- ``sensored`` runs from any scenario, leaving the injection settings out with
  one line; so does every estimator with the options of the others (one file
  serves both injection families); a key no estimator declares is an error.
- The schema states each ``[motor]`` key's unit.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from bench._errors import ScenarioError
from bench.cli import main
from bench.scenarios import _schema
from bench.scenarios._plausible import _Motor, current_for_torque, motor_plausibility_error
from bench.scenarios._schema import MOTOR_KEYS, SHIPPED, load_scenario
from bench.scenarios._setup import build_controller, check_estimator_fits
from plant_rt import PRESETS

ROOT = Path(__file__).resolve().parents[1]
KEYS = ("n_p", "R_s", "L_d", "L_q", "psi_f", "i_rated", "i_max", "tau_rated", "w_m_rated", "J")


def preset_values(name: str) -> dict[str, float]:
    p = PRESETS[name]
    out = {k: float(getattr(p.motor, k)) for k in KEYS}
    out["u_dc"] = p.inverter.u_dc
    return out


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_the_papers_motors_are_plausible(name: str) -> None:
    assert motor_plausibility_error(preset_values(name), {}) is None


def test_every_shipped_and_example_scenario_loads() -> None:
    files = [*SHIPPED, *map(str, sorted((ROOT / "docs" / "examples").glob("*.toml")))]
    assert len(files) > len(SHIPPED)
    for f in files:
        load_scenario(f)


def test_current_for_rated_torque_against_closed_forms() -> None:
    base = preset_values("wen2023")
    # surface magnets (L_d = L_q): tau = 1.5 n_p psi_f i_q, so i = tau / (1.5 n_p psi_f)
    spm = _Motor(**{**base, "L_d": 0.07, "L_q": 0.07})
    assert current_for_torque(spm, 7.5) == pytest.approx(7.5 / (1.5 * 4 * 0.3), rel=1e-6)
    # pure reluctance (psi_f = 0): the best angle is 45 deg, tau = 1.5 n_p (L_q - L_d) i^2 / 2
    rel = _Motor(**{**base, "psi_f": 0.0})
    i = math.sqrt(2.0 * 7.5 / (1.5 * 4 * (0.082 - 0.057)))
    assert current_for_torque(rel, 7.5) == pytest.approx(i, rel=1e-6)
    # the IPMSM's reluctance torque lowers the current below the magnet-only one
    ipm = _Motor(**base)
    assert current_for_torque(ipm, 7.5) < 7.5 / (1.5 * 4 * 0.3)


@pytest.mark.parametrize(
    ("table", "field", "looks"),
    [
        (
            "[motor]\nL_d = 36.0\nL_q = 51.0",
            "motor.L_d",
            "L_d = 36 looks like mH; the schema wants H",
        ),
        ("[motor]\nL_q = 82.0", "motor.L_q", "looks like mH; the schema wants H (0.082)"),
        ("[motor]\nR_s = 2800.0", "motor.R_s", "looks like mOhm; the schema wants Ohm (2.8)"),
        ("[motor]\npsi_f = 300.0", "motor.psi_f", "looks like mWb; the schema wants Wb (0.3)"),
        (
            "[motor]\nw_m_rated = 1500.0",
            "motor.w_m_rated",
            "looks like rpm; the schema wants rad/s",
        ),
        ("[motor]\ni_rated = 4000.0\ni_max = 8000.0", "motor.i_rated", "looks like mA"),
        ("[motor]\npsi_f = 0.0003", "motor.psi_f", "divided by 1000 once too often"),
        ("[inverter]\nu_dc = 540000.0", "inverter.u_dc", "looks like mV; the schema wants V"),
        (
            "[motor]\nJ = 40.0",
            "motor.J",
            "J = 40 looks like kg cm^2; the schema wants kg m^2 (0.004)",
        ),
        ("[motor]\nJ = 30000.0", "motor.J", "looks like g cm^2; the schema wants kg m^2 (0.003)"),
    ],
)
def test_a_value_off_by_1000_names_its_field_and_unit(
    tmp_path: Path, table: str, field: str, looks: str
) -> None:
    f = tmp_path / "mine.toml"
    f.write_text(f'extends = "wen-5.1"\n{table}\n')
    with pytest.raises(ScenarioError) as e:
        load_scenario(str(f))
    msg = str(e.value)
    assert msg.startswith(f"{f}: field '{field}': "), msg
    assert looks in msg and "\n" not in msg, msg


def test_the_new_users_mh_motor_is_one_line_from_bench_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    f = tmp_path / "mine.toml"
    f.write_text('extends = "wen-5.1"\n[motor]\nL_d = 36\nL_q = 51\n')
    assert main(["run", str(f), "--duration", "0.01", "-i", "udp_multicast"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'motor.L_d'" in err[0] and "looks like mH" in err[0], err


def test_the_mechanical_time_constant_bounds_and_message() -> None:
    """J w_m_rated / tau_rated: the papers' 0.063 s and 0.053 s load; a J no unit explains is
    named with the time constant and the keys to check."""
    from bench.scenarios._plausible import TAU_M_MAX_S, TAU_M_MIN_S

    for name, tau_m in (("wen2023", 0.0628), ("xue2022", 0.0526)):
        v = preset_values(name)
        assert v["J"] * v["w_m_rated"] / v["tau_rated"] == pytest.approx(tau_m, rel=1e-3)
    base = preset_values("wen2023")
    w, tau = base["w_m_rated"], base["tau_rated"]
    for t_m in (0.6 * TAU_M_MIN_S, 1.5 * TAU_M_MAX_S):
        err = motor_plausibility_error({**base, "J": t_m * tau / w}, {})
        assert err is not None and err[0] == "motor.J", err
        assert "mechanical time constant" in err[1] and "check J (kg m^2)" in err[1], err
    for t_m in (1.5 * TAU_M_MIN_S, 0.9 * TAU_M_MAX_S):
        assert motor_plausibility_error({**base, "J": t_m * tau / w}, {"J": "motor.J"}) is None


def test_an_inertia_in_kg_cm2_is_one_line_from_bench_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    f = tmp_path / "mine.toml"
    f.write_text('extends = "wen-5.1"\n[motor]\nJ = 40\n')
    assert main(["run", str(f), "--duration", "0.01", "-i", "udp_multicast"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'motor.J'" in err[0] and "looks like kg cm^2" in err[0], err


def test_plausible_changes_load(tmp_path: Path) -> None:
    """An rms rating typed as peak (a factor sqrt 2) and a motor of its own are not mistakes."""
    f = tmp_path / "mine.toml"
    f.write_text(
        'extends = "wen-5.1"\n[motor]\ni_rated = 2.83\nL_d = 0.03\nL_q = 0.05\nR_s = 1.2\n'
        "psi_f = 0.25\nw_m_rated = 200.0\n"
    )
    scn = load_scenario(str(f))
    assert scn.motor["L_d"] == 0.03


def test_injection_settings_need_a_motor_table(tmp_path: Path) -> None:
    own = (ROOT / "bench" / "scenarios" / "wen-5.1.toml").read_text()
    f = tmp_path / "mine.toml"
    f.write_text(own + "\n[estimator_options]\nV_h = 40.0\n")
    with pytest.raises(ScenarioError, match=r"field 'estimator_options': injection settings"):
        load_scenario(str(f))
    # an empty [motor] says the preset's motor is meant; extending a scenario keeps its motor
    f.write_text(own + "\n[motor]\n[estimator_options]\nV_h = 40.0\n")
    assert load_scenario(str(f)).estimator_options == {"V_h": 40.0}
    f.write_text('extends = "wen-5.1"\n[estimator_options]\nV_h = 40.0\n')
    assert load_scenario(str(f)).estimator_options == {"V_h": 40.0}


def test_sensored_runs_from_any_scenario_saying_what_it_leaves_out(tmp_path: Path) -> None:
    f = tmp_path / "mine.toml"
    f.write_text('extends = "wen-5.1"\n[estimator_options]\nV_h = 40.0\nf_h = 400.0\n')
    scn = load_scenario(str(f))
    note = check_estimator_fits(scn, "sensored")
    assert note is not None and "V_h, f_h" in note and "sensored" in note
    build_controller(scn, "sensored")
    assert check_estimator_fits(scn, "tt-dq") is None


def test_one_file_serves_both_injection_families(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Issue 27: with V_h and U_h, tt-dq and square-wave both run; each leaves out the other's
    option with a note naming it and its owners; each gets its own."""
    f = tmp_path / "mine.toml"
    f.write_text('extends = "wen-5.1"\n[estimator_options]\nV_h = 40.0\nU_h = 25.0\n')
    scn = load_scenario(str(f))
    sq = build_controller(scn, "square-wave")
    assert sq.gains()["estimator.U_h"] == 25.0
    note = check_estimator_fits(scn, "square-wave")
    assert note is not None and "\n" not in note
    assert (
        "square-wave leaves out" in note
        and "V_h: sfhf, tt-ab, tt-dq, self-demod, epf, hybrid-tt-dq" in note
    )
    rot = build_controller(scn, "tt-dq")
    assert rot.gains()["estimator.V_h"] == 40.0
    note = check_estimator_fits(scn, "tt-dq")
    assert note is not None and "U_h: square-wave, square-wave-nocic, hybrid-square-wave" in note
    assert check_estimator_fits(load_scenario("xue-fig13"), "square-wave") is None
    # bench run prints the note, one line
    rc = main(["run", str(f), "-e", "tt-dq", "--duration", "0.002", "--out", str(tmp_path / "r")])
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("note:")]
    assert rc == 0 and len(err) == 1 and "U_h" in err[0], err
    import json

    meta = json.loads((tmp_path / "r" / "meta.json").read_text())
    assert meta["estimator_options_left_out"] == ["U_h"]


def test_an_option_no_estimator_declares_is_one_line_naming_file_and_key(tmp_path: Path) -> None:
    f = tmp_path / "mine.toml"
    f.write_text('extends = "xue-fig13"\n[estimator_options]\nU_h = 25.0\nV_hh = 40.0\n')
    with pytest.raises(ScenarioError) as e:
        load_scenario(str(f))
    msg = str(e.value)
    assert msg.startswith(f"{f}: field 'estimator_options.V_hh': unknown key"), msg
    assert "\n" not in msg and "V_h" in msg


def test_the_schema_states_each_motor_keys_unit() -> None:
    doc = _schema.__doc__ or ""
    assert "**peak** phase values" in doc and "mechanical rad/s" in doc
    block = doc[doc.index("    [motor]") : doc.index("    [controller_model]")]
    for key in MOTOR_KEYS:
        line = next((ln for ln in block.splitlines() if re.match(rf"\s+{key} = ", ln)), None)
        assert line is not None and "#" in line, key
    for key, unit in (("L_d", "H"), ("R_s", "Ohm"), ("psi_f", "Wb"), ("i_rated", "peak")):
        assert unit in next(ln for ln in block.splitlines() if f" {key} = " in ln), key
