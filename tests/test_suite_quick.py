"""``bench suite paper --quick``: the smoke selection, what its help says, and what it costs.

The suite itself is replaced by a stub that records what it was asked to
run: these tests check the selection, not the runs (tests/test_suite.py).
"""

from __future__ import annotations

from typing import Any

import pytest

from bench import cli
from bench.scenarios._schema import load_scenario
from bench.studies import _suite
from bench.studies._suite import QUICK_DURATION_S, SMOKE, paper_jobs
from bench.studies._sweep import SWEEPS, sweep_jobs


@pytest.fixture
def asked(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    got: list[Any] = []

    def fake_run_suite(opt: Any) -> dict[str, Any]:
        got.append(opt)
        return {"suite": {}, "claims": []}

    monkeypatch.setattr(_suite, "run_suite", fake_run_suite)
    return got


def test_quick_alone_runs_the_smoke_selection(asked: list[Any], tmp_path: Any) -> None:
    assert cli.main(["suite", "paper", "--quick", "--out", str(tmp_path / "o"), "-q"]) == 0
    (opt,) = asked
    assert opt.quick and opt.sweep_quick
    assert opt.scenarios == SMOKE.scenarios and opt.estimators == SMOKE.estimators
    assert opt.plants == ("ideal",) and opt.sweeps == ("speed",)
    jobs = paper_jobs(
        tmp_path, scenarios=opt.scenarios, estimators=opt.estimators, quick=True, plants=opt.plants
    )
    # one run per scenario (paper and estimator family), each cut short
    assert [(j.scenario.name, j.estimator) for j in jobs] == list(
        zip(SMOKE.scenarios, SMOKE.estimators, strict=True)
    )
    assert all(j.scenario.duration <= QUICK_DURATION_S for j in jobs)
    families = {load_scenario(s).paper for s in SMOKE.scenarios}
    assert len(families) == len(SMOKE.scenarios)  # one scenario per paper
    points = sweep_jobs(opt.sweeps, quick=True)
    assert len(points) == 9 and all(p.scenario.duration <= QUICK_DURATION_S for p in points)


def test_quick_with_a_choice_runs_that_choice_cut_short(asked: list[Any], tmp_path: Any) -> None:
    args = ["suite", "paper", "--quick", "--scenarios", "wen-5.4", "--plants", "ideal,drive"]
    assert cli.main([*args, "--no-sweep", "--out", str(tmp_path / "o"), "-q"]) == 0
    (opt,) = asked
    assert opt.scenarios == ("wen-5.4",) and opt.estimators is None
    assert opt.plants == ("ideal", "drive") and opt.sweeps == () and opt.quick
    # without --quick: every shipped scenario on every plant, every sweep
    assert cli.main(["suite", "paper", "--out", str(tmp_path / "p"), "-q"]) == 0
    full = asked[1]
    assert not full.quick and len(full.plants) == 3 and full.sweeps == tuple(SWEEPS)
    assert len(full.scenarios) > len(SMOKE.scenarios)


def test_quick_help_names_what_it_runs(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        cli.build_parser().parse_args(["suite", "paper", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    quick = text[text.index("--quick") :].replace("- ", "-")
    for name in (*SMOKE.scenarios, *SMOKE.estimators, *SMOKE.plants, *SMOKE.sweeps):
        assert name in quick, name
    assert f"{QUICK_DURATION_S:g} s" in quick and "minute" in quick
