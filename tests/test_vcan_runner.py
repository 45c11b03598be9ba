"""tools/vcan-tests refuses to pass silently: in CI, SocketCAN tests that did not run fail."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _run(**env: str) -> subprocess.CompletedProcess[str]:
    e = {k: v for k, v in os.environ.items() if k != "CI"}
    e.update(env)
    return subprocess.run(
        ["bash", str(ROOT / "tools" / "vcan-tests")],
        cwd=ROOT,
        env=e,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_in_ci_tests_that_could_not_run_are_an_error() -> None:
    p = _run(CI="true", VCAN_TESTS_VIA="none")
    assert p.returncode == 1, p.stdout + p.stderr
    out = p.stdout + p.stderr
    assert "did not run" in out and "CI=true" in out


def test_outside_ci_it_warns_and_passes() -> None:
    p = _run(VCAN_TESTS_VIA="none")
    assert p.returncode == 0, p.stdout + p.stderr
    assert "VCAN_TESTS_VIA=none" in p.stdout + p.stderr


def test_a_bad_setting_is_one_line() -> None:
    p = _run(VCAN_TESTS_VIA="sometimes")
    assert p.returncode == 2
    assert p.stderr.strip().splitlines() == [
        "vcan-tests: error: VCAN_TESTS_VIA=sometimes: expected auto, native, uml or none"
    ]
