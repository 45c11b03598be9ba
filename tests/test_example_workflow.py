"""The worked example's CI workflow installs the bench before the project that needs it:
the bench is not on PyPI, so ``pip install -e '.[test]'`` alone fails on a hosted runner
(pip looks for ``can-hil-bench`` there).  docs/TESTING.md says how it is installed."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WORKFLOW = ROOT / "docs" / "examples" / "ci-project" / ".github" / "workflows" / "hil.yml"


def _runs() -> list[str]:
    """The ``run:`` commands of the workflow's steps, in their order (one line each)."""
    return [m.strip() for m in re.findall(r"^\s+run: (.+)$", WORKFLOW.read_text(), re.M)]


def test_the_bench_is_installed_from_git_before_the_project() -> None:
    runs = _runs()
    project = [i for i, r in enumerate(runs) if "pip install -e '.[test]'" in r]
    bench = [i for i, r in enumerate(runs) if re.search(r"pip install .*can-hil-bench @ git\+", r)]
    assert project and bench, runs
    assert bench[0] < project[0], runs
    # the URL it installs from is the step's own setting, shown where a user edits it
    text = WORKFLOW.read_text()
    assert re.search(r"BENCH_GIT: https://\S+\.git", text), text
