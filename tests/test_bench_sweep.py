"""``bench sweep``: dotted scenario keys, grid and random plans, results, resuming, executors.

Points are short ``xue-fig13`` runs (1 kHz, 0.6 s): cheap, and deterministic,
so two executors must give the same numbers.
"""

from __future__ import annotations

import csv
import json
import os
import sys
from pathlib import Path
from typing import Any

import pytest

from bench._errors import BenchError, ScenarioError
from bench.cli import main
from bench.scenarios._dotted import parse_value, scenario_table, scenario_with, split_values
from bench.studies._executors import LOST, execute
from bench.studies._grid import Plan, parse_grid, parse_random, run_sweep

SCN = "xue-fig13"
DUR = 0.6


def test_dotted_keys_change_one_value_and_are_validated() -> None:
    base = scenario_table("wen-5.1")
    scn = scenario_with(base, {"controller_model.L_q": 1.2, "inverter.t_dead": 2e-6, "seed": 7})
    assert scn.controller_model.L_q == 1.2 and scn.controller_model.L_d == 1.0
    assert scn.inverter["t_dead"] == 2e-6 and scn.seed == 7
    assert scn.estimators == (
        "sfhf",
        "tt-ab",
        "tt-dq",
        "self-demod",
        "epf",
        "sensored",
    )  # the rest is wen-5.1's
    with pytest.raises(ScenarioError, match="controller_model"):
        scenario_with(base, {"controller_model.L_x": 1.2})
    with pytest.raises(ScenarioError, match="inverter"):
        scenario_with(base, {"inverter.t_dead": -1.0})


def test_values_read_as_toml_and_lists_survive_the_commas() -> None:
    assert parse_value("1e-6") == 1e-6 and parse_value("12") == 12 and parse_value("true") is True
    assert parse_value("abc") == "abc"
    assert split_values("[[0, 1], [2, 3]],[[0, 5]], 7") == ["[[0, 1], [2, 3]]", "[[0, 5]]", "7"]
    assert parse_grid(["a.b=1,2.5,true"]) == {"a.b": [1, 2.5, True]}
    with pytest.raises(BenchError):
        parse_grid(["a.b"])


def test_plan_grid_is_every_combination_and_random_draws_are_seeded() -> None:
    p = Plan(SCN, ("square-wave",), grid={"a": [1, 2], "b": [3, 4, 5]})
    assert len(p.points()) == 6 and {"a": 2, "b": 5} in p.points()
    r = {"x": parse_random("0:1"), "n": parse_random("int:8:12"), "c": parse_random("choice:a,b")}
    q = Plan(SCN, ("square-wave",), grid={"a": [1, 2]}, random=r, samples=5, seed=3)
    pts = q.points()
    assert len(pts) == 10 and pts == q.points()  # the same seed, the same draws
    assert all(0.0 <= pt["x"] <= 1.0 and 8 <= pt["n"] <= 12 and pt["c"] in "ab" for pt in pts)
    # each draw is combined with every grid point
    assert [pt["x"] for pt in pts[:5]] == [pt["x"] for pt in pts[5:]]
    other = Plan(SCN, ("square-wave",), grid={"a": [1, 2]}, random=r, samples=5, seed=4).points()
    assert [pt["x"] for pt in other] != [pt["x"] for pt in pts]
    log = parse_random("log:1e-3:1e-1")
    assert log.kind == "log" and log.lo == 1e-3
    with pytest.raises(BenchError):
        parse_random("1:0")


