"""The controller's design travels in the run's plan (bench/nodes/_plan.py, controller/_design.py).

``bench run`` designs the controller once (its check of the estimator) and
hands the design to the controller node in ``plan.json``: the node builds the
same controller without a search, and without importing scipy. A plan whose
design was made for other settings is not used (the node designs for the
plan's settings and says so); a plan made without one (``bench controller
SCENARIO``) has the node design for itself.
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from bench.nodes._loops import controller_node
from bench.nodes._plan import make_plan, read_plan
from bench.scenarios import _setup
from bench.scenarios._schema import Scenario, load_scenario
from bench.wire._bus import BusSpec
from bench.wire._codec import Codec
from controller import Controller, DesignRecord

BUS = BusSpec("udp_multicast", "239.0.0.1", 44100)


def _plan(tmp_path: Path, name: str, est: str, design: bool = True) -> Path:
    scn = load_scenario(name).with_overrides(duration=0.1)
    rec = _setup.checked_design(scn, est)[1] if design else None
    plan = make_plan(scn, est, mode="lockstep", plant_bus=BUS, run_id=5, design=rec)
    return plan.write(tmp_path / f"{name}-{est}.json")


def _no_search(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every search and discretisation of a design fails: only a design record can serve."""
    import scipy.optimize
    import scipy.signal

    def searched(*a: object, **k: object) -> None:
        raise AssertionError("the node searched its design again")

    monkeypatch.setattr(scipy.optimize, "brentq", searched)
    monkeypatch.setattr(scipy.signal, "bilinear", searched)


@pytest.mark.parametrize(
    ("name", "est"), [("wen-5.1", "tt-dq"), ("xue-fig13", "square-wave"), ("wen-5.1", "sensored")]
)
def test_the_node_builds_the_plans_design_without_searching(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, name: str, est: str
) -> None:
    plan = read_plan(_plan(tmp_path, name, est))
    assert plan.controller is not None and plan.design is not None and plan.design.results
    fresh = Controller(plan.controller).gains()  # designed here, searches and all
    _no_search(monkeypatch)
    node = controller_node(plan, Codec())
    assert node.ctrl.design_refused is None
    assert node.ctrl.gains() == fresh


def test_a_node_handed_its_design_imports_no_scipy(tmp_path: Path) -> None:
    plan_file = _plan(tmp_path, "wen-5.1", "tt-dq")
    code = (
        "import sys\n"
        "from bench.nodes._loops import controller_node\n"
        "from bench.nodes._plan import read_plan\n"
        "from bench.wire._codec import Codec\n"
        f"node = controller_node(read_plan({str(plan_file)!r}), Codec())\n"
        "node.ctrl.gains()\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy'))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout


def test_a_design_made_for_other_settings_is_not_used(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plan = read_plan(_plan(tmp_path, "wen-5.1", "tt-dq"))
    other = read_plan(_plan(tmp_path, "wen-5.1", "tt-ab"))

    assert plan.controller is not None and other.controller is not None
    mixed = replace(plan, design=other.design)
    node = controller_node(mixed, Codec())
    err = capsys.readouterr().err
    assert "field 'design'" in err and "designed for 'controller' here" in err
    assert node.ctrl.design_refused is not None
    # the controller of the plan's settings, not the other design's
    assert node.ctrl.gains() == Controller(plan.controller).gains()
    assert node.ctrl.gains() != Controller(other.controller).gains()


def test_a_plan_without_a_design_has_the_node_design_for_itself(tmp_path: Path) -> None:
    plan = read_plan(_plan(tmp_path, "wen-5.1", "tt-dq", design=False))
    assert plan.controller is not None and plan.design is None
    node = controller_node(plan, Codec())
    assert node.ctrl.design_refused is None
    assert node.ctrl.gains() == Controller(plan.controller).gains()


def test_the_settings_digest_survives_the_plans_json(tmp_path: Path) -> None:
    from controller._design import settings_digest

    for name, est in (("wen-5.3", "tt-dq"), ("xue-fig17", "square-wave"), ("wen-5.1", "sfhf")):
        scn = load_scenario(name)
        plan = read_plan(_plan(tmp_path, name, est))
        assert plan.controller is not None and plan.design is not None
        assert settings_digest(plan.controller) == plan.design.settings
        assert settings_digest(_setup.controller_pars(scn, est)) == plan.design.settings


def _kept_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[Scenario, DesignRecord]:
    """wen-5.1's tt-dq design, made once with the cache in ``tmp_path``."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    scn = load_scenario("wen-5.1")
    return scn, _setup.checked_design(scn, "tt-dq")[1]


def test_a_design_is_kept_for_the_next_run_of_the_same_settings(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from bench.scenarios._designs import cache_dir

    scn, first = _kept_once(tmp_path, monkeypatch)
    assert len(list(cache_dir().glob("*.json"))) == 1
    _no_search(monkeypatch)  # the second run of the same settings searches nothing
    assert _setup.checked_design(scn, "tt-dq")[1] == first
    # other settings are another design, and need their own search
    with pytest.raises(AssertionError, match="searched its design again"):
        _setup.checked_design(scn.with_overrides(f_sw=8000.0), "tt-dq")


def test_the_design_cache_can_be_turned_off(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from bench.scenarios._designs import CACHE_ENV, cache_dir

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setenv(CACHE_ENV, "off")
    _setup.checked_design(load_scenario("wen-5.1"), "tt-dq")
    assert not cache_dir().exists()


def test_a_kept_design_that_cannot_be_read_is_made_again(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from bench.scenarios._designs import cache_dir

    scn, first = _kept_once(tmp_path, monkeypatch)
    (kept,) = cache_dir().glob("*.json")
    kept.write_text("{not json")
    assert _setup.checked_design(scn, "tt-dq")[1] == first
    assert kept.read_text().startswith('{"settings"')
