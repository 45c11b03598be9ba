"""The layers of ``bench/``, ``plant_rt/`` and ``controller/`` (docs/ARCHITECTURE.md):
no import circle, no upward import.

Every import inside ``bench/`` counts, also one inside a function (a lazy
import is still a dependency).  The layers, lowest first, are
:data:`LAYERS`; a module may import its own subpackage and the layers below,
never one above: nothing below the command line imports the command line.
``plant_rt`` and ``controller`` never import each other nor ``bench``, and
inside each the same holds: no import circle, and the package's
``__init__`` (its public names) is imported by none of its own modules (it is
the top layer of the package: a module that needs a sibling imports the
sibling).
"""

from __future__ import annotations

import ast
from collections.abc import Iterable, Mapping
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

#: ``bench``'s layers, lowest first (the first name after ``bench.``).
LAYERS = (
    "_errors",
    "_jsonio",
    "wire",
    "scenarios",
    "nodes",
    "monitor",
    "runs",
    "captures",
    "studies",
    "_api",
    "testing",
    "_pytest_plugin",
    "cli",
    "__main__",
)


def module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def modules(package: str) -> dict[str, Path]:
    return {module_name(p): p for p in sorted((ROOT / package).rglob("*.py"))}


def extensions(package: str) -> set[str]:
    """The package's compiled modules (C, built in place), named by their stubs (``*.pyi``
    without a ``.py`` twin): importing one imports no Python module of the package."""
    return {
        module_name(p)
        for p in sorted((ROOT / package).rglob("*.pyi"))
        if not p.with_suffix(".py").exists()
    }


def imported(path: Path, name: str, known: Iterable[str]) -> set[str]:
    """The modules of ``known`` that the module ``name`` at ``path`` imports (anywhere in it)."""
    known = set(known)
    pkg = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        targets: list[str] = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                base = ".".join([*up, base] if base else up)
            # each name: the module it is, else the module it is taken from (``from bench
            # import _jsonio`` imports bench._jsonio, not the package's public names)
            targets = [f"{base}.{a.name}" for a in node.names]
        for t in targets:
            # the longest known module the target names (a name imported from a module)
            while t and t not in known:
                t = t.rpartition(".")[0]
            if t and t != name:
                out.add(t)
    return out


def graph(package: str) -> dict[str, set[str]]:
    mods = modules(package)
    known = set(mods) | extensions(package)
    return {n: imported(p, n, known) for n, p in mods.items()}


