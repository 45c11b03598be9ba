"""A short version of the paper suite: runs, sweep, report.md and summary.json.

Two scenarios (Wen 5.4 with THD and speed error, Xue Fig. 17 with the
overshoot) cut to 1.6 s, run in-process, and the quick speed sweep; the
numbers are not comparable with the papers (the runs end before the load
steps), so the test checks that every cell is filled and agrees with the
runs' own metrics, and that the sweep separates the methods as measured.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

from bench import cli
from bench.scenarios._schema import load_scenario
from bench.studies._report import NOT_RUN, REPRODUCED
from bench.studies._suite import SuiteOptions, quick_scenario, run_suite


@pytest.fixture(scope="module")
def quick_suite(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, dict]:
    tmp = tmp_path_factory.mktemp("suite")
    out, runs = tmp / "out", tmp / "runs"
    summary = run_suite(
        SuiteOptions(
            out_dir=out,
            runs_dir=runs,
            scenarios=("wen-5.4", "xue-fig17"),
            plants=("ideal", "drive"),
            quick=True,
            sweeps=("speed",),
            sweep_quick=True,
            inprocess=True,
            workers=2,
            progress=False,
        )
    )
    return out, runs, summary


def table_rows(md: str) -> list[list[str]]:
    rows = []
    for line in md.splitlines():
        if line.startswith("|") and not line.startswith("|---"):
            rows.append([c.strip() for c in re.split(r"(?<!\\)\|", line.strip())[1:-1]])
    return rows


def test_quick_suite_writes_filled_report_and_summary(quick_suite: tuple[Path, Path, dict]) -> None:
    out, _, summary = quick_suite
    md = (out / "report.md").read_text()
    on_disk = json.loads((out / "summary.json").read_text())
    assert on_disk["claims"] == summary["claims"]
    # every estimator each scenario lists, on each plant
    assert len(summary["runs"]) == 2 * (6 + 3)
    for r in summary["runs"]:
        assert "error" not in r, r
        for k in ("theta_err_max_deg", "theta_err_abs_mean_deg", "speed_err_max_rpm"):
            assert math.isfinite(r["metrics"][k]), (r["scenario"], r["estimator"], k)
    drive = [r for r in summary["runs"] if r["plant"] == "drive"]
    assert len(drive) == 9 and all(r["files"].startswith("runs/drive/") for r in drive)
    assert (out / "runs" / "drive" / "wen-5.4" / "tt-dq" / "metrics.json").is_file()
    # each run claim once per plant: the drive's with its own numbers
    ids = {c["id"]: c for c in summary["claims"]}
    assert ids["wen-5.4-numbers@drive"]["plant"] == "drive"
    assert ids["wen-5.4-numbers@drive"]["detail"] != ids["wen-5.4-numbers"]["detail"]
    assert "drive plant, countermeasures on" in md
    thd = {
        r["estimator"]: r["metrics"]["thd_phase_a_pct"]
        for r in summary["runs"]
        if r["scenario"] == "wen-5.4" and r["plant"] == "ideal"
    }
    assert len(thd) == 6 and all(math.isfinite(v) and v > 0 for v in thd.values())
    over = [
        r["metrics"]["speed_overshoot_rpm"]
        for r in summary["runs"]
        if r["scenario"] == "xue-fig17" and r["plant"] == "ideal"
    ]
    assert len(over) == 3 and all(math.isfinite(v) for v in over)
    rows = table_rows(md)
    assert len(rows) > 20
    for row in rows:
        for c in row:
            assert c and c.lower() not in ("nan", "n/a", "failed"), row
    # the report's numbers are the runs' numbers
    tt = next(
        r for r in summary["runs"] if r["scenario"] == "wen-5.4" and r["estimator"] == "tt-dq"
    )
    row = next(x for x in rows if x[:2] == ["tt-dq", "bench"])
    m = tt["metrics"]
    assert row[2] == f"{m['theta_err_max_deg']:.2f}"
    assert row[4] == f"{m['theta_err_mean_deg']:.2f} / {m['theta_err_abs_mean_deg']:.2f}"
    assert row[6] == f"{m['thd_phase_a_pct']:.2f} / {tt['thd_phase_a_hf_pct']:.2f}"
    assert "where_max" in tt
    # Wen's rivals run on the bench (reconstructed), so every paper row has its bench row
    assert "paper only (not implemented)" not in md
    assert "self-demod ([27], reconstructed)" in md and "epf ([25], reconstructed)" in md


def test_quick_suite_output_is_small_and_runs_keep_the_big_files(
    quick_suite: tuple[Path, Path, dict],
) -> None:
    out, runs, _ = quick_suite
    assert (out / "runs" / "wen-5.4" / "tt-dq" / "run.png").stat().st_size < 120_000
    assert (out / "runs" / "xue-fig17" / "square-wave" / "metrics.json").exists()
    assert (out / "sweeps" / "sweep-speed.png").exists()
    assert not list(out.rglob("signals.csv")) and not list(out.rglob("capture.*"))
    assert (runs / "wen-5.4" / "tt-dq" / "signals.csv").exists()


def test_quick_sweep_verdict_matches_its_slopes(quick_suite: tuple[Path, Path, dict]) -> None:
    _, _, summary = quick_suite
    claims = {c["id"]: c for c in summary["claims"]}
    assert claims["wen-flat-delay"]["verdict"] == NOT_RUN  # no delay sweep in this run
    sp = summary["sweeps"]["speed"]["methods"]
    flat = {e: sp[e]["flat"] for e in ("sfhf", "tt-ab", "tt-dq")}
    want = flat == {"sfhf": False, "tt-ab": False, "tt-dq": True}
    assert (claims["wen-flat-speed"]["verdict"] == REPRODUCED) == want
    # what the bench measures: the alpha-beta and SFHF demodulators drift with speed by
    # several degrees per 100 rpm, the estimated-d-q one stays within FLAT_DEG
    assert abs(sp["tt-ab"]["slope"]) > 2.0 and abs(sp["sfhf"]["slope"]) > 2.0
    assert abs(sp["tt-dq"]["span_deg"]) < 1.0


def test_quick_scenario_moves_the_thd_window_into_the_run() -> None:
    s = quick_scenario(load_scenario("wen-5.4"))
    assert s.duration == pytest.approx(1.6)
    assert s.thd_window_s is not None and s.thd_window_s[1] <= s.duration
    assert s.thd_window_s[0] >= s.score_from_s - 1e-12


def test_cli_rejects_unknown_names_with_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["suite", "paper", "--scenarios", "wen-9.9", "--no-sweep"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "wen-9.9" in err[0]
    assert cli.main(["suite", "sweep", "--sweeps", "temperature"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "temperature" in err[0]


def test_suite_runs_over_the_can_transport_equal_in_process(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The suite's real path: each run two processes in lockstep over udp_multicast.

    Lockstep is exact, so the metrics equal the in-process suite's for the same
    quick scenario; the progress display prints a line per finished run.
    """
    common = dict(
        scenarios=("xue-fig13",),
        estimators=("sensored", "square-wave"),
        plants=("ideal",),
        quick=True,
    )
    over_can = run_suite(
        SuiteOptions(
            out_dir=tmp_path / "can",
            runs_dir=tmp_path / "can-runs",
            interface="udp_multicast",
            workers=2,
            progress=True,
            **common,  # type: ignore[arg-type]
        )
    )
    err = capsys.readouterr().err
    inproc = run_suite(
        SuiteOptions(
            out_dir=tmp_path / "inproc",
            runs_dir=tmp_path / "inproc-runs",
            inprocess=True,
            progress=False,
            **common,  # type: ignore[arg-type]
        )
    )
    assert over_can["suite"]["transport"].startswith("udp_multicast")
    assert over_can["suite"]["mode"] == "lockstep"
    by = {(r["scenario"], r["estimator"]): r for r in inproc["runs"]}
    assert len(over_can["runs"]) == len(by) == 2
    for r in over_can["runs"]:
        ref = by[(r["scenario"], r["estimator"])]
        for key in ("theta_err_max_deg", "theta_err_rms_deg", "speed_err_max_rpm", "steps"):
            assert r["metrics"][key] == ref["metrics"][key], (r["estimator"], key)
        run_dir = tmp_path / "can-runs" / r["scenario"] / r["estimator"]
        assert (run_dir / "capture.blf").is_file() and (run_dir / "plant.json").is_file()
    # the progress display: one line per finished run (stderr is not a terminal here)
    done = [ln for ln in err.splitlines() if re.match(r"\[\d/2\] xue-fig13", ln)]
    assert len(done) == 2 and all(" done " in ln for ln in done), err


