"""One registry entry per estimator (``controller.EstimatorSpec``): what reads it, and plug-ins
that declare their options the same way."""

from __future__ import annotations

import ast
import dataclasses
import json
import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from bench._errors import ScenarioError
from bench.cli import main
from bench.scenarios import _schema
from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import build_controller, motor_model
from controller import (
    EstimatorPluginError,
    EstimatorSpec,
    estimator_spec,
    make_estimator,
    option_field,
)
from controller import _registry as reg
from controller._engine import _KINDS
from plant_rt import preset
from tests.oracle.estimators import oracle_estimator

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "docs" / "examples"


@dataclass(frozen=True)
class ToyOptions:
    """Options of the toy estimator.

    Parameters
    ----------
    k_toy : float
        A gain of the toy (rad/s), at most 50.
    depth : int
        How deep it looks (PWM periods).
    """

    k_toy: float = option_field(7.0, positive=True, maximum=50.0)
    depth: int = option_field(3, kind="int", minimum=1)


def _toy(motor: Any, T_s: float, **options: Any) -> Any:
    from my_estimator import create as flux

    _toy.received = dict(options)  # type: ignore[attr-defined]
    return flux(motor, T_s)


@pytest.fixture
def toy_spec(monkeypatch: pytest.MonkeyPatch) -> Iterator[EstimatorSpec]:
    """A new estimator added to the registry, and nothing else changed."""
    monkeypatch.syspath_prepend(str(EXAMPLES))
    spec = EstimatorSpec("toy-flux", _toy, "none", ToyOptions, summary="a toy flux estimator")
    monkeypatch.setitem(reg.SPECS, spec.name, spec)
    _schema.shipped_options.cache_clear()
    _schema.estimator_option_keys.cache_clear()
    yield spec
    monkeypatch.undo()
    _schema.shipped_options.cache_clear()
    _schema.estimator_option_keys.cache_clear()


def test_a_new_spec_appears_in_the_schema_and_bench_list(
    toy_spec: EstimatorSpec, capsys: pytest.CaptureFixture[str]
) -> None:
    """One registry entry: docs/SCENARIOS.md gets its options table (unit, default, range and
    meaning from the options dataclass), ``bench list`` its line and JSON entry."""
    from bench.scenarios._reference import render

    doc = render()
    section = doc.split("### toy-flux\n", 1)[1].split("\n### ", 1)[0]
    assert "| `k_toy` | rad/s | 7 | > 0 <= 50 | A gain of the toy (rad/s), at most 50. |" in section
    assert "| `depth` | PWM periods | 3 | integer >= 1 |" in section
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if ln.strip().startswith("toy-flux"))
    assert line.split() == ["toy-flux", "none", "a", "toy", "flux", "estimator"]
    assert main(["list", "--json"]) == 0
    cat = json.loads(capsys.readouterr().out)
    assert cat["estimators"]["toy-flux"] == "none"
    assert cat["estimator_specs"]["toy-flux"]["options"] == ["k_toy", "depth"]


def test_a_new_specs_options_arrive_checked(toy_spec: EstimatorSpec, tmp_path: Path) -> None:
    """A scenario may set the new estimator's options (values in their type), it receives
    exactly them, and a value out of the declared range is one line naming file and key."""
    f = tmp_path / "s.toml"
    f.write_text(
        'extends = "wen-5.1"\nknown_initial_angle = true\nestimator = "toy-flux"\n'
        "[estimator_options]\nk_toy = 9\nV_h = 40.0\n"
    )
    scn = load_scenario(str(f))
    build_controller(scn, "toy-flux", "python")
    assert _toy.received == {"k_toy": 9.0}  # type: ignore[attr-defined]
    assert isinstance(_toy.received["k_toy"], float)  # type: ignore[attr-defined]
    f.write_text(f.read_text().replace("k_toy = 9", "k_toy = 51.0"))
    with pytest.raises(ScenarioError) as e:
        load_scenario(str(f))
    assert str(e.value) == f"{f}: field 'estimator_options.k_toy': must be <= 50.0, got 51.0"


