"""The Python API (``bench.run``, ``bench.analyze``, ...): the files of a run, the status of
``bench run``, the errors of the command line, and an ``import bench`` that imports nothing."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import bench
from bench.runs._local import exit_status
from bench.runs._results import RunResult
from tests.ports import free_port

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "tests" / "data" / "firmware-100rpm.toml"
GROUP = "239.74.163.3"


@pytest.fixture(scope="module")
def local_run(tmp_path_factory: pytest.TempPathFactory) -> bench.Run:
    return bench.run(SCENARIO, out=tmp_path_factory.mktemp("api") / "run")


def test_a_run_holds_the_files_of_its_folder(local_run: bench.Run) -> None:
    run = local_run
    assert run.folder is not None and run.transport == "in-process" and run.exit_status == 0
    assert run.metrics == json.loads((run.folder / "metrics.json").read_text())
    header = (run.folder / "signals.csv").read_text().splitlines()[0].split(",")
    assert list(run.signals) == header
    assert all(isinstance(v, np.ndarray) for v in run.signals.values())
    assert len(run.signals["t"]) == run.metrics["steps"] == 3001
    # sensored: the estimate is the true angle
    assert np.median(np.abs(run.signals["theta_err_deg"])) < 0.01
    assert run.metrics["theta_err_abs_mean_deg"] < 0.01
    assert (run.folder / "run.png").is_file() and run.meta["transport"] == "in-process"


def test_without_a_folder_nothing_is_left_and_the_numbers_are_the_same(
    local_run: bench.Run,
) -> None:
    run = bench.run(SCENARIO)
    assert run.folder is None
    for key in ("theta_err_max_deg", "speed_err_max_rpm", "steps"):
        assert run.metrics[key] == local_run.metrics[key], key
    np.testing.assert_array_equal(run.signals["w_m_rpm"], local_run.signals["w_m_rpm"])


def test_a_folder_used_again_keeps_no_earlier_file(tmp_path: Path) -> None:
    (tmp_path / "capture.blf").write_bytes(b"an earlier run's")
    (tmp_path / "notes.txt").write_text("mine")
    run = bench.run(SCENARIO, duration=0.1, out=tmp_path)
    assert not (tmp_path / "capture.blf").exists() and (tmp_path / "notes.txt").exists()
    assert run.metrics["steps"] == 1001 and (tmp_path / "run.png").is_file()


def test_overrides_are_the_dotted_keys_of_bench_sweep(local_run: bench.Run) -> None:
    run = bench.run(SCENARIO, overrides={"speed_rpm": [[0.0, 0.0], [0.05, 50.0]]}, duration=0.25)
    assert run.metrics["steps"] == 2501
    assert abs(run.signals["w_ref_rpm"][-1] - 50.0) < 1e-6
    assert abs(local_run.signals["w_ref_rpm"][-1] - 100.0) < 1e-6


def _cli_error(*args: str) -> str:
    res = subprocess.run(
        [sys.executable, "-m", "bench", *args], cwd=ROOT, capture_output=True, text=True
    )
    assert res.returncode == 2
    return res.stderr


@pytest.mark.parametrize(
    ("kwargs", "cli", "error"),
    [
        ({}, ["run", "no-such-scenario"], bench.ScenarioError),
        ({"estimator": "no-such"}, ["run", str(SCENARIO), "-e", "no-such"], bench.BenchError),
        ({"duration": -1.0}, ["run", str(SCENARIO), "--duration", "-1"], None),
    ],
)
def test_a_mistake_is_the_bench_error_with_the_command_lines_text(
    kwargs: dict[str, Any], cli: list[str], error: type[Exception] | None
) -> None:
    scenario = "no-such-scenario" if cli[1] == "no-such-scenario" else SCENARIO
    with pytest.raises(bench.BenchError) as e:
        bench.run(scenario, **kwargs)
    if error is not None:
        assert type(e.value) is error
        assert str(e.value) in _cli_error(*cli)
    assert "\n" not in str(e.value)


def test_a_wrong_dotted_key_names_itself() -> None:
    with pytest.raises(bench.ScenarioError, match=r"controller_model\.nope"):
        bench.run(SCENARIO, overrides={"controller_model.nope": 1.0})


def test_exit_status_is_the_one_of_bench_run(tmp_path: Path) -> None:
    def res(metrics: dict[str, Any], **meta: Any) -> RunResult:
        return RunResult(tmp_path, metrics, tmp_path, {"T_s": 1e-4, **meta})

    assert exit_status(res({"lock_lost": False, "plant_fault": "none"}))[0] == 0
    assert exit_status(res({"lock_lost": True, "lock_lost_at_s": 0.7}))[0] == 4
    # a trip comes first: the angle is lost because the inverter is off
    assert exit_status(res({"lock_lost": True, "plant_fault": "overcurrent"}))[0] == 3
    assert exit_status(res({}, interrupted=True))[0] == 130
    # an analysis of an interrupted run's capture is not itself interrupted
    assert exit_status(res({}, interrupted=True), analysis=True)[0] == 0


def test_to_pandas_without_pandas_says_how(
    local_run: bench.Run, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "pandas", None)
    with pytest.raises(bench.BenchError, match=r"pandas is not installed.*\[pandas\]"):
        local_run.to_pandas()


def test_to_pandas(local_run: bench.Run) -> None:
    pytest.importorskip("pandas")
    df = local_run.to_pandas()
    assert list(df.columns) == list(local_run.signals) and len(df) == 3001


def test_over_a_bus_and_analyzed_again(tmp_path: Path) -> None:
    """transport= runs the nodes as processes (bench run's path); bench.analyze of its
    capture gives the same scores."""
    port = free_port()
    run = bench.run(SCENARIO, transport=f"udp_multicast:{GROUP}:{port}", out=tmp_path / "bus")
    assert run.exit_status == 0 and run.transport == f"udp_multicast:{GROUP} port {port}"
    assert run.folder is not None and (run.folder / "capture.blf").is_file()
    assert run.metrics["steps"] == 3001 and run.metrics["frames_rejected"] == 0
    # the controller was designed once, by bench.run, and handed to its node (as bench run)
    design = json.loads((run.folder / "plan.json").read_text()).get("design")
    assert design and design["results"]
    again = bench.analyze(run.folder / "capture.blf", out=tmp_path / "again", plots=False)
    assert again.exit_status == 0 and again.folder == tmp_path / "again"
    for key in ("theta_err_max_deg", "speed_err_max_rpm", "steps", "lock_lost"):
        assert again.metrics[key] == run.metrics[key], key


def test_names() -> None:
    assert "wen-5.1" in bench.list_scenarios() and "tt-dq" in bench.estimators()
    assert bench.load_scenario("wen-5.1").name == "wen-5.1"
    with pytest.raises(AttributeError):
        bench.no_such_name  # noqa: B018


def test_import_bench_imports_nothing_else() -> None:
    """Every node process imports ``bench``: its public names come on first use."""
    code = "import sys, bench; print(sorted(m for m in sys.modules if m.startswith('bench')))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "['bench']"


def test_transport_names_a_bus() -> None:
    from bench._api import bus_of
    from bench.wire._bus import UDP_DEFAULT_PORT, udp_multicast_group

    spec = bus_of("udp_multicast:239.1.2.3:45000")
    assert (spec.interface, spec.channel, spec.port) == ("udp_multicast", "239.1.2.3", 45000)
    full6 = "ff15:7079:7468:6f6e:6465:6d6f:6d63:6173"
    assert bus_of(f"udp_multicast:{full6}:45002").port == 45002
    # a run's own port, but python-can's where a controller under test must find the bus
    own = bus_of("udp_multicast")
    assert own.channel == udp_multicast_group() and own.port != UDP_DEFAULT_PORT
    assert bus_of("udp_multicast", known_port=True).port == UDP_DEFAULT_PORT
    with pytest.raises(bench.InterfaceError, match="virtual"):
        bus_of("virtual")
    with pytest.raises(bench.InterfaceError, match="'nosuch': unknown"):
        bench.run(SCENARIO, transport="nosuch:x")