def _need_distributed() -> None:
    """Dask is the project's ``dask`` extra, which ``make`` installs: in CI its absence fails."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        if os.environ.get("CI"):
            raise
        pytest.skip("Dask distributed is not installed (pip install -e '.[dask]')")


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open() as f:
        return list(csv.DictReader(f))


def test_sweep_writes_results_and_resumes(tmp_path: Path) -> None:
    plan = Plan(
        SCN,
        ("square-wave", "square-wave-nocic"),
        grid={"sensors.current_noise_a": [0.0, 0.1]},
        duration=DUR,
    )
    res = run_sweep(plan, tmp_path, workers=1, progress=False)
    rows = _rows(tmp_path / "results.csv")
    assert len(rows) == 4
    assert {r["estimator"] for r in rows} == {"square-wave", "square-wave-nocic"}
    assert {r["sensors.current_noise_a"] for r in rows} == {"0.0", "0.1"}
    for key in ("theta_err_abs_max_deg", "lock_lost", "speed_err_max_rpm", "wall_s"):
        assert key in rows[0]
    assert (tmp_path / "plots" / "line-sensors_current_noise_a.png").is_file()
    tp = res.summary["throughput"]
    assert tp["points"] == 4 and tp["points_per_s"] > 0
    # noise makes a difference a wrong override (one ignored) would not
    by = {(r["estimator"], r["sensors.current_noise_a"]): r for r in rows}
    assert (
        by[("square-wave", "0.1")]["theta_err_rms_deg"]
        != by[("square-wave", "0.0")]["theta_err_rms_deg"]
    )
    # resuming: nothing runs again; a lost line runs again, alone
    log = tmp_path / "points.jsonl"
    lines = log.read_text().splitlines()
    res2 = run_sweep(plan, tmp_path, workers=1, progress=False)
    assert "throughput" not in res2.summary and res2.summary["finished"] == 4
    log.write_text("\n".join(lines[:3]) + "\n" + lines[3][:20])  # a torn last line
    res3 = run_sweep(plan, tmp_path, workers=1, progress=False)
    assert res3.summary["throughput"]["points"] == 1 and res3.summary["missing"] == 0
    assert len(_rows(tmp_path / "results.csv")) == 4


def test_two_keys_give_a_heatmap_per_estimator(tmp_path: Path) -> None:
    plan = Plan(
        SCN,
        ("square-wave",),
        grid={"controller_model.L_d": [0.9, 1.1], "controller_model.L_q": [0.9, 1.1]},
        duration=DUR,
    )
    res = run_sweep(plan, tmp_path, workers=2, progress=False)
    assert "plots/heatmap-square-wave-controller_model_L_d-controller_model_L_q.png" in res.files


def test_dask_local_cluster_gives_the_local_numbers(tmp_path: Path) -> None:
    """``--executor dask`` on a local cluster of 2 workers: the in-process runs are
    deterministic, so every metric equals the local executor's."""
    _need_distributed()
    args = ["sweep", SCN, "-e", "square-wave", "--grid", "sensors.current_noise_a=0,0.05,0.1"]
    args += ["--duration", str(DUR), "-q"]
    assert main([*args, "--out", str(tmp_path / "local"), "--workers", "1"]) == 0
    assert (
        main([*args, "--out", str(tmp_path / "dask"), "--executor", "dask", "--workers", "2"]) == 0
    )
    a = {r["sensors.current_noise_a"]: r for r in _rows(tmp_path / "local" / "results.csv")}
    b = {r["sensors.current_noise_a"]: r for r in _rows(tmp_path / "dask" / "results.csv")}
    assert a.keys() == b.keys() and len(a) == 3
    for k in a:
        assert a[k]["theta_err_abs_max_deg"] == b[k]["theta_err_abs_max_deg"]
    sw = json.loads((tmp_path / "dask" / "sweep.json").read_text())
    assert sw["throughput"]["executor"] == "dask" and sw["throughput"]["workers"] == 2


# ------------------------------------------------------------- workers that die


def die_once(task: tuple[str, int]) -> dict[str, Any]:
    """Kill the worker process the first time a marked task runs; its result otherwise."""
    marker, n = task
    if n == 1 and not os.path.exists(marker):
        Path(marker).write_text("died")
        os._exit(3)
    return {"n": n, "pid": os.getpid()}


def test_local_worker_death_loses_no_finished_point(tmp_path: Path) -> None:
    marker = str(tmp_path / "died")
    tasks = [(marker, n) for n in range(6)]
    got: dict[int, dict[str, Any]] = {}
    info = execute(tasks, die_once, lambda i, r: got.__setitem__(i, r), workers=2)
    assert Path(marker).exists()  # a worker did die
    assert sorted(got) == list(range(6)) and all(got[i]["n"] == i for i in got)
    assert info.restarts == 1 and info.lost == 0


def test_dask_worker_death_reruns_its_point(tmp_path: Path) -> None:
    _need_distributed()
    import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    try:
        marker = str(tmp_path / "died")
        tasks = [(marker, n) for n in range(6)]
        got: dict[int, dict[str, Any]] = {}
        info = execute(tasks, die_once, lambda i, r: got.__setitem__(i, r), executor="dask")
    finally:
        cloudpickle.unregister_pickle_by_value(sys.modules[__name__])
    assert Path(marker).exists()
    assert sorted(got) == list(range(6))
    assert all(got[i].get("n") == i and got[i].get("error") != LOST for i in got)
    assert info.lost == 0


def test_cli_mistakes_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for argv, says in (
        (["sweep", SCN, "--out", str(tmp_path)], "--grid"),
        (["sweep", SCN, "--grid", "nosuch=1", "--out", str(tmp_path)], "nosuch"),
        (
            ["sweep", SCN, "--grid", "seed=1", "--scheduler", "tcp://x:1", "--out", str(tmp_path)],
            "--scheduler",
        ),
        (["sweep", SCN, "--random", "seed=int:1:3", "--out", str(tmp_path)], "--samples"),
    ):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and says in err, err


def test_scale_figures_go_between_the_markers() -> None:
    from bench.studies._scale import BEGIN, END, scale_table, update_doc

    cfg = {"executor": "local", "workers": 2, "points_per_s": 1.5, "speedup": 1.8}
    table = scale_table({"configs": {"local-2": cfg}})
    assert "| local | 2 | 1.500 | 1.80x |" in table and "nan" in table
    doc = f"intro\n{BEGIN}\nold\n{END}\nrest\n"
    new = update_doc(doc, table)
    assert "old" not in new and table in new and new.endswith(f"{END}\nrest\n")
    assert update_doc(new, "x") == f"intro\n{BEGIN}\nx\n{END}\nrest\n"


def test_machine_calibration_reports_both_walls() -> None:
    from bench.studies._scale import machine_speedup

    ms = machine_speedup(n=10_000)
    assert ms["wall_1_s"] > 0 and ms["wall_2_s"] > 0
    assert ms["speedup"] == pytest.approx(2 * ms["wall_1_s"] / ms["wall_2_s"])
