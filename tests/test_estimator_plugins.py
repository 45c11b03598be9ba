"""Estimator plug-ins: ``package.module:factory`` and the entry-point group, checked on load."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from bench._errors import ScenarioError
from bench.cli import main
from bench.scenarios._setup import motor_model
from controller import EstimatorPluginError, UnknownEstimatorError, make_estimator
from controller._registry import ENTRY_POINT_GROUP, SPECS, entry_point_names, injection_family
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
    est = make_estimator("my_estimator:create", m, T_S, alpha_o=100.0)
    # alpha_o is an option it declares, and sets the PLL's double pole
    assert est.gains()["k_i"] == pytest.approx(1e4)
    # V_h is not: a run leaves it out (hand_over); given to the factory it is one line
    from controller._registry import hand_over

    assert hand_over("my_estimator:create", {"V_h": 50.0, "w_c": 10.0}) == ({"w_c": 10.0}, ["V_h"])
    with pytest.raises(EstimatorPluginError, match="unknown option 'V_h'"):
        make_estimator("my_estimator:create", m, T_S, V_h=50.0)
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
def test_the_example_is_stable_over_the_whole_scenario(
    examples_on_path: None, tmp_path: Path
) -> None:
    """The plug-in goes through the whole chain (scenario, node, frames, metrics) over the
    whole of flux-known-angle.toml (4 s): the speed loop designed with the example's speed
    response keeps it stable (without it a 7.5 Hz oscillation grew to -60/+250 rpm by 4 s:
    |dtheta| 20 deg, speed error 165 rpm). Measured: |dtheta| <= 0.32 deg, speed error
    0.97 rpm, tracking error 3.3 rpm (the end of the ramp at the scoring start)."""
    from bench.scenarios._schema import load_scenario
    from bench.studies._grid import Plan, run_sweep

    scenario = str(EXAMPLES / "flux-known-angle.toml")
    plan = Plan(scenario, ("my_estimator:create",), grid={"seed": [51]})
    res = run_sweep(plan, tmp_path, workers=1, progress=False, plots=False)
    (rec,) = res.records
    m = rec["metrics"]
    assert "error" not in m and not m["lock_lost"]
    assert m["sim_s"] == pytest.approx(load_scenario(scenario).duration, abs=1e-3)
    assert m["theta_err_abs_max_deg"] < 1.0
    assert m["speed_err_max_rpm"] < 5.0
    assert m["speed_track_err_max_rpm"] < 10.0


def test_the_examples_speed_loop_is_designed_with_its_speed_response(
    examples_on_path: None,
) -> None:
    """The controller lowers the speed loop's bandwidth for the PLL's lag to the designed
    phase margin (30 deg); the loop designed for an exact speed keeps less than 1 deg."""
    from bench.scenarios._schema import load_scenario
    from bench.scenarios._setup import build_controller
    from controller._controller import SPEED_PM_MIN_DEG, speed_loop_margin

    c = build_controller(
        load_scenario(str(EXAMPLES / "flux-known-angle.toml")), "my_estimator:create"
    )
    g = c.gains()
    assert g["speed_pm_deg"] == pytest.approx(SPEED_PM_MIN_DEG, abs=0.1)
    assert g["alpha_s"] < 2 * math.pi * 5.0 / 2
    target = 2 * math.pi * 5.0
    pm_exact = speed_loop_margin(
        target,
        g["alpha_c"],
        4 * target,
        g["T_s"],
        c.estimator.speed_response,  # type: ignore[attr-defined]
    )[0]
    assert pm_exact < 5.0  # 0.8 deg; the flux observer's own lag takes the rest


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


# -- a plug-in that wraps a shipped estimator runs as it does --------------------------------

WRAP = """
from controller import make_estimator, declared_options


