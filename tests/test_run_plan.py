"""The run's plan (bench/nodes/_plan.py): made once, read by every node, nothing on argv.

A node builds its plant and controller from the plan alone (the same objects
the scenario builds, bit for bit); ``bench run`` starts each node with
``--plan`` and nothing of the run's settings; the plan's fixed settings
cannot be overridden beside it; the controller node reports its design, and
the scoring reads that report instead of building the controller again.
"""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bench.nodes._controller_node import controller_design
from bench.nodes._plan import PLAN_FILE, make_plan, read_plan
from bench.runs import _processes
from bench.scenarios import _setup
from bench.scenarios._schema import load_scenario
from bench.wire._bus import BusSpec

BUS = BusSpec("udp_multicast", "239.0.0.1", 44100)
BUS_B = BusSpec("udp_multicast", "239.0.0.1", 44101)


@pytest.mark.parametrize(
    ("name", "profile"), [("wen-5.3", "ideal"), ("xue-fig17", "drive"), ("wide-speed-wen", "drive")]
)
def test_a_plan_reads_back_equal_and_builds_what_the_scenario_builds(
    tmp_path: Path, name: str, profile: str
) -> None:
    scn = load_scenario(name).with_overrides(plant_profile=profile, duration=0.37)
    for est in (*scn.estimators, "sensored"):
        plan = make_plan(
            scn, est, mode="lockstep", plant_bus=BUS, controller_bus=BUS_B, run_id=77, pace_every=9
        )
        back = read_plan(plan.write(tmp_path / f"{est}.json"))
        assert back == plan, est
        # the one place the duration becomes steps: 0.37 s at the scenario's rate
        assert back.n_steps == round(0.37 / back.T_s)
        assert back.controller == _setup.controller_pars(scn, est)
        assert back.needs_truth == (est == "sensored")
    plant_a, plant_b = back.plant.build("python"), _setup.build_plant(scn, "python")
    for _ in range(3):
        plant_a.step(0.6, 0.4, 0.5)
        plant_b.step(0.6, 0.4, 0.5)
        assert plant_a.sample() == plant_b.sample() and plant_a.truth() == plant_b.truth()


def test_the_nodes_get_the_plan_and_no_run_setting_on_their_command_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    scn = load_scenario("wen-5.1").with_overrides(duration=0.2)
    scn = scn.with_overrides(latency=replace(scn.latency, duty_delay_steps=2))
    plan = make_plan(scn, "tt-dq", mode="lockstep", plant_bus=BUS, controller_bus=BUS_B, run_id=9)
    plan_file = plan.write(tmp_path / PLAN_FILE)
    cmds: list[list[str]] = []

    class Fake:
        def __init__(self, cmd: list[str], **kw: Any) -> None:
            cmds.append(cmd)

    monkeypatch.setattr(_processes.subprocess, "Popen", Fake)
    monkeypatch.setattr(_processes, "_wait_ready", lambda *a, **k: None)
    roles = _processes.node_roles(plan, {"plant": ["--engine", "python"]})
    assert [r for r, _ in roles] == ["link", "controller", "plant"]
    _processes.start_nodes(roles, plan_file, tmp_path, {}, [], stop=lambda: False)
    tails = [c[c.index("-m") + 2 :] for c in cmds]
    assert tails == [
        ["link", "--plan", str(plan_file)],
        ["controller", "--plan", str(plan_file), "--report", str(tmp_path / "controller.json")],
        [
            "plant",
            "--plan",
            str(plan_file),
            "--engine",
            "python",
            "--report",
            str(tmp_path / "plant.json"),
        ],
    ]


def _bench(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "bench", *args], capture_output=True, text=True, timeout=120
    )


