"""A scenario with single keys changed, named by their dotted TOML path.

``controller_model.L_q = 1.2`` sets ``L_q`` in the scenario's
``[controller_model]`` table; ``seed = 3`` sets a top-level key.  The keys
are the scenario file's own (``bench/scenarios/_schema.py``), so a sweep of
a key means the same as editing the file, and every changed scenario is
validated again by :func:`~bench.scenarios._schema.parse_scenario` (a wrong
key or value is one line naming it).  A scenario file can do the same with
``extends = "wen-5.1"`` and the keys it changes.
"""

from __future__ import annotations

import copy
import json
import tomllib
from collections.abc import Mapping
from typing import Any

from bench._errors import ScenarioError
from bench.scenarios._schema import Scenario, _resolved_toml, parse_scenario, scenario_path


def scenario_table(name_or_path: str) -> tuple[dict[str, Any], str]:
    """The TOML table of a shipped scenario or a file (``extends`` merged), and its source."""
    path = scenario_path(name_or_path)
    if path.suffix == ".json":
        d = json.loads(path.read_text(encoding="utf-8"))
        src = str(d.get("source", path))
        return {k: v for k, v in d.items() if v is not None and k != "source"}, src
    src = name_or_path if not path.exists() or name_or_path == path.stem else str(path)
    table = _resolved_toml(path, src, ())
    table.setdefault("name", path.stem)
    return table, src


def parse_value(text: str) -> Any:
    """A command-line value as TOML reads it (``1e-6``, ``12``, ``true``), else the text."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def split_values(text: str) -> list[str]:
    """``V1,V2,...`` split at the commas outside brackets and quotes (a value may be a list)."""
    out: list[str] = []
    cur: list[str] = []
    depth, quote = 0, ""
    for ch in text:
        if quote:
            quote = "" if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            out.append("".join(cur).strip())
            cur = []
            continue
        cur.append(ch)
    out.append("".join(cur).strip())
    return [v for v in out if v]


def set_key(table: dict[str, Any], key: str, value: Any) -> None:
    """Set the dotted ``key`` of a scenario table in place."""
    *tables, leaf = key.split(".")
    if not leaf or any(not t for t in tables):
        raise ScenarioError(f"key {key!r}: expected a dotted scenario key such as inverter.t_dead")
    node = table
    for t in tables:
        sub = node.setdefault(t, {})
        if not isinstance(sub, dict):
            raise ScenarioError(f"key {key!r}: {t!r} is a value, not a table")
        node = sub
    node[leaf] = value


def scenario_with(
    base: tuple[dict[str, Any], str],
    changes: Mapping[str, Any],
    name: str | None = None,
    run_with: tuple[str, ...] = (),
) -> Scenario:
    """The scenario of ``base`` (from :func:`scenario_table`) with ``changes`` applied;
    ``run_with``: the estimators it is run with (``parse_scenario``'s ``also``)."""
    table, src = base
    t = copy.deepcopy(table)
    for k, v in changes.items():
        set_key(t, k, v)
    if name is not None:
        t["name"] = name
    what = ", ".join(f"{k}={v}" for k, v in changes.items())
    return parse_scenario(t, f"{src} ({what})" if what else src, run_with)
