"""Shared by the tests that run a user's tests as the user would: pytest in a folder of
its own, with the bench as installed and the ``hil`` fixture over udp_multicast."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path


def run_pytest(
    cwd: Path, tmp_path: Path, *args: str, timeout: float, path_without_bin: bool = False
) -> tuple[subprocess.CompletedProcess[str], Path]:
    """pytest in ``cwd`` (``args`` added), and its JUnit XML report.

    The bench is the installed one: neither this checkout's ``PYTHONPATH`` nor the
    outer pytest's ``PYTEST_*`` variables reach it.  The runs' folders go under
    ``tmp_path/runs``, the report to ``tmp_path/report.xml``.  ``path_without_bin``:
    this environment's ``bin`` taken off the ``PATH``, as for a user who did not
    activate it (a controller must then call the bench as ``sys.executable -m bench``).
    """
    report = tmp_path / "report.xml"
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")}
    env.pop("PYTHONPATH", None)
    if path_without_bin:
        bin_dir = str(Path(sys.executable).parent)
        env["PATH"] = os.pathsep.join(
            d for d in env.get("PATH", "").split(os.pathsep) if d and d != bin_dir
        )
    cmd = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q",
           "--hil-interface", "udp_multicast", f"--junitxml={report}",
           f"--basetemp={tmp_path}/runs", *args]  # fmt: skip
    p = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    return p, report
