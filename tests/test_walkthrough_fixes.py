"""Defects of a user walkthrough: each a one-line error or the right file, not a surprise.

- ``bench rerun -e tt-dq`` on a 1 kHz Xue capture: the same one-line error as ``bench run``;
- a reused ``--out`` folder: the capture its ``meta.json`` names, not an older one beside it;
- ``bench suite paper`` whose filters leave nothing to run: an error, not an empty report;
- ``bench suite report``: the sweeps in the suite's order, the committed report byte for byte;
- ``bench rerun``: the paper's column names the method its numbers belong to.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import can
import pytest

from bench.captures._read import (
    _find_in_folder,
    read_capture,
)
from bench.captures._rerun import rerun_capture
from bench.cli import main
from bench.runs._run import run_scenario
from bench.scenarios._schema import load_scenario
from bench.studies._report import render_markdown
from bench.studies._suite import unmatched_estimators
from bench.wire._bus import BusSpec
from tests.ports import free_port

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results"


def quiet(_: str) -> None:
    pass


@pytest.fixture(scope="module")
def xue_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A recorded xue-fig13 run (1 kHz, square-wave, 0.2 s) with an ASC capture."""
    scn = load_scenario("xue-fig13").with_overrides(duration=0.2, score_from_s=0.1)
    out = tmp_path_factory.mktemp("xue-fig13")
    run_scenario(
        scn,
        "square-wave",
        spec=BusSpec("udp_multicast", "239.74.163.2", free_port()),
        out_dir=out,
        log_format="asc",
        progress=False,
    )
    return out


def _write_blf(path: Path, n: int) -> None:
    with can.BLFWriter(str(path)) as w:
        for i in range(n):
            w.on_message_received(
                can.Message(timestamp=1.0 + i, arbitration_id=0x7F0, data=bytes([i] * 8))
            )


def _error_lines(capsys: pytest.CaptureFixture[str]) -> list[str]:
    return capsys.readouterr().err.strip().splitlines()


# ---------------------------------------------------------------- 1: rerun of a misfit


def test_rerun_of_an_estimator_that_cannot_run_the_scenario_is_one_line(
    xue_run: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["run", "xue-fig13", "-e", "tt-dq"]) == 2
    run_err = _error_lines(capsys)
    assert len(run_err) == 1 and run_err[0].startswith("bench: error: --estimator tt-dq: cannot")

    assert main(["rerun", str(xue_run), "-e", "tt-dq", "--no-plots"]) == 2
    err = _error_lines(capsys)
    assert err == run_err  # the same check, the same words
    assert "Nyquist" in err[0] and "Traceback" not in err[0]
    assert not (xue_run / "rerun-tt-dq").exists()  # nothing written


# ---------------------------------------------------------------- 2: a reused --out folder