def create(motor, T_s, **options):
    return make_estimator("tt-dq", motor, T_s, **options)
{extra}
"""


def _frames(scn: object, estimator: str) -> list[tuple[int, bytes]]:
    from bench.nodes._loops import run_inprocess
    from bench.wire._codec import Codec

    return [(m.arbitration_id, bytes(m.data)) for m in run_inprocess(scn, estimator, Codec())]  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("module", "extra", "options"),
    [
        # the module: no family, no declaration (it receives every option, **options):
        # the estimator says it is rotating
        ("wrap_bare", "", "V_h = 40.0"),
        # family and options declared as the shipped estimator's: it receives tt-dq's alone
        (
            "wrap_decl",
            'create.injection_family = "rotating"\ncreate.options = declared_options("tt-dq")',
            "V_h = 40.0\nU_h = 25.0",
        ),
    ],
)
def test_a_plugin_wrapping_tt_dq_runs_bit_for_bit_like_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, module: str, extra: str, options: str
) -> None:
    """wen-5.1 (HF start-up from an unknown angle, then the speed ramp) with V_h set: every
    frame of the run, telemetry included, equals tt-dq's, and so do the designed gains."""
    from bench.scenarios._schema import load_scenario
    from bench.scenarios._setup import build_controller

    _write(tmp_path, module, WRAP.format(extra=extra))
    monkeypatch.syspath_prepend(str(tmp_path))
    f = tmp_path / "both.toml"
    f.write_text(
        'extends = "wen-5.1"\nduration = 0.45\nscore_from_s = 0.4\n'
        f"[estimator_options]\n{options}\n"
    )
    scn = load_scenario(str(f))
    name = f"{module}:create"
    shipped, wrapped = build_controller(scn, "tt-dq"), build_controller(scn, name)
    assert wrapped.family == "rotating" and wrapped.gains() == shipped.gains()
    # it runs as tt-dq's kind in the core, not as a Python estimator
    assert wrapped._core.kind == shipped._core.kind == SPECS["tt-dq"].compiled_kind
    assert not wrapped.external_estimator
    assert wrapped.gains()["estimator.V_h"] == 40.0
    a, b = _frames(scn, "tt-dq"), _frames(scn, name)
    assert len(a) == len(b) > 4 * 4500
    assert a == b


def test_a_factory_whose_family_contradicts_its_estimator_is_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _write(tmp_path, "wrap_none", WRAP.format(extra='create.injection_family = "none"'))
    monkeypatch.syspath_prepend(str(tmp_path))
    from bench.scenarios._schema import load_scenario
    from bench.scenarios._setup import build_controller

    with pytest.raises(EstimatorPluginError) as e:
        build_controller(load_scenario("wen-5.1"), "wrap_none:create")
    msg = str(e.value)
    assert "\n" not in msg and "wrap_none:create" in msg
    assert "declares injection_family 'none'" in msg and "TTDQEstimator is a 'rotating'" in msg


# -- a plug-in built on a shipped estimator brings its own period, or is refused --------------

OWN_PERIOD = """
from controller import make_estimator
from controller._tt_dq import TTDQEstimator


class Held(TTDQEstimator):
    \"\"\"tt-dq's design with a period of its own: the angle it was reset to, held.\"\"\"

    calls = 0

    def update(self, x):
        self.calls += 1
        self.err = 0.25
        self.i_alpha_f = x.i_alpha
        self.i_beta_f = x.i_beta

    def injection(self):
        return (3.0, -2.0)


def create(motor, T_s, **options):
    e = make_estimator("tt-dq", motor, T_s, **options)
    e.__class__ = Held
    return e
"""


