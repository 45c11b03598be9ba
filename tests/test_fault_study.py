"""``bench suite faults``: the outcome of a case, a failed case as a result, and
docs/FAULTS.md and the README's block as the rendering of docs/faults/faults.json."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench.cli import main
from bench.studies._faults import (
    AT_S,
    BUS_KINDS,
    CONTROLLERS,
    EXTERNAL,
    OUTCOMES,
    PROCESS_ESTIMATOR,
    cases_of,
    catalogue,
    headline,
    outcome,
    readme_block,
    render_doc,
    run_case,
    run_fault_study,
    shortest_duration,
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
    runnable = {k for k, v in KINDS.items() if not v.refused}
    assert kinds == runnable
    assert all(f["at_s"] == AT_S for _, f in catalogue(540.0))


def test_a_case_that_fails_is_a_record_not_a_crash() -> None:
    bad = {"at_s": AT_S, "kind": "drop", "message": "PlantTruth", "prob": 1.0}
    rec = run_case("square-wave", "drop: PlantTruth", bad, 1.5)
    assert rec["outcome"] == "failed" and "faults[0].message" in rec["error"]


def test_study_runs_and_renders(tmp_path: Path) -> None:
    s = run_fault_study(
        tmp_path,
        estimators=("square-wave",),
        kinds=("dc_link_step", "babble"),
        controllers=("in-process",),
        duration=1.2,
    )
    by = {r["fault"]: r for r in s["records"]}
    assert [r["kind"] for r in s["records"]] == ["dc_link_step", "dc_link_step", "babble"]
    sag = by["dc_link_step: sag to 60 %"]
    assert sag["outcome"] == "detected" and sag["detected_by"] == "controller_dc_undervoltage"
    assert by["dc_link_step: surge to 118 %"]["detected_by"] == "controller_dc_overvoltage"
    assert sum(headline(s)[("square-wave", "in-process")].values()) == 3
    assert {r["controller"] for r in s["records"]} == {"in-process"}
    assert (tmp_path / "report.md").read_text() == render_doc(
        json.loads((tmp_path / "faults.json").read_text())
    )


def test_committed_doc_and_readme_are_the_json() -> None:
    summary = json.loads(JSON.read_text(encoding="utf-8"))
    assert (ROOT / "docs" / "FAULTS.md").read_text(encoding="utf-8") == render_doc(summary)
    assert readme_block(summary) in (ROOT / "README.md").read_text(encoding="utf-8")
    from controller import ESTIMATOR_NAMES

    counts = headline(summary)
    inproc = [e for e, c in counts if c == "in-process"]
    assert tuple(inproc) == ESTIMATOR_NAMES
    assert all(sum(counts[(e, "in-process")].values()) == len(catalogue(540.0)) for e in inproc)
    assert set(next(iter(counts.values()))) == set(OUTCOMES)
    # the process variants: the bus kinds with one estimator, and the external controller
    bus = [lab for lab, f in catalogue(540.0) if f["kind"] in BUS_KINDS]
    for key in ((PROCESS_ESTIMATOR, "python"), (PROCESS_ESTIMATOR, "native"), (EXTERNAL,) * 2):
        assert sum(counts[key].values()) == len(bus), key
    assert set(counts) == {
        *((e, "in-process") for e in ESTIMATOR_NAMES),
        *((PROCESS_ESTIMATOR, "python"), (PROCESS_ESTIMATOR, "native"), (EXTERNAL, EXTERNAL)),
    }


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
    assert main(["suite", "faults", "--controllers", "matlab", "--out", str(tmp_path)]) == 2
    assert "--controllers: unknown 'matlab'" in capsys.readouterr().err
    assert main(["suite", "faults", "--update", "--out", str(tmp_path / "none")]) == 2
    assert "--update: " in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    assert main(["suite", "faults", "--from-json", str(bad)]) == 2
    assert "not a fault study's faults.json" in capsys.readouterr().err


def test_process_variants_run_the_bus_kinds_with_one_estimator_unless_full() -> None:
    ests = ("sfhf", "tt-dq", "square-wave")
    cases = cases_of(ests, None, CONTROLLERS, "bus")
    n_all, n_bus = len(catalogue(540.0)), sum(f["kind"] in BUS_KINDS for _, f in catalogue(540.0))
    by: dict[tuple[str, str], int] = {}
    for ctl, est, _, _ in cases:
        by[(ctl, est)] = by.get((ctl, est), 0) + 1
    assert by == {
        **{("in-process", e): n_all for e in ests},
        ("python", "tt-dq"): n_bus,
        ("native", "tt-dq"): n_bus,
        ("external", EXTERNAL): n_bus,
    }
    full = cases_of(ests, ("babble",), ("native", "external"), "full")
    assert [(c, e) for c, e, _, _ in full] == [
        ("native", "sfhf"),
        ("native", "tt-dq"),
        ("native", "square-wave"),
        ("external", EXTERNAL),
    ]


def test_update_keeps_the_cases_not_run(tmp_path: Path) -> None:
    old = json.loads(JSON.read_text(encoding="utf-8"))
    s = run_fault_study(
        tmp_path,
        estimators=("square-wave",),
        kinds=("babble",),
        controllers=("in-process",),
        duration=old["duration_s"],
        keep=old,
    )
    assert len(s["records"]) == len(old["records"])
    new = [r for r in s["records"] if r["estimator"] == "square-wave" and r["kind"] == "babble"]
    assert len(new) == 1 and new[0]["controller"] == "in-process"
    assert [r["fault"] for r in s["records"]] == [r["fault"] for r in old["records"]]


def test_the_controller_as_a_process_gives_the_in_process_record() -> None:
    """A 50 ms sample loss in lockstep (the retransmission rules) with the Python and the
    native controller node as processes over udp_multicast: the same record as in
    process, reaction time and angle error included (lockstep is deterministic whatever
    carries the frames); the native node served (not a fallback)."""
    label, fault = next((lab, f) for lab, f in catalogue(540.0) if "PhaseSamples" in lab)
    recs = {c: run_case("square-wave", label, fault, 1.2, c) for c in CONTROLLERS[:3]}
    ref = recs["in-process"]
    assert ref["outcome"] == "tripped" and ref["error"] is None
    same = ("exit_status", "detected_by", "reaction_ms", "lock_kept", "theta_err_abs_max_deg")
    for c in ("python", "native"):
        assert recs[c]["controller"] == c
        assert {k: recs[c][k] for k in same} == {k: ref[k] for k in same}, c
    assert recs["native"]["node_engine"] == "native"
    assert recs["python"]["node_engine"] == "python"


def test_the_external_controller_is_scored_by_the_plant_protections() -> None:
    """The example external controller (no supervision) under 50 ms of silence: the plant's
    duty watchdog trips after its 20 ms (wen-5.1, 10 kHz: 198 periods after the last duty,
    period 4999's), as for the bench's own controller."""
    label, fault = next((lab, f) for lab, f in catalogue(540.0) if f["kind"] == "silence")
    rec = run_case("tt-dq", label, fault, shortest_duration() + 0.05, EXTERNAL)
    assert rec["estimator"] == EXTERNAL and rec["controller"] == EXTERNAL
    assert rec["error"] is None, rec["error"]
    assert rec["outcome"] == "tripped" and rec["detected_by"] == "watchdog"
    assert rec["reaction_ms"] == pytest.approx(19.8)