def cycles(g: Mapping[str, Iterable[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in g.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(g):
        if v not in index:
            visit(v)
    return out


def layer(name: str) -> int:
    parts = name.split(".")
    if len(parts) == 1:  # bench/__init__.py: the public names, imported on first use
        return len(LAYERS)
    head = parts[1]
    if head not in LAYERS:
        raise AssertionError(f"{name}: not in a layer of LAYERS; add its subpackage there")
    return LAYERS.index(head)


def upward(g: Mapping[str, Iterable[str]]) -> list[str]:
    """Imports of a higher layer than the importer's."""
    return sorted(
        f"{src} imports {dst}" for src, dsts in g.items() for dst in dsts if layer(dst) > layer(src)
    )


# -- the checks themselves can fail ------------------------------------------


def test_the_cycle_finder_finds_a_circle_and_nothing_else() -> None:
    g = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert cycles(g) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_an_upward_import_is_found() -> None:
    g = {"bench.wire._codec": {"bench.cli"}, "bench.cli.run": {"bench.wire._codec"}}
    assert upward(g) == ["bench.wire._codec imports bench.cli"]


def test_a_lazy_import_counts(tmp_path: Path) -> None:
    f = tmp_path / "m.py"
    f.write_text("def f():\n    from bench.cli import main\n    return main\n")
    assert imported(f, "bench.runs.m", {"bench.cli", "bench.runs.m"}) == {"bench.cli"}


# -- the project's own tree --------------------------------------------------


def test_bench_has_no_import_circle() -> None:
    assert cycles(graph("bench")) == []


def test_the_pure_packages_have_no_import_circle() -> None:
    """``controller`` holds its compiled core by composition (``Controller._core``) as the
    plant does (``Plant._core``): no module of either package imports one that imports it
    back.  The packages' ``__init__`` re-exports are left out: a submodule imports its
    siblings, never the package."""
    for package in ("controller", "plant_rt"):
        g = graph(package)
        assert len(g) > 5, f"{package}'s modules were not found"
        g = {n: {d for d in deps if d != package} for n, deps in g.items() if n != package}
        assert cycles(g) == [], package


def test_no_layer_imports_a_layer_above_it() -> None:
    assert upward(graph("bench")) == []


def test_nothing_below_the_command_line_imports_it() -> None:
    g = graph("bench")
    below = [s for s in g if layer(s) < LAYERS.index("cli")]
    assert below, "the layers were not found"
    assert [s for s in below if any(d.startswith("bench.cli") for d in g[s])] == []


def test_every_bench_module_is_in_a_layer() -> None:
    for name in modules("bench"):
        layer(name)


#: Import circles known and being removed, each named with why it is there, so that
#: the test guards every other module now.  Delete an entry once its circle is
#: gone: the test then fails if it comes back.  (None today: the controller's
#: ``_controller``/``_compiled``/``_engine`` circle ended with the core held by
#: composition.)
KNOWN_CIRCLES: dict[str, list[list[str]]] = {}


@pytest.mark.parametrize("package", ["plant_rt", "controller"])
def test_pure_packages_have_no_import_circle_but_the_known_ones(package: str) -> None:
    found = cycles(graph(package))
    known = KNOWN_CIRCLES.get(package, [])
    # a known circle that grew (a module joined it) is a new circle
    assert [c for c in found if c not in known] == []


@pytest.mark.parametrize("package", ["plant_rt", "controller"])
def test_no_module_of_a_pure_package_imports_its_own_init(package: str) -> None:
    g = graph(package)
    assert len(g) > 3, "the package's modules were not found"
    assert sorted(s for s, dsts in g.items() if s != package and package in dsts) == []


def test_the_pure_packages_import_no_side_effect_library() -> None:
    """Neither pure package imports python-can, cantools or any ``bench`` module
    (anywhere in a module, a lazy import included)."""
    for package in ("plant_rt", "controller"):
        for name, path in modules(package).items():
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                heads: list[str] = []
                if isinstance(node, ast.Import):
                    heads = [a.name.split(".")[0] for a in node.names]
                elif isinstance(node, ast.ImportFrom) and not node.level:
                    heads = [(node.module or "").split(".")[0]]
                bad = {"can", "cantools", "bench"} & set(heads)
                assert not bad, f"{name} imports {sorted(bad)}"


def test_plant_and_controller_stay_pure() -> None:
    for pure, other in (("plant_rt", "controller"), ("controller", "plant_rt")):
        for name, path in modules(pure).items():
            text = path.read_text(encoding="utf-8")
            for forbidden in (other, "bench", "can"):
                assert f"import {forbidden}\n" not in text, f"{name} imports {forbidden}"
                assert f"from {forbidden} " not in text and f"from {forbidden}." not in text, (
                    f"{name} imports {forbidden}"
                )


def test_every_subcommand_module_is_registered_and_registers_itself() -> None:
    import importlib

    from bench.cli import SUBCOMMANDS, build_parser

    on_disk = sorted(p.stem for p in (ROOT / "bench" / "cli").glob("*.py") if p.stem[0] != "_")
    assert sorted(SUBCOMMANDS) == on_disk
    for name in SUBCOMMANDS:
        assert callable(importlib.import_module(f"bench.cli.{name}").register)
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    assert set(SUBCOMMANDS) <= set(sub.choices)  # type: ignore[arg-type]