def test_a_plan_cannot_be_overridden_beside_it(tmp_path: Path) -> None:
    scn = load_scenario("wen-5.1")
    f = make_plan(scn, "tt-dq", mode="lockstep", plant_bus=BUS, run_id=3).write(tmp_path / "p.json")
    for role, extra in (("plant", ["--duration", "3"]), ("controller", ["--run-id", "5"])):
        r = _bench(role, "--plan", str(f), *extra)
        assert r.returncode == 2, r.stderr
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and extra[0] in lines[0] and "plan" in lines[0], r.stderr
    f.write_text(json.dumps({"version": 999}))
    r = _bench("plant", "--plan", str(f))
    assert r.returncode == 2 and "version" in r.stderr and "Traceback" not in r.stderr


def test_the_scoring_reads_the_controllers_report_and_builds_no_controller(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from bench.runs import _results

    scn = load_scenario("wide-speed-wen").with_overrides(duration=2.0)
    est = "hybrid-tt-dq"
    # as the controller node writes it into controller.json (JSON, read back)
    design = json.loads(json.dumps(controller_design(_setup.build_controller(scn, est))))
    assert design["band_edges"] and design["injection"]["w_h"] > 0
    n, T_s = 20000, 1e-4
    w_rpm = np.linspace(0.0, 900.0, n)
    theta = np.cumsum(w_rpm * 4 * np.pi / 30.0) * T_s
    err = np.radians(3.0) * np.sin(np.arange(n) * 0.01)
    zeros = np.zeros(n)
    table = {
        "t": np.arange(n) * T_s,
        "step": np.arange(n),
        "theta_e": theta % (2 * np.pi),
        "theta_hat": (theta - err) % (2 * np.pi),
        "w_m_rpm": w_rpm,
        "w_hat_rpm": w_rpm,
        "w_ref_rpm": w_rpm,
        "tau_L": zeros,
        "tau_e": zeros,
        "i_a": zeros,
        "i_d": zeros,
        "i_q": zeros,
        "mode": np.full(n, 3.0),
    }
    bands = _results.hybrid_band_metrics(table, scn, est)
    assert bands, "a hybrid run has band metrics"
    built = _results.fundamental_corner_hz(scn, est, table)
    meta_built = _results.run_metadata(scn, est, mode="lockstep", transport="x", link=False)

    calls: list[str] = []

    def no_build(scn: Any, est: str, *a: Any, **k: Any) -> Any:
        calls.append(est)
        raise ValueError("the controller was built again")

    monkeypatch.setattr(_setup, "build_controller", no_build)
    assert _results.fundamental_corner_hz(scn, est, table, design) == built
    meta = _results.run_metadata(
        scn, est, mode="lockstep", transport="x", link=False, design=design
    )
    assert meta["controller_gains"] == meta_built["controller_gains"]
    again = _results.hybrid_band_metrics(table, scn, est, design)
    assert json.dumps(again, sort_keys=True) == json.dumps(bands, sort_keys=True)
    assert calls == []
    # without the report it is built (the patch takes effect): a capture's analysis
    assert _results.fundamental_corner_hz(scn, est, table) is None
    assert calls == [est]


def test_a_run_writes_its_plan_and_records_the_nodes_design(tmp_path: Path) -> None:
    """``bench run`` over udp_multicast: ``plan.json`` in the folder, the gains in
    ``meta.json`` are the ones the controller node reported."""
    from bench.runs._run import run_scenario
    from tests.ports import free_port

    scn = load_scenario("wen-5.1").with_overrides(duration=0.15, score_from_s=0.05)
    spec = BusSpec("udp_multicast", "239.74.163.2", free_port())
    res = run_scenario(scn, "tt-dq", spec=spec, out_dir=tmp_path / "run", progress=False)
    plan = read_plan(tmp_path / "run" / PLAN_FILE)
    assert plan.run_id == res.meta["run_id"] and plan.n_steps == round(0.15 / plan.T_s)
    # the plant ran the plan's periods, and every one has its row
    assert res.meta["node_reports"]["plant"]["steps"] == plan.n_steps
    assert res.metrics["steps_missing"] == 0
    report = json.loads((tmp_path / "run" / "controller.json").read_text())
    assert res.meta["controller_gains"] == report["design"]["gains"]
    assert report["design"]["gains"]["alpha_c"] > 0