def test_a_reused_folder_gives_the_capture_its_meta_json_names(
    xue_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "reused"
    shutil.copytree(xue_run, folder)
    _write_blf(folder / "capture.blf", 3)  # an older BLF run's capture, left behind
    assert json.loads((folder / "meta.json").read_text())["capture"] == "capture.asc"
    assert _find_in_folder(folder) == folder / "capture.asc"
    frames, problem = read_capture(folder)
    asc, _ = read_capture(folder / "capture.asc")
    assert problem is None and len(frames) == len(asc) > 100

    # rerun of the folder: the recorded estimator on its own capture reproduces it
    res = rerun_capture(folder, "square-wave", out_dir=tmp_path / "r", plots=False, echo=quiet)
    assert res.report["estimate"]["reproduces_recorded_bit_for_bit"]

    # replay of the folder sends the ASC capture's frames
    port = free_port()
    rc = main(["replay", str(folder), "-i", "udp_multicast", "--port", str(port), "--speed", "20"])
    assert rc == 0
    assert f"replay: {len(asc)} of {len(asc)} frames" in capsys.readouterr().err


@pytest.mark.parametrize(
    "meta",
    [None, "{not json", json.dumps({"capture": "capture.log"}), json.dumps({"capture": None})],
    ids=["no-meta", "unreadable-meta", "named-file-missing", "no-capture-entry"],
)
def test_without_a_usable_meta_json_the_first_capture_is_taken(
    meta: str | None, tmp_path: Path
) -> None:
    _write_blf(tmp_path / "capture.blf", 2)
    (tmp_path / "capture.asc").write_text("")
    if meta is not None:
        (tmp_path / "meta.json").write_text(meta)
    assert _find_in_folder(tmp_path) == tmp_path / "capture.blf"


def test_meta_json_names_a_file_of_the_folder_only(tmp_path: Path) -> None:
    outside = tmp_path / "capture.asc"
    outside.write_text("")
    folder = tmp_path / "run"
    folder.mkdir()
    _write_blf(folder / "capture.blf", 2)
    (folder / "meta.json").write_text(json.dumps({"capture": str(outside)}))
    assert _find_in_folder(folder) == folder / "capture.blf"


# ---------------------------------------------------------------- 3: a suite with nothing to run


def test_suite_with_nothing_left_to_run_is_an_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    rc = main(
        [
            "suite",
            "paper",
            "--scenarios",
            "xue-fig13",
            "--estimators",
            "tt-dq",
            "--no-sweep",
            "--quick",
            "--inprocess",
            "-o",
            str(out),
            "--runs-dir",
            str(tmp_path / "runs"),
        ]
    )
    assert rc == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("bench: error: --estimators tt-dq: ")
    assert "xue-fig13 lists square-wave, square-wave-nocic, sensored" in err[0]
    assert err[0].endswith("nothing left to run")
    assert captured.out == ""
    assert not out.exists()  # no report of claims "not run"


def test_unmatched_estimators_names_only_those_no_scenario_lists() -> None:
    assert unmatched_estimators(("xue-fig13", "wen-5.1"), ("tt-dq", "square-wave")) is None
    why = unmatched_estimators(("xue-fig13",), ("sensored", "tt-dq", "sfhf"))
    assert why is not None
    assert why.startswith("--estimators tt-dq, sfhf: ")
    assert "sensored:" not in why


# ---------------------------------------------------------------- 4: the report's sweep order


def test_suite_report_reproduces_the_committed_report(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    copy = tmp_path / "results"
    shutil.copytree(RESULTS, copy)
    # away from the repository: the run folders of a local suite run are not read
    monkeypatch.chdir(tmp_path)
    assert main(["suite", "report", str(copy)]) == 0
    capsys.readouterr()
    assert (copy / "report.md").read_bytes() == (RESULTS / "report.md").read_bytes()
    assert (copy / "summary.json").read_bytes() == (RESULTS / "summary.json").read_bytes()


def test_report_orders_sweeps_and_methods_as_the_suite_does() -> None:
    from bench.studies._sweep import METHODS, SWEEPS

    summary = json.loads((RESULTS / "summary.json").read_text())
    want = render_markdown(summary)
    heads = re.findall(r"^### position error vs (.*)$", want, flags=re.M)
    assert heads == [SWEEPS[k].label for k in SWEEPS if k in summary["sweeps"]]
    # the same summary in any order of its sweeps and methods: the same report
    summary["sweeps"] = {
        k: dict(v, methods=dict(reversed(list(v["methods"].items()))))
        for k, v in reversed(list(summary["sweeps"].items()))
    }
    assert render_markdown(summary) == want
    first = want.index("### position error vs")
    rows = re.findall(r"^\| (sfhf|tt-ab|tt-dq) \|", want[first:], flags=re.M)
    assert rows[: len(METHODS)] == list(METHODS)


def test_failed_points_are_listed_in_the_sweeps_order() -> None:
    """Error keys are text ("100" sorts before "25" in summary.json): listed by value."""
    summary = json.loads((RESULTS / "summary.json").read_text())
    # a sweep whose values sort differently as text (speed: "400" < "50")
    kind, sw = next(
        (k, v)
        for k, v in summary["sweeps"].items()
        if f"{v['values'][-1]:g}" < f"{v['values'][1]:g}"
    )
    est = next(iter(sw["methods"]))
    lo, hi = sw["values"][1], sw["values"][-1]
    errs = {f"{hi:g}": "late", f"{lo:g}": "early"}
    sw["methods"][est]["errors"] = dict(sorted(errs.items()))  # as read back from JSON
    text = render_markdown(summary)
    line = next(ln for ln in text.splitlines() if ln.startswith("Failed points: "))
    assert line == f"Failed points: {est} at {lo:g}: early; {est} at {hi:g}: late", kind
    sw["methods"][est]["errors"] = errs  # as built by the suite: the same report
    assert render_markdown(summary) == text


# ---------------------------------------------------------------- 5: the paper's column of rerun


def test_rerun_names_the_method_of_the_papers_column(
    xue_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from bench.runs._results import format_metrics

    scn = load_scenario("xue-fig13")
    assert main(["rerun", str(xue_run), "-e", "sensored", "--no-plots", "-o", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    head = out.splitlines()[0]
    # another method than the paper's: no paper column beside it, a line naming whose it is
    assert head.split() == ["metric", "bench"]
    assert f"(the paper's numbers are for {scn.estimator}; this run is sensored)" in out
    # the heading bench run prints for the paper's own method
    own = format_metrics({}, scn.paper_result, scn.estimator, scn.estimator).splitlines()[0]
    assert own.split()[-2:] == ["paper", f"({scn.estimator})"]
    res = rerun_capture(xue_run, "sensored", out_dir=tmp_path, plots=False, echo=quiet)
    assert res.paper_method == "square-wave"
