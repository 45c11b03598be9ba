"""The reference site (``make docs-site``) builds with warnings as errors.

Its API reference is generated from the docstrings (docs/conf.py,
docs/api/*.rst), so a public name (one of a public module's ``__all__``)
without a docstring, a malformed docstring, or a broken link between the
guides fails the build.  Sphinx, MyST and the theme are the ``docs`` extra
(``pip install -e '.[docs]'``, which ``make`` installs); without them this
is skipped, except in CI, where it must run.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
#: What the docs extra installs (pyproject.toml).
NEEDED = ("sphinx", "myst_parser", "furo")
MISSING = [m for m in NEEDED if importlib.util.find_spec(m) is None]

if MISSING and os.environ.get("CI"):
    pytest.fail(f"CI must build the docs site: {', '.join(MISSING)} not installed", pytrace=False)
pytestmark = pytest.mark.skipif(
    bool(MISSING),
    reason=f"{', '.join(MISSING)} not installed (the docs extra: pip install -e '.[docs]')",
)


def _conf() -> Any:
    spec = importlib.util.spec_from_file_location("docs_conf", DOCS / "conf.py")
    assert spec and spec.loader
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _make_recipe() -> str:
    text = (ROOT / "Makefile").read_text()
    m = re.search(r"^docs-site:[^\n]*\n((?:\t[^\n]*\n)+)", text, re.M)
    assert m, "Makefile: no docs-site target"
    return m.group(1)


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The site built as ``make docs-site`` builds it, into a temporary folder."""
    assert "sphinx-build -W --keep-going" in _make_recipe()
    out = tmp_path_factory.mktemp("site")
    cmd = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html"]
    cmd += ["-d", str(out / "doctrees"), str(DOCS), str(out / "html")]
    r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, f"sphinx-build -W failed:\n{r.stdout[-3000:]}\n{r.stderr[-6000:]}"
    return out / "html"


def _inventory(html: Path) -> set[str]:
    from sphinx.util.inventory import InventoryFile

    with (html / "objects.inv").open("rb") as f:
        inv = InventoryFile.load(f, "", lambda base, uri: uri)
    data = inv.data if hasattr(inv, "data") else inv
    return {name for entries in data.values() for name in entries}


def test_every_public_name_is_in_the_api_reference(site: Path) -> None:
    documented = _inventory(site)
    conf = _conf()
    missing = []
    for name in sorted(conf._public_names()):
        mod, _, attr = name.rpartition(".")
        obj = getattr(importlib.import_module(mod), attr)
        home = f"{getattr(obj, '__module__', mod)}.{getattr(obj, '__qualname__', attr)}"
        if name not in documented and home not in documented:  # bench.BenchError: bench._errors'
            missing.append(name)
    assert not missing, f"public names not in the API reference: {missing}"
    for name in ("bench.run", "bench.Run", "bench.testing.assert_within", "controller.Option"):
        assert name in documented, name
    assert "bench.scenarios._schema.load_scenario" not in documented  # private stays out


def test_the_pytest_options_come_from_the_plugin(site: Path) -> None:
    page = (site / "api" / "testing.html").read_text()
    for option in ("--hil-interface", "--hil-channel", "--hil-engine"):
        assert f'id="cmdoption{option}"' in page or option in page, option
    assert "auto,compiled,python" in page.replace(" ", "")  # --hil-engine's choices


def test_every_guide_is_a_page_of_the_site(site: Path) -> None:
    guides = sorted(p.stem for p in DOCS.glob("*.md") if p.stem != "index")
    assert "TESTING" in guides and "RUNS" in guides
    missing = [g for g in guides if not (site / f"{g}.html").is_file()]
    assert not missing, f"guides not built into the site: {missing}"
    # the page is the guide itself (MyST), not a copy: its first heading is there
    first = next(ln for ln in (DOCS / "RUNS.md").read_text().splitlines() if ln.startswith("# "))
    assert first[2:].split("`")[0].strip() in (site / "RUNS.html").read_text()


def test_a_public_name_without_a_docstring_is_a_warning(caplog: pytest.LogCaptureFixture) -> None:
    conf = _conf()

    App = SimpleNamespace(config=SimpleNamespace(public_names={"bench.run"}))
    lines: list[str] = []
    with caplog.at_level("WARNING"):
        conf._undocumented(App, "function", "bench.run", None, None, lines)
    assert "public name bench.run has no docstring" in caplog.text
    caplog.clear()
    with caplog.at_level("WARNING"):
        conf._undocumented(App, "function", "bench.run", None, None, ["Run a scenario."])
    assert not caplog.text
    # a constant a package imports gets the #: comment of the module that defines it
    data: list[str] = ["int([x]) -> integer"]  # not its type's docstring either
    conf._undocumented(App, "data", "plant_rt.FAULT_NONE", 0, None, data)
    assert data and "no fault" in " ".join(data)


def _build_page(tmp_path: Path, text: str) -> subprocess.CompletedProcess[str]:
    """A one-page site with docs/conf.py (``-c``): what ``-W`` makes of ``text``."""
    src = tmp_path / "src"
    src.mkdir(parents=True)
    (src / "index.md").write_text(text)
    cmd = [sys.executable, "-m", "sphinx", "-W", "-q", "-b", "html", "-c", str(DOCS)]
    cmd += [str(src), str(tmp_path / "html")]
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=120)


def test_a_broken_link_fails_and_a_link_to_a_repository_file_does_not(tmp_path: Path) -> None:
    ok = _build_page(tmp_path / "ok", "# Page\n\nThe DBC: [`dbc/bench.dbc`](dbc/bench.dbc).\n")
    assert ok.returncode == 0, ok.stderr[-3000:]
    bad = _build_page(tmp_path / "bad", "# Page\n\nSee [the guide](NO_SUCH_GUIDE.md).\n")
    assert bad.returncode != 0 and "NO_SUCH_GUIDE" in bad.stderr, bad.stderr[-3000:]
