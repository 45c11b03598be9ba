"""What a run records and prints about itself: ``meta.json``'s motor, PWM rate and DC link
as built, and the printed table's rows (what each error row measures; no empty paper column)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench.runs._metrics import METRIC_LABELS
from bench.runs._plots import metrics_text
from bench.runs._results import format_metrics, run_metadata
from bench.scenarios._schema import load_scenario
from plant_rt import PRESETS


def _own(tmp_path: Path) -> Path:
    f = tmp_path / "mine.toml"
    f.write_text(
        'extends = "wen-5.1"\nf_sw = 5000.0\n[motor]\nR_s = 1.4\n[inverter]\nu_dc = 300.0\n'
    )
    return f


def test_meta_records_the_motor_rate_and_dc_link_as_built(tmp_path: Path) -> None:
    scn = load_scenario(str(_own(tmp_path)))
    meta = run_metadata(scn, "tt-dq", mode="lockstep", transport="x", link=False)
    shipped = PRESETS["wen2023"]
    assert meta["motor"]["R_s"] == 1.4 and meta["motor"]["L_q"] == shipped.motor.L_q
    assert meta["f_sw"] == 5000.0 and meta["T_s"] == pytest.approx(2e-4)
    assert meta["u_dc"] == 300.0 and meta["plant"]["inverter"]["u_dc"] == 300.0
    pre = meta["preset"]
    # the keys stay; the values are the run's, the preset's own ones under "replaced"
    assert {"name", "motor", "inverter", "f_sw", "doc"} <= set(pre)
    assert pre["f_sw"] == 5000.0 and pre["inverter"]["u_dc"] == 300.0
    assert pre["motor"] == meta["motor"]
    assert pre["replaced"] == {
        "f_sw": shipped.f_sw,
        "motor.R_s": shipped.motor.R_s,
        "inverter.u_dc": shipped.inverter.u_dc,
    }
    # a shipped scenario on its preset's plant replaces nothing
    plain = run_metadata(load_scenario("wen-5.1"), "tt-dq", mode="lockstep", transport="x",
                         link=False)  # fmt: skip
    assert plain["preset"]["replaced"] == {} and plain["motor"]["R_s"] == shipped.motor.R_s
    assert json.loads(json.dumps(meta))["motor"] is not None


def test_the_table_says_which_rows_keep_their_sign() -> None:
    m = {
        "theta_err_max_deg": 1.5,
        "theta_err_min_deg": -2.5,
        "theta_err_abs_max_deg": 2.5,
        "theta_err_abs_max_rad": 0.0436,
        "steps": 10,
    }
    rows = {ln.split()[0]: ln for ln in format_metrics(m).splitlines()[1:]}
    assert rows["theta_err_max_deg"].endswith("largest dtheta (signed)")
    assert rows["theta_err_min_deg"].endswith("smallest dtheta (signed)")
    # the |dtheta| max the plot's box shows is a row of its own, with the plot's label
    assert rows["theta_err_abs_max_deg"].split()[1] == "2.500"
    assert rows["theta_err_abs_max_deg"].endswith(METRIC_LABELS["theta_err_abs_max_deg"])
    assert f"{METRIC_LABELS['theta_err_abs_max_deg']} 2.50 deg" in metrics_text(m)
    assert rows["steps"].split() == ["steps", "10"]


def test_the_paper_column_only_where_the_paper_has_numbers() -> None:
    m = {"theta_err_max_deg": 1.0, "theta_err_mean_deg": 0.5}
    own = format_metrics(m, {}, None, "tt-dq").splitlines()
    assert own[0].split() == ["metric", "bench"]
    assert own[1].split()[:3] == ["theta_err_max_deg", "1.000", "deg"]
    paper = format_metrics(m, {"theta_err_max_deg": 4.0}, "tt-dq", "tt-dq").splitlines()
    assert paper[0].split() == ["metric", "bench", "paper", "(tt-dq)"]
    assert paper[1].split()[:4] == ["theta_err_max_deg", "1.000", "4.0", "deg"]
    assert paper[2].split()[:3] == ["theta_err_mean_deg", "0.500", "deg"]  # no number: blank
    # a controller under test's results are headed with its name (--dut-name)
    dut = format_metrics(m, {"theta_err_max_deg": 4.0}, "tt-dq", "tt-dq", "my-drive")
    assert dut.splitlines()[0].split() == ["metric", "my-drive", "paper", "(tt-dq)"]


def test_analyze_of_a_capture_made_elsewhere_records_the_plant_it_analysed_with(
    tmp_path: Path,
) -> None:
    import can

    from bench.captures._read import analyze_capture
    from bench.nodes._loops import run_inprocess
    from bench.wire._codec import Codec

    f = _own(tmp_path)
    scn = load_scenario(str(f)).with_overrides(duration=0.05)
    cap = tmp_path / "elsewhere" / "drive.blf"
    cap.parent.mkdir()
    with can.Logger(str(cap)) as w:
        for m in run_inprocess(scn, "sensored", Codec()):
            w.on_message_received(m)
    analyze_capture(cap, scenario=str(f), echo=lambda _: None, plots=False, duration=0.05)
    meta = json.loads((cap.parent / "meta.json").read_text())
    assert meta["motor"]["R_s"] == 1.4 and meta["u_dc"] == 300.0 and meta["f_sw"] == 5000.0
    assert meta["preset"]["replaced"]["motor.R_s"] == PRESETS["wen2023"].motor.R_s


def test_the_papers_mean_stands_beside_the_metric_it_is_compared_with() -> None:
    """Wen's "dtheta avg" (``paper_result.theta_err_mean_deg``) is a mean |dtheta| (the
    README's claims compare it so): the table shows it on that row, not the signed mean's."""
    m = {"theta_err_mean_deg": -0.1, "theta_err_abs_mean_deg": 0.4}
    rows = format_metrics(m, {"theta_err_mean_deg": 2.0}, "tt-dq", "tt-dq").splitlines()[1:]
    by = {ln.split()[0]: ln.split() for ln in rows}
    assert by["theta_err_abs_mean_deg"][:3] == ["theta_err_abs_mean_deg", "0.400", "2.0"]
    assert by["theta_err_mean_deg"][:3] == ["theta_err_mean_deg", "-0.100", "deg"]


def test_the_timed_rows_say_which_span_each_measures() -> None:
    """``wall_s`` is the whole run's, ``realtime_factor`` the plant loop's alone: the table
    says so, so 0.70 x beside 18.6 s of a 10 s run is no contradiction."""
    rows = {
        ln.split()[0]: ln
        for ln in format_metrics({"wall_s": 18.6, "realtime_factor": 0.7}).splitlines()[1:]
    }
    assert "start-up" in rows["wall_s"] and "included" in rows["wall_s"]
    assert "plant's loop alone" in rows["realtime_factor"]
