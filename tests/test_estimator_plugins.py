"""Estimator plug-ins: ``package.module:factory`` and the entry-point group, checked on load."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from bench.cli import main
from bench.scenarios._setup import motor_model
from controller import EstimatorPluginError, UnknownEstimatorError, make_estimator
from controller._registry import ENTRY_POINT_GROUP, entry_point_names, injection_family
from plant_rt import preset

EXAMPLES = Path(__file__).resolve().parent.parent / "docs" / "examples"
T_S = 1e-4


@pytest.fixture
def examples_on_path(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(str(EXAMPLES))


def _write(tmp: Path, name: str, text: str) -> None:
    (tmp / f"{name}.py").write_text(text)


def test_the_example_loads_by_module_and_factory(examples_on_path: None) -> None:
    m = motor_model(preset("wen2023"))
    est = make_estimator("my_estimator:create", m, T_S, V_h=50.0, alpha_o=100.0)
    # V_h is a rotating-injection option the factory does not name: not passed;
    # alpha_o is, and sets the PLL's double pole
    assert est.gains()["k_i"] == pytest.approx(1e4)
    assert injection_family("my_estimator:create") == "none"
    est.reset(1.0)
    assert est.theta_hat == pytest.approx(1.0)
    assert est.injection() == (0.0, 0.0)


def test_entry_point_group_registers_a_name(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _write(tmp_path, "acme_est", "from my_estimator import create\n")
    dist = tmp_path / "acme_est-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: acme-est\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text(f"[{ENTRY_POINT_GROUP}]\nacme-flux = acme_est:create\n")
    monkeypatch.syspath_prepend(str(EXAMPLES))
    monkeypatch.syspath_prepend(str(tmp_path))
    assert "acme-flux" in entry_point_names()
    assert injection_family("acme-flux") == "none"
    est = make_estimator("acme-flux", motor_model(preset("wen2023")), T_S)
    assert type(est).__name__ == "FluxPLL"


@pytest.mark.parametrize(
    ("name", "text", "says"),
    [
        ("broken_imp", "import no_such_module_xyz\n", "cannot import broken_imp"),
        ("no_factory", "x = 1\n", "has no 'create'"),
        ("not_callable", "create = 3\n", "not callable"),
        (
            "bad_family",
            "def create(m, T_s):\n    return None\ncreate.injection_family = 'hf'\n",
            "injection_family 'hf'",
        ),
    ],
)
def test_a_plugin_that_fails_to_load_is_one_line_naming_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, name: str, text: str, says: str
) -> None:
    _write(tmp_path, name, text)
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(EstimatorPluginError) as e:
        injection_family(f"{name}:create")
    msg = str(e.value)
    assert "\n" not in msg and f"{name}:create" in msg and says in msg


def test_an_estimator_missing_the_protocol_is_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _write(
        tmp_path,
        "half_est",
        "class E:\n    theta_hat = 0.0\n    w_hat = 0.0\n    err = 0.0\n"
        "    def injection(self):\n        return 0.0, 0.0\n"
        "def create(m, T_s, **kw):\n    return E()\n",
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(EstimatorPluginError) as e:
        make_estimator("half_est:create", motor_model(preset("wen2023")), T_S)
    msg = str(e.value)
    assert "half_est:create" in msg and "Estimator protocol" in msg
    for member in ("i_alpha_f", "i_beta_f", "update()", "reset()"):
        assert member in msg
    assert "injection()" not in msg and "theta_hat" not in msg


def test_unknown_name_lists_the_plugin_form() -> None:
    with pytest.raises(UnknownEstimatorError, match=r"package\.module:factory"):
        injection_family("no-such-estimator")


def test_cli_reports_a_broken_plugin_on_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    _write(tmp_path, "broken_cli", "raise RuntimeError('boom')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    for argv in (
        ["run", "wen-5.1", "-e", "broken_cli:create", "--out", str(tmp_path / "r")],
        ["sweep", "wen-5.1", "-e", "broken_cli:create", "--grid", "seed=1", "--out", str(tmp_path)],
        ["suite", "paper", "--estimators", "broken_cli:create", "--out", str(tmp_path / "s")],
    ):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "broken_cli:create" in err and "RuntimeError: boom" in err


@pytest.mark.slow
def test_the_example_closes_the_loop_through_a_sweep(
    examples_on_path: None, tmp_path: Path
) -> None:
    """The plug-in goes through the whole chain (scenario, node, frames, metrics) and tracks:
    on wen-5.1 with a known initial angle at 100 rpm its error stays within a few degrees."""
    from bench.studies._grid import Plan, run_sweep

    plan = Plan(
        str(EXAMPLES / "flux-known-angle.toml"),
        ("my_estimator:create",),
        grid={"seed": [51]},
        duration=1.0,
    )
    res = run_sweep(plan, tmp_path, workers=1, progress=False, plots=False)
    (rec,) = res.records
    m = rec["metrics"]
    assert "error" not in m and not m["lock_lost"]
    assert m["theta_err_abs_max_deg"] < 3.0
    assert math.isfinite(m["speed_err_max_rpm"])


def test_a_module_in_the_working_folder_is_found(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """As ``python -m`` would: the ``bench`` script heads ``sys.path`` with its own folder."""
    import sys

    _write(tmp_path, "cwd_est", "from my_estimator import create\n")
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", ".")])
    monkeypatch.syspath_prepend(str(EXAMPLES))
    monkeypatch.chdir(tmp_path)
    assert str(tmp_path) not in sys.path
    assert injection_family("cwd_est:create") == "none"