def test_a_plugin_subclassing_a_shipped_estimator_runs_its_own_period(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A subclass of tt-dq that overrides its per-period methods is an external Python
    estimator: the core calls its ``update`` every period (never tt-dq's kind, which would
    ignore them) and adds its ``injection``; the oracle's step gives the same bits."""
    from bench.scenarios._schema import load_scenario
    from bench.scenarios._setup import build_controller, controller_pars
    from controller import Measurement
    from controller._engine import KIND_EXTERNAL
    from tests.oracle import OracleController

    _write(tmp_path, "held_est", OWN_PERIOD)
    monkeypatch.syspath_prepend(str(tmp_path))
    scn = load_scenario("wen-5.1")
    name = "held_est:create"
    ctrl = build_controller(scn, name)
    ref = OracleController(controller_pars(scn, name))
    assert ctrl._core.kind == KIND_EXTERNAL and ctrl.external_estimator
    n = 60
    outs = []
    for c in (ctrl, ref):
        c.set_enable(True)
        outs.append([c.step(Measurement(k, 0.5, -0.2, -0.3, 300.0, None, None)) for k in range(n)])
    assert outs[0] == outs[1]
    assert ctrl.estimator.calls == ref.estimator.calls == n  # type: ignore[attr-defined]
    assert ctrl.injection() == (3.0, -2.0)
    assert {o.err for o in outs[0][-10:]} == {0.25}


@pytest.mark.parametrize(
    ("module", "body", "why"),
    [
        # a subclass with no period of its own: tt-dq's is the core's alone
        (
            "bare_est",
            "from controller._tt_dq import TTDQEstimator\n"
            "class Bare(TTDQEstimator):\n    pass\n"
            "def create(motor, T_s, **options):\n"
            "    e = make_estimator('tt-dq', motor, T_s, **options)\n"
            "    e.__class__ = Bare\n    return e\n",
            "Bare is built on a shipped estimator, whose period runs only in the core, and has "
            "no per-period methods of its own (missing: update(), injection())",
        ),
        # the sensored baseline reads the plant's truth, which a plug-in never receives
        (
            "truth_est",
            "def create(motor, T_s, **options):\n"
            "    return make_estimator('sensored', motor, T_s)\n",
            "it returns the SensoredEstimator, which reads the plant's truth",
        ),
    ],
)
def test_a_plugin_a_shipped_estimator_cannot_run_is_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, module: str, body: str, why: str
) -> None:
    _write(tmp_path, module, "from controller import make_estimator\n" + body)
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(EstimatorPluginError) as e:
        make_estimator(f"{module}:create", motor_model(preset("wen2023")), T_S)
    msg = str(e.value)
    assert "\n" not in msg and f"{module}:create" in msg and why in msg


# -- a plug-in gets the options it declares ----------------------------------------------------

FAMILY_PLUGIN = """
import dataclasses
from controller import Option
from my_estimator import create as flux

RECEIVED = {{}}


@dataclasses.dataclass(frozen=True)
class Pars:
    \"\"\"Options of the plug-in.

    Parameters
    ----------
    gain : float
        A gain of its own (rad/s).
    \"\"\"

    gain: float = dataclasses.field(default=1.0, metadata={{"positive": True}})


def create(motor, T_s, **options):
    RECEIVED.clear()
    RECEIVED.update(options)
    return flux(motor, T_s)


create.injection_family = "{family}"
create.options = {options}
"""


@pytest.mark.parametrize(
    ("family", "options", "own"),
    [
        ("none", '{"gain": Option(1.0, "rad/s", "A gain.", positive=True)}', {"gain": 3.0}),
        ("rotating", "Pars", {"gain": 3.0}),
        (
            "square",
            '{"gain": Option(1.0, positive=True), "U_h": Option(20.0, "V", positive=True)}',
            {"gain": 3.0, "U_h": 25.0},
        ),
    ],
)
def test_each_familys_plugin_receives_the_options_it_declares(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    family: str,
    options: str,
    own: dict[str, float],
) -> None:
    """A scenario naming the plug-in with its own option, V_h and U_h: the factory gets exactly
    the keys it declares, checked; the rest are left out with the note."""
    import importlib

    from bench.scenarios._schema import load_scenario
    from bench.scenarios._setup import build_controller, check_estimator_fits

    mod = f"fam_{family}"
    _write(tmp_path, mod, FAMILY_PLUGIN.format(family=family, options=options))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.syspath_prepend(str(EXAMPLES))
    name = f"{mod}:create"
    f = tmp_path / "s.toml"
    f.write_text(
        f'extends = "wen-5.1"\nknown_initial_angle = true\nestimators = ["tt-dq", "{name}"]\n'
        "[estimator_options]\nV_h = 40.0\nU_h = 25.0\ngain = 3\n"
    )
    scn = load_scenario(str(f))
    assert scn.estimator_options["gain"] == 3.0 and isinstance(scn.estimator_options["gain"], float)
    build_controller(scn, name)
    assert own == importlib.import_module(mod).RECEIVED
    note = check_estimator_fits(scn, name)
    left = [k for k in ("V_h", "U_h") if k not in own]
    assert (
        note is not None
        and f"leaves out the scenario's estimator options {', '.join(left)}" in note
    )
    # a value its declaration refuses: one line naming the file, the key and the plug-in
    f.write_text(f.read_text().replace("gain = 3", "gain = -1"))
    with pytest.raises(ScenarioError) as e:
        load_scenario(str(f))
    msg = str(e.value)
    assert msg.startswith(f"{f}: field 'estimator_options.gain': must be > 0") and name in msg


