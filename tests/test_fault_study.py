"""``bench suite faults``: the outcome of a case, a failed case as a result, and
docs/FAULTS.md and the README's block as the rendering of docs/faults/faults.json."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench.cli import main
from bench.studies._faults import (
    AT_S,
    OUTCOMES,
    catalogue,
    headline,
    outcome,
    readme_block,
    render_doc,
    run_case,
    run_fault_study,
)

ROOT = Path(__file__).resolve().parents[1]
JSON = ROOT / "docs" / "faults" / "faults.json"


@pytest.mark.parametrize(
    ("rec", "want"),
    [
        ({"detected_by": "controller_open_phase", "lock_kept": False}, "detected"),
        ({"detected_by": "watchdog", "lock_kept": True}, "tripped"),
        ({"detected_by": None, "lock_kept": True}, "ridden through"),
        ({"detected_by": None, "lock_kept": None}, "ridden through"),
        ({"detected_by": None, "lock_kept": False}, "lock lost"),
        ({"error": "x", "detected_by": "watchdog"}, "failed"),
    ],
)
def test_outcome(rec: dict[str, object], want: str) -> None:
    assert outcome(rec) == want


def test_catalogue_covers_every_kind_a_lockstep_run_applies() -> None:
    from bench.scenarios._faults import KINDS

    kinds = {f["kind"] for _, f in catalogue(540.0)}
    runnable = {k for k, v in KINDS.items() if not v.refused and k != "silence"}
    assert kinds == runnable
    assert all(f["at_s"] == AT_S for _, f in catalogue(540.0))


def test_a_case_that_fails_is_a_record_not_a_crash() -> None:
    rec = run_case("square-wave", "silence", {"at_s": AT_S, "kind": "silence"}, 1.5)
    assert rec["outcome"] == "failed" and "not implemented in lockstep" in rec["error"]


def test_study_runs_and_renders(tmp_path: Path) -> None:
    s = run_fault_study(
        tmp_path, estimators=("square-wave",), kinds=("dc_link_step", "babble"), duration=1.2
    )
    by = {r["fault"]: r for r in s["records"]}
    assert [r["kind"] for r in s["records"]] == ["dc_link_step", "dc_link_step", "babble"]
    sag = by["dc_link_step: sag to 60 %"]
    assert sag["outcome"] == "detected" and sag["detected_by"] == "controller_dc_undervoltage"
    assert by["dc_link_step: surge to 118 %"]["detected_by"] == "controller_dc_overvoltage"
    assert sum(headline(s)["square-wave"].values()) == 3
    assert (tmp_path / "report.md").read_text() == render_doc(
        json.loads((tmp_path / "faults.json").read_text())
    )


def test_committed_doc_and_readme_are_the_json() -> None:
    summary = json.loads(JSON.read_text(encoding="utf-8"))
    assert (ROOT / "docs" / "FAULTS.md").read_text(encoding="utf-8") == render_doc(summary)
    assert readme_block(summary) in (ROOT / "README.md").read_text(encoding="utf-8")
    from controller import ESTIMATOR_NAMES

    counts = headline(summary)
    assert tuple(counts) == ESTIMATOR_NAMES
    assert all(sum(c.values()) == len(catalogue(540.0)) for c in counts.values())
    assert set(next(iter(counts.values()))) == set(OUTCOMES)


def test_from_json_renders_without_running(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    doc = tmp_path / "F.md"
    assert main(["suite", "faults", "--from-json", str(JSON), "--doc", str(doc)]) == 0
    assert doc.read_text(encoding="utf-8") == (ROOT / "docs" / "FAULTS.md").read_text(
        encoding="utf-8"
    )
    assert main(["suite", "faults", "--duration", "0.9", "--out", str(tmp_path)]) == 2
    assert "--duration must be > 1 s" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    assert main(["suite", "faults", "--from-json", str(bad)]) == 2
    assert "not a fault study's faults.json" in capsys.readouterr().err