def test_run_record_keeps_a_hybrid_runs_band_metrics(tmp_path: Path) -> None:
    """``summary.json`` keeps the per-band figures and hand-overs of a hybrid run (the
    report's per-band table reads them there); other metrics stay to the fixed list."""
    from bench.studies._suite import SUMMARY_METRICS, RunJob, run_record

    scn = load_scenario("wide-speed-xue")
    job = RunJob(scn, "hybrid-square-wave", tmp_path / "run", None)
    band = {
        "band_lo_rpm": 50.4,
        "band_below_steps": 10,
        "band_above_injection_loss_w": None,
        "handover_at_s": [10.06],
        "handover_dips_pct": [3.5],
        "handover_dip_max_pct": 3.5,
    }
    metrics = {"theta_err_max_deg": 1.0, "frames_recorded": 99, **band}
    rec = run_record(job, {"metrics": metrics, "wall_s": 1.0}, tmp_path)
    assert rec["metrics"] == {"theta_err_max_deg": 1.0, **band}
    assert "frames_recorded" not in SUMMARY_METRICS


def test_update_reruns_only_the_chosen_runs_and_keeps_every_other_record(
    quick_suite: tuple[Path, Path, dict], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``bench suite paper --update``: the chosen run's record and folder are replaced, every
    other record and file stays byte for byte; a filter that matches no run is one line."""
    import shutil

    out, _, _ = quick_suite
    copy = tmp_path / "suite"
    shutil.copytree(out, copy)
    before = json.loads((out / "summary.json").read_text())
    victim = ("xue-fig17", "square-wave", "drive")
    vdir = Path("runs", "drive", "xue-fig17", "square-wave")
    # a stale record and a stale file, so that a kept (not replaced) run is seen
    stale = json.loads((copy / "summary.json").read_text())
    for r in stale["runs"]:
        if (r["scenario"], r["estimator"], r["plant"]) == victim:
            r["metrics"]["theta_err_rms_deg"] = -1.0
    (copy / "summary.json").write_text(json.dumps(stale))
    (copy / vdir / "stale.txt").write_text("older run")
    args = ["suite", "paper", "--update", "--quick", "--inprocess", "--out", str(copy)]
    args += ["--runs-dir", str(tmp_path / "runs"), "-q"]
    sel = ["--scenarios", "xue-fig17", "--estimators", "square-wave", "--plants", "drive"]
    assert cli.main([*args, *sel]) == 0
    after = json.loads((copy / "summary.json").read_text())
    assert len(after["runs"]) == len(before["runs"]) == 18
    replaced = 0
    for old, new in zip(before["runs"], after["runs"], strict=True):
        key = (new["scenario"], new["estimator"], new["plant"])
        assert key == (old["scenario"], old["estimator"], old["plant"])  # in its place
        if key == victim:
            replaced += 1
            assert new["metrics"]["theta_err_rms_deg"] > 0  # not the stale record
            # lockstep is exact: the run made again gives the same numbers
            assert {k: v for k, v in new["metrics"].items() if k != "wall_s"} == {
                k: v for k, v in old["metrics"].items() if k != "wall_s"
            }
        else:
            assert json.dumps(new, sort_keys=True) == json.dumps(old, sort_keys=True), key
    assert replaced == 1
    assert after["sweeps"] == before["sweeps"]  # no sweep ran: the kept one stays
    assert [u["runs"] for u in after["suite"]["updates"]] == [[list(victim)]]
    # the report says which runs were made again
    note = "`bench suite paper --update` (1 updates): xue-fig17/square-wave (drive)."
    assert note in (copy / "report.md").read_text()
    for f in out.rglob("*"):
        rel = f.relative_to(out)
        if f.is_file() and rel.parent != vdir and rel.name not in ("summary.json", "report.md"):
            assert (copy / rel).read_bytes() == f.read_bytes(), rel
    assert not (copy / vdir / "stale.txt").exists()
    assert (copy / vdir / "metrics.json").is_file() and (copy / vdir / "run.png").is_file()
    capsys.readouterr()
    # a filter that matches no run: one line, exit 2, the suite untouched
    kept = (copy / "summary.json").read_bytes()
    nothing = ["--scenarios", "wen-5.4", "--estimators", "square-wave"]
    assert cli.main([*args, *nothing]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "square-wave" in err[0] and "nothing left to run" in err[0], err
    assert (copy / "summary.json").read_bytes() == kept
    # runs made otherwise than the suite's (over a bus into an in-process suite): refused
    assert cli.main([*args[:4], *args[5:], *sel]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--inprocess" in err[0], err
    # no suite in --out
    assert cli.main(["suite", "paper", "--update", "--out", str(tmp_path / "none"), *sel]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "summary.json" in err[0], err
