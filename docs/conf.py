"""Sphinx configuration of the reference site (``make docs-site`` -> docs/_build/html).

The source folder is docs/ itself: the guides (docs/*.md, MyST Markdown)
are the site's pages as they stand, not copies, so their links to one
another are checked by the build; docs/api/*.rst generate the API
reference from the docstrings (autodoc, numpy style through napoleon).
The folders of data and examples beside the guides are not pages.

Built with ``-W`` (tests/test_docs_site.py), so a broken link between
guides, a malformed docstring, or a public name (a module's ``__all__``)
without a docstring fails the build.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

project = "can-hil-bench"
author = "the can-hil-bench contributors"
copyright = "the can-hil-bench contributors, MIT licence"
release = importlib.metadata.version("can-hil-bench")

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "myst_parser",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
# data, examples and reports beside the guides are not pages of the site
exclude_patterns = ["_build", "examples", "faults", "perf", "realtime", "reliability", "results"]

myst_heading_anchors = 3  # the guides link to their sections as GitHub does (#the-papers-...)
myst_enable_extensions = ["colon_fence"]

napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
napoleon_use_ivar = True  # a class's "Attributes" section: fields, not a second entry per attribute
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_typehints_format = "short"
autodoc_default_options = {"members": True, "undoc-members": True, "show-inheritance": True}

html_theme = "furo"
html_title = "can-hil-bench"
html_static_path: list[str] = []


#: The modules whose ``__all__`` is public API: each name needs a docstring.
PUBLIC_MODULES = ("bench", "bench._errors", "bench.testing", "bench._pytest_plugin")
PUBLIC_MODULES += ("controller", "plant_rt")


def _public_names() -> set[str]:
    names = set()
    for mod in PUBLIC_MODULES:
        for name in importlib.import_module(mod).__all__:
            names.add(f"{mod}.{name}")
    return names


_ALL_NAMES = {name.rpartition(".")[2] for name in _public_names()}


def _keep_public(app: Any, what: str, name: str, obj: Any, skip: bool, options: Any) -> bool | None:
    """Every name of a public module's ``__all__`` is documented, its constants too."""
    return False if what == "module" and name in _ALL_NAMES else None


def _doc_comment(name: str) -> list[str]:
    """The ``#:`` comment of a constant a package imports, where its submodule defines it."""
    from sphinx.pycode import ModuleAnalyzer

    package, _, attr = name.rpartition(".")
    obj = getattr(sys.modules[package], attr)
    for modname, mod in sorted(sys.modules.items()):
        if modname.startswith(package + ".") and getattr(mod, attr, None) is obj:
            if not str(getattr(mod, "__file__", "")).endswith(".py"):
                continue  # an extension module (the core's binding) re-exporting the value
            docs = ModuleAnalyzer.for_module(modname).find_attr_docs()
            if ("", attr) in docs:
                return list(docs[("", attr)])
    return []


def _is_own(obj: Any, lines: list[str]) -> bool:
    """Whether a constant's docstring ``lines`` are not the docstring of its type."""
    from sphinx.util.docstrings import prepare_docstring

    own = [line.strip() for line in lines if line.strip()]
    typ = [line.strip() for line in prepare_docstring(type(obj).__doc__ or "") if line.strip()]
    return own != typ


def _undocumented(app: Any, what: str, name: str, obj: Any, options: Any, lines: list[str]) -> None:
    """A public name without a docstring is a warning (an error under ``-W``)."""
    if what == "data":  # its ``#:`` comment, else nothing (not its type's docstring)
        lines[:] = _doc_comment(name) or (lines if _is_own(obj, lines) else [])
    if name in app.config.public_names and not any(line.strip() for line in lines):
        from sphinx.util import logging

        logging.getLogger(__name__).warning("public name %s has no docstring", name)


class _OptionRecorder:
    """A stand-in for pytest's parser and its option group: records ``addoption``."""

    def __init__(self) -> None:
        self.options: list[tuple[tuple[str, ...], dict[str, Any]]] = []

    def getgroup(self, name: str, description: str = "") -> _OptionRecorder:
        return self

    def addoption(self, *names: str, **kw: Any) -> None:
        self.options.append((names, kw))