def test_an_option_out_of_range_is_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A shipped option out of its declared range (``M >= 1``) and an amplitude above the
    inverter's linear limit (its ``limit``): ``bench run`` exits 2 with one line."""
    f = tmp_path / "s.toml"
    for body, why in (
        ("M = 0", "field 'estimator_options.M': must be >= 1, got 0"),
        ("U_h = 400.0", "field 'estimator_options.U_h': injection amplitude 400 V is above"),
    ):
        f.write_text(f'extends = "xue-fig13"\n[estimator_options]\n{body}\n')
        assert main(["run", str(f), "--out", str(tmp_path / "r")]) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and why in err and str(f) in err
        assert not (tmp_path / "r").exists()


PLUGIN_SPEC = '''
from dataclasses import dataclass
from controller import EstimatorSpec, option_field
from my_estimator import create as flux

RECEIVED = {{}}


@dataclass(frozen=True)
class Options:
    """Parameters
    ----------
    alpha_o : float
        PLL bandwidth (rad/s).
    mode : str
        How it starts.
    """

    alpha_o: float = option_field(60.0, positive=True)
    mode: str = option_field("cold", choices=("cold", "warm"))


def create(motor, T_s, **options):
    RECEIVED.clear()
    RECEIVED.update(options)
    return flux(motor, T_s)


SPEC = EstimatorSpec("mine", create, "none", Options{extra})
'''


