"""``bench run``'s start-up: the nodes start together, the parent builds no controller unless
a node failed to start, and a misfit is still one line naming the scenario and the estimator."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from bench.runs import _processes
from tests.ports import free_port

REFUSING_PLUGIN = """
def create(pars, T_s, **kw):
    raise ValueError("this estimator refuses the design")
"""


def test_every_node_is_started_before_the_first_ready_is_awaited(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    events: list[str] = []

    class Fake:
        def __init__(self, cmd: list[str], **kw: Any) -> None:
            events.append("start " + cmd[cmd.index("-m") + 2])

    def wait_ready(p: Any, role: str, log: Path, **kw: Any) -> None:
        events.append("ready " + role)

    monkeypatch.setattr(_processes.subprocess, "Popen", Fake)
    monkeypatch.setattr(_processes, "_wait_ready", wait_ready)
    roles: list[tuple[str, list[str]]] = [("link", []), ("controller", []), ("plant", [])]
    procs: list[Any] = []
    _processes.start_nodes(roles, tmp_path / "plan.json", tmp_path, {}, procs, stop=lambda: False)
    assert events == [
        "start link",
        "start controller",
        "start plant",
        "ready link",
        "ready controller",
        "ready plant",
    ]
    assert [r for r, _ in procs] == ["link", "controller", "plant"]


def test_a_controller_that_cannot_be_built_is_one_line_naming_scenario_and_estimator(
    tmp_path: Path,
) -> None:
    """The parent builds the controller before any process starts: a misfit is one line
    naming the scenario and the estimator, and nothing is recorded."""
    (tmp_path / "refusing_est.py").write_text(REFUSING_PLUGIN)
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "bench", "run", "wen-5.1", "-e", "refusing_est:create"]
    cmd += ["--duration", "0.01", "--port", str(free_port()), "--out", str(out), "-q"]
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 2, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("bench: error")]
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert lines[0].startswith(
        "bench: error: --estimator refusing_est:create: cannot run scenario wen-5.1 "
        "(this estimator refuses the design)"
    ), lines[0]
    assert not (out / "capture.blf").exists()