def _hil_options_directive() -> Any:
    """``.. hil-options::``: the plugin's options from its own ``pytest_addoption``."""
    from docutils.statemachine import StringList
    from sphinx.util.docutils import SphinxDirective

    from bench._pytest_plugin import pytest_addoption

    class HilOptions(SphinxDirective):
        def run(self) -> list[Any]:
            rec = _OptionRecorder()
            pytest_addoption(rec)  # type: ignore[arg-type]
            lines = []
            for names, kw in rec.options:
                value = "{" + ",".join(kw["choices"]) + "}" if "choices" in kw else "VALUE"
                lines += [f".. option:: {', '.join(names)} {value}", ""]
                lines += [f"   {kw.get('help', '')}", ""]
            node = self.parse_text_to_nodes(StringList(lines, "bench._pytest_plugin"))
            return list(node)

    return HilOptions


def _constants_directive() -> Any:
    """``.. public-constants:: controller``: ``autodata`` of each constant of the ``__all__``.

    autodoc's ``automodule`` documents a constant a package imports only if
    the package itself carries its ``#:`` comment; the comment's home is
    where the constant is defined (:func:`_doc_comment` reads it there).
    """
    import inspect

    from docutils.statemachine import StringList
    from sphinx.util.docutils import SphinxDirective

    class PublicConstants(SphinxDirective):
        required_arguments = 1

        def run(self) -> list[Any]:
            mod = importlib.import_module(self.arguments[0])
            lines = []
            for name in mod.__all__:
                obj = getattr(mod, name)
                if not (inspect.isclass(obj) or inspect.isroutine(obj)):
                    lines += [f".. autodata:: {mod.__name__}.{name}", ""]
            return list(self.parse_text_to_nodes(StringList(lines, mod.__name__)))

    return PublicConstants


def _no_protocol_signature(
    app: Any, what: str, name: str, obj: Any, options: Any, signature: str | None, ret: str | None
) -> tuple[str, str | None] | None:
    """A :class:`typing.Protocol` (``controller.Estimator``) is implemented, not called."""
    if what == "class" and signature == "(*args, **kwargs)":
        return "", ret
    return None


def _repository_links() -> Any:
    """Links of the guides to repository files that are not pages: shown as their text.

    A guide links ``../bench/scenarios`` or ``../CONTRIBUTING.md`` for a
    reader of the repository; on the site these are not pages, so the link
    keeps its text and loses its target.  A link to a path that exists
    nowhere is left to MyST, which warns (an error under ``-W``).
    """
    from docutils import nodes
    from sphinx import addnodes
    from sphinx.transforms.post_transforms import SphinxPostTransform

    class RepositoryLinks(SphinxPostTransform):
        default_priority = 5  # before MyST's resolver (9)

        def _in_repository(self, node: Any) -> bool:
            target = str(node["reftarget"])
            here = Path(self.env.doc2path(node.get("refdoc", self.env.docname))).parent
            if node.get("refdomain") == "doc":
                if target in self.env.all_docs:
                    return False
                paths = [Path(self.env.srcdir) / f"{target}.md", Path(f"{target}.md")]
            else:
                paths = [here / target, ROOT / target]
            return any(ROOT in p.resolve().parents and p.resolve().exists() for p in paths)

        def run(self, **kwargs: Any) -> None:
            for node in list(self.document.findall(addnodes.pending_xref)):
                if node.get("reftype") == "myst" and self._in_repository(node):
                    node.replace_self(nodes.inline("", "", *node.children))

    return RepositoryLinks


def setup(app: Any) -> None:
    app.add_post_transform(_repository_links())
    app.add_directive("hil-options", _hil_options_directive())
    app.add_directive("public-constants", _constants_directive())
    app.add_config_value("public_names", set(), "env")
    app.config.public_names = _public_names()
    app.connect("autodoc-process-docstring", _undocumented)
    app.connect("autodoc-skip-member", _keep_public)
    app.connect("autodoc-process-signature", _no_protocol_signature)