def test_a_plugins_spec_declares_its_options_as_a_shipped_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``package.module:SPEC``: its options dataclass is read as the shipped ones' are (unit
    from the docstring, checks from option_field), and the options it declares arrive."""
    import importlib

    (tmp_path / "plug_spec.py").write_text(PLUGIN_SPEC.format(extra=""))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.syspath_prepend(str(EXAMPLES))
    name = "plug_spec:SPEC"
    s = estimator_spec(name)
    assert (s.name, s.family, s.needs_truth, s.compiled_kind) == (name, "none", False, None)
    decl = s.declared()
    assert decl is not None and decl["alpha_o"].unit == "rad/s" and decl["alpha_o"].positive
    assert decl["mode"].range_text() == "cold, warm"
    f = tmp_path / "s.toml"
    f.write_text(
        f'extends = "wen-5.1"\nknown_initial_angle = true\nestimator = "{name}"\n'
        '[estimator_options]\nalpha_o = 80\nmode = "warm"\nV_h = 40.0\n'
    )
    scn = load_scenario(str(f))
    build_controller(scn, name, "python")
    assert importlib.import_module("plug_spec").RECEIVED == {"alpha_o": 80.0, "mode": "warm"}
    f.write_text(f.read_text().replace('"warm"', '"hot"'))
    with pytest.raises(ScenarioError) as e:
        load_scenario(str(f))
    msg = str(e.value)
    assert msg.startswith(f"{f}: field 'estimator_options.mode': expected 'cold' or 'warm'")
    assert name in msg and "\n" not in msg
    # the API checks the same declaration
    with pytest.raises(EstimatorPluginError, match="option 'alpha_o': must be > 0"):
        make_estimator(name, motor_model(preset("wen2023")), 1e-4, alpha_o=-1.0)


@pytest.mark.parametrize(
    ("extra", "why"),
    [
        (", needs_truth=True", "only the built-in sensored baseline reads the truth"),
        (", compiled_kind=1", "a plug-in runs in Python"),
    ],
)
def test_a_plugin_spec_cannot_read_truth_or_claim_a_compiled_kind(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, extra: str, why: str
) -> None:
    mod = f"plug_bad{len(extra)}"
    (tmp_path / f"{mod}.py").write_text(PLUGIN_SPEC.format(extra=extra))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.syspath_prepend(str(EXAMPLES))
    with pytest.raises(EstimatorPluginError) as e:
        estimator_spec(f"{mod}:SPEC")
    assert why in str(e.value) and "\n" not in str(e.value)


def test_a_plugin_declared_by_a_mapping_of_options_is_a_dataclass_too(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The older declaration (``factory.options``, names to ``controller.Option``) still works
    and gives the same spec form as the example's dataclass: a dataclass whose fields are
    the options, with the same checks."""
    (tmp_path / "plug_map.py").write_text(
        "import math\nfrom controller import Option\nfrom my_estimator import create as flux\n"
        "def create(motor, T_s, **options):\n    return flux(motor, T_s, **options)\n"
        "create.options = {'alpha_o': Option(2 * math.pi * 20, 'rad/s', 'PLL bandwidth.', "
        "positive=True), 'w_c': Option(20.0, 'rad/s', 'Corner.', minimum=0.0)}\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.syspath_prepend(str(EXAMPLES))
    by_map, by_class = estimator_spec("plug_map:create"), estimator_spec("my_estimator:create")
    for s in (by_map, by_class):
        assert s.options is not None and dataclasses.is_dataclass(s.options)
        assert [f.name for f in dataclasses.fields(s.options)] == ["alpha_o", "w_c"]
        decl = s.declared()
        assert decl is not None and decl["w_c"].minimum == 0.0 and decl["w_c"].unit == "rad/s"
        assert decl["alpha_o"].positive and decl["alpha_o"].default == pytest.approx(40 * math.pi)
    with pytest.raises(EstimatorPluginError, match=r"option 'w_c': must be >= 0\.0"):
        make_estimator("plug_map:create", motor_model(preset("wen2023")), 1e-4, w_c=-1.0)


def test_the_shipped_specs_hold_what_the_bench_reads() -> None:
    """Exactly one estimator reads the truth, and it has no injection; the compiled kinds are
    the specs'; every spec's options are a dataclass the factory takes whole; what a factory
    builds is its spec's kind in the core (its design: the protocol's attributes, no
    per-period methods, those are the core's; its oracle meets the whole protocol)."""
    specs = reg.SPECS
    truth = [n for n, s in specs.items() if s.needs_truth]
    assert len(truth) == 1 and specs[truth[0]].family == "none"
    assert {n: s.compiled_kind for n, s in specs.items() if s.compiled_kind} == _KINDS
    motor = motor_model(preset("wen2023"))
    for name, s in specs.items():
        assert s.family in reg.FAMILIES and s.summary
        assert s.options is not None and dataclasses.is_dataclass(s.options)
        defaults = {k: o.default for k, o in (s.declared() or {}).items()}
        if s.family == "square":  # Xue's estimators run at 1 kHz
            est = s.factory(motor, 1e-3, **defaults)
        else:
            est = s.factory(motor, 1e-4, **defaults)
        assert reg.shipped_kind(est) == s.compiled_kind, name
        if s.compiled_kind is None:  # not in the core yet: its Python period runs, external
            assert not reg.missing_members(est), name
        else:  # the core's period, the oracle's in the tests
            assert reg.missing_members(est) == ["update()", "injection()"], name
            assert not reg.missing_members(oracle_estimator(est)), name
        with pytest.raises(TypeError):
            s.factory(motor, 1e-4, no_such_option=1.0)
    assert set(reg.SPECS["hybrid-tt-dq"].declared() or {}) > set(
        reg.SPECS["tt-dq"].declared() or {}
    )


def _name_tests(path: Path, names: set[str], prefixes: set[str]) -> list[str]:
    """``x == "name"``-like comparisons and ``x.startswith("prefix")`` calls in ``path``."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Compare):
            for c in [node.left, *node.comparators]:
                consts = c.elts if isinstance(c, ast.Tuple | ast.List | ast.Set) else [c]
                for k in consts:
                    if isinstance(k, ast.Constant) and k.value in names:
                        out.append(f"{path.relative_to(ROOT)}:{node.lineno}: {k.value!r}")
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr in ("startswith", "endswith")
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and node.args[0].value in prefixes
        ):
            out.append(f"{path.relative_to(ROOT)}:{node.lineno}: {node.args[0].value!r}")
    return out


def test_no_estimator_name_is_tested_as_a_string() -> None:
    """The code reads the spec (needs_truth, family, speed_band, proposed_in), never compares
    an estimator's name; a name is only a key to its spec or a choice of what to run."""
    names = set(reg.ESTIMATOR_NAMES)
    prefixes = {part for n in names for part in n.split("-")} | {f"{p}-" for p in names}
    found = [
        hit
        for pkg in ("bench", "controller", "plant_rt")
        for path in sorted((ROOT / pkg).rglob("*.py"))
        for hit in _name_tests(path, names, prefixes - {"dq", "ab", "wave"})
    ]
    assert found == []


def test_a_plugin_run_with_estimator_receives_the_options_of_a_file_that_does_not_name_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``bench run FILE -e PLUGIN`` (and ``bench sweep``): the plug-in's declared options in a
    file that names only shipped estimators arrive, checked; the effective scenario the nodes
    read names it, so they accept them too.  Without ``--estimator`` the key stays one line
    of error."""
    import importlib

    from bench.scenarios._dotted import scenario_table, scenario_with
    from bench.scenarios._schema import write_effective

    (tmp_path / "plug_cli.py").write_text(PLUGIN_SPEC.format(extra=""))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.syspath_prepend(str(EXAMPLES))
    name = "plug_cli:SPEC"
    f = tmp_path / "s.toml"
    f.write_text(
        'extends = "wen-5.1"\nknown_initial_angle = true\n[estimator_options]\nmode = "warm"\n'
    )
    with pytest.raises(ScenarioError, match="or in a run of it with --estimator"):
        load_scenario(str(f))
    scn = load_scenario(str(f), (name,))
    assert scn.estimators[-1] == name and scn.estimator_options["mode"] == "warm"
    again = load_scenario(str(write_effective(scn, tmp_path / "scenario.json")))
    build_controller(again, name, "python")
    assert importlib.import_module("plug_cli").RECEIVED == {"mode": "warm"}
    # bench sweep -e PLUGIN --grid estimator_options.mode=...: each point's scenario too
    point = scenario_with(scenario_table(str(f)), {"estimator_options.mode": "cold"}, None, (name,))
    assert point.estimator_options["mode"] == "cold" and name in point.estimators
    with pytest.raises(ScenarioError, match=r"estimator_options\.mode.: unknown key"):
        scenario_with(scenario_table(str(f)), {"estimator_options.mode": "cold"})
    f.write_text(f.read_text().replace('"warm"', '"hot"'))
    with pytest.raises(ScenarioError) as e:
        load_scenario(str(f), (name,))
    assert str(e.value) == (
        f"{f}: field 'estimator_options.mode': expected 'cold' or 'warm', got 'hot' "
        f"(an option of {name})"
    )


def test_the_controller_node_takes_the_truth_when_the_spec_says_so(
    toy_spec: EstimatorSpec, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The node reads ``needs_truth`` from the spec, not the name: the new estimator gets the
    truth once its spec says it needs it, and not before."""
    from bench.nodes._loops import make_controller_node
    from bench.wire._codec import Codec

    scn = load_scenario("wen-5.1")
    codec = Codec()
    assert not make_controller_node(scn, "toy-flux", codec).needs_truth
    monkeypatch.setitem(reg.SPECS, "toy-flux", dataclasses.replace(toy_spec, needs_truth=True))
    assert make_controller_node(scn, "toy-flux", codec).needs_truth


@pytest.mark.parametrize("command", ["run", "rerun"])
def test_the_estimator_help_lists_the_registry(
    command: str, toy_spec: EstimatorSpec, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``--estimator``'s help is the registry's list: a new entry appears in it with no edit
    of the command line (the help once named six of the ten estimators)."""
    import argparse

    from bench.cli import _common

    monkeypatch.setitem(reg.SPECS, "toy-flux", toy_spec)
    monkeypatch.setattr(reg, "ESTIMATOR_NAMES", tuple(reg.SPECS))
    monkeypatch.setattr("controller.ESTIMATOR_NAMES", tuple(reg.SPECS))
    text = _common.estimator_help("required")
    assert all(name in text for name in reg.SPECS) and "toy-flux" in text
    module = __import__(f"bench.cli.{command}", fromlist=["register"])
    parser = argparse.ArgumentParser()
    subs = parser.add_subparsers()
    module.register(subs)
    sub = subs.choices[command]
    helps = [a.help or "" for a in sub._actions if "--estimator" in a.option_strings]
    assert helps and "toy-flux" in helps[0]
