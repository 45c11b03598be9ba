"""The worked example docs/examples/ci-project runs as its README says: its three tests,
with pytest in a copy of the folder, over udp_multicast (the fallback of its CI workflow
when the runner has no vcan), pass, and its report names what ran where."""

from __future__ import annotations

import json
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from tests.inner_pytest import run_pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "docs" / "examples" / "ci-project"

#: The example's own pytest timeout per test (its pyproject.toml), times its three tests,
#: and a margin: the outer limit is the inner one's, never tighter (a busy machine slows
#: every run alike; a hung node is caught by the inner timeout first).
INNER_TIMEOUT_S = 600
OUTER_TIMEOUT_S = 3 * INNER_TIMEOUT_S + 120


@pytest.mark.slow
@pytest.mark.timeout(OUTER_TIMEOUT_S + 60)
def test_the_example_projects_tests_pass(tmp_path: Path) -> None:
    project = tmp_path / "my-drive"
    shutil.copytree(EXAMPLE, project, ignore=shutil.ignore_patterns("__pycache__", ".*cache"))
    p, report = run_pytest(project, tmp_path, timeout=OUTER_TIMEOUT_S)
    assert p.returncode == 0, p.stdout[-4000:] + p.stderr[-2000:]
    root = ET.parse(report).getroot()
    suite = root if root.tag == "testsuite" else root.find("testsuite")
    assert suite is not None
    assert (suite.get("tests"), suite.get("failures"), suite.get("errors")) == ("3", "0", "0")
    assert suite.get("skipped") == "0"
    props = {
        case.get("name"): {str(p.get("name")): str(p.get("value")) for p in case.iter("property")}
        for case in suite.iter("testcase")
    }
    assert set(props) == {
        "test_paper_bounds",
        "test_inductance_error",
        "test_our_controller_on_the_bus",
    }
    for name, prop in props.items():
        # every run went over the bus named, between processes, and was a result
        assert prop["hil.transport"].startswith("udp_multicast"), (name, prop["hil.transport"])
        assert prop["hil.exit_status"] == "0", name
        assert prop["hil.lock_lost"] == "False", name
    # the plug-in ran (not the scenario's own estimator), and the controller under test did
    meta = json.loads((Path(props["test_paper_bounds"]["hil.folder"]) / "meta.json").read_text())
    assert meta["estimator"] == "my_drive.estimator:create"
    dut = Path(props["test_our_controller_on_the_bus"]["hil.folder"])
    meta = json.loads((dut / "meta.json").read_text())
    assert meta["controller"] == "external" and meta["controller_name"] == "my-drive"
    assert (dut / "dut.log").is_file()