def test_an_unknown_option_is_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, examples_on_path: None
) -> None:
    """An option no estimator declares (a plug-in's, in a file that does not name the plug-in,
    or a typo) is one line naming file and key; the API names the plug-in and what it declares."""
    from bench.scenarios._schema import load_scenario

    _write(tmp_path, "fam_x", FAMILY_PLUGIN.format(family="none", options="Pars"))
    monkeypatch.syspath_prepend(str(tmp_path))
    f = tmp_path / "s.toml"
    f.write_text('extends = "wen-5.1"\n[estimator_options]\ngain = 3.0\n')
    with pytest.raises(ScenarioError) as e:
        load_scenario(str(f))
    msg = str(e.value)
    assert msg.startswith(f"{f}: field 'estimator_options.gain': unknown key") and "\n" not in msg
    assert "names the plug-in in estimator or estimators" in msg
    with pytest.raises(EstimatorPluginError) as e2:
        make_estimator("fam_x:create", motor_model(preset("wen2023")), T_S, gian=3.0)
    msg = str(e2.value)
    assert "\n" not in msg and "unknown option 'gian' (it declares: gain)" in msg


def test_a_malformed_declaration_is_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _write(
        tmp_path, "bad_decl", "def create(m, T_s, **kw):\n    pass\ncreate.options = {'g': 1.0}\n"
    )
    _write(tmp_path, "bad_kw", "from controller import Option\ndef create(m, T_s, a=1.0):\n"
           "    pass\ncreate.options = {'b': Option(1.0)}\n")  # fmt: skip
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(EstimatorPluginError, match=r"option 'g': expected a controller\.Option"):
        injection_family("bad_decl:create")
    with pytest.raises(EstimatorPluginError, match="declares options its factory does not take: b"):
        injection_family("bad_kw:create")


def test_a_plugin_without_a_declaration_receives_what_its_signature_takes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """As docs/ESTIMATORS.md says: ``**options`` receives every option of the scenario (a
    family-none plug-in used to receive none, a rotating one only the rotating keys); named
    keywords receive those named."""
    import importlib

    from bench.scenarios._schema import load_scenario
    from bench.scenarios._setup import build_controller, check_estimator_fits
    from controller._registry import hand_over

    _write(
        tmp_path,
        "und_all",
        "from my_estimator import create as flux\nRECEIVED = {}\n"
        "def create(motor, T_s, **options):\n    RECEIVED.update(options)\n"
        "    return flux(motor, T_s)\n",
    )
    _write(tmp_path, "und_kw", "def create(motor, T_s, alpha_o=1.0):\n    pass\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.syspath_prepend(str(EXAMPLES))
    assert hand_over("und_kw:create", {"V_h": 1.0, "alpha_o": 2.0}) == ({"alpha_o": 2.0}, ["V_h"])
    f = tmp_path / "s.toml"
    f.write_text(
        'extends = "wen-5.1"\nknown_initial_angle = true\n'
        "[estimator_options]\nV_h = 40.0\nU_h = 25.0\n"
    )
    scn = load_scenario(str(f))
    build_controller(scn, "und_all:create")
    assert importlib.import_module("und_all").RECEIVED == {"V_h": 40.0, "U_h": 25.0}
    assert check_estimator_fits(scn, "und_all:create") is None
