"""docs/SCENARIOS.md is the schema: every key the loader accepts is documented with
its unit, default and range, each documented range is the loader's, and the file
is what ``bench schema`` writes."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import pytest

from bench._errors import ScenarioError
from bench.scenarios import _schema as schema
from bench.scenarios._reference import KEYS, NO_BAD, defaults, estimator_options, render
from bench.scenarios._schema import load_scenario

ROOT = Path(__file__).resolve().parent.parent
MINIMAL = {"preset": "wen2023", "duration": 1.0}


def test_docs_scenarios_md_is_what_bench_schema_writes() -> None:
    assert (ROOT / "docs" / "SCENARIOS.md").read_text(encoding="utf-8") == render(), (
        "docs/SCENARIOS.md is out of date: bench schema --doc docs/SCENARIOS.md"
    )


def test_every_key_the_loader_accepts_is_documented_and_no_other() -> None:
    accepted = {
        "": set(schema._TOP_KEYS),
        "noise": {f.name for f in dataclasses.fields(schema.Noise)},
        "latency": {f.name for f in dataclasses.fields(schema.Latency)},
        "controller_model": set(schema.MODEL_ERROR_KEYS),
        "motor": set(schema.MOTOR_KEYS),
        "inverter": set(schema.INVERTER_KEYS),
        "sensors": set(schema.SENSOR_KEYS),
        "magnetics": set(schema.MAGNETICS_KEYS),
        "controller": set(schema.CONTROLLER_KEYS),
    }
    assert {t: set(k) for t, k in KEYS.items()} == accepted
    for table, keys in KEYS.items():
        for k, key in keys.items():
            assert key.meaning and key.range, (table, k)
    # every [estimator_options] key is some estimator's, and each estimator's are its own
    options = estimator_options()
    assert set().union(*map(set, options.values())) == set(schema.estimator_option_keys())
    assert options["sensored"] == {}
    for rows in options.values():
        for k, (_unit, default, rng, meaning) in rows.items():
            assert default and rng and meaning, k


def _load(tmp_path: Path, data: dict[str, Any]) -> Any:
    f = tmp_path / "s.toml"
    f.write_text(_toml(data))
    return load_scenario(str(f))


def _toml(data: dict[str, Any]) -> str:
    top = [f"{k} = {json.dumps(v)}" for k, v in data.items() if not isinstance(v, dict)]
    tables = [
        f"[{k}]\n" + "\n".join(f"{kk} = {json.dumps(vv)}" for kk, vv in v.items())
        for k, v in data.items()
        if isinstance(v, dict)
    ]
    return "\n".join(top + tables) + "\n"


def test_the_documented_code_defaults_are_what_a_minimal_scenario_gets(tmp_path: Path) -> None:
    scn = _load(tmp_path, MINIMAL)
    code = defaults()
    for k, v in code[""].items():
        got = getattr(scn, k)
        assert got == v, k
    for table, attr in (("latency", "latency"), ("noise", "noise"),
                        ("controller_model", "controller_model")):  # fmt: skip
        for k, v in code[table].items():
            assert getattr(getattr(scn, attr), k) == v, (table, k)


def _bad_cases() -> list[tuple[str, str, Any]]:
    cases = [
        (table, k, key.bad)
        for table, keys in KEYS.items()
        for k, key in keys.items()
        if key.bad is not NO_BAD
    ]
    from bench.scenarios._reference import option_range

    cases += [("estimator_options", k, option_range(k)[1]) for k in schema.estimator_option_keys()]
    return cases


@pytest.mark.parametrize(("table", "key", "bad"), _bad_cases())
def test_each_documented_range_is_the_loaders(
    tmp_path: Path, table: str, key: str, bad: Any
) -> None:
    data: dict[str, Any] = dict(MINIMAL)
    if table:
        data[table] = {key: bad}
    else:
        data[key] = bad
    with pytest.raises(ScenarioError) as info:
        _load(tmp_path, data)
    name = f"'{table}.{key}'" if table else f"'{key}'"
    assert name in str(info.value) or (key == "extends" and "'extends'" in str(info.value))


def test_every_top_level_and_table_key_has_a_refused_example_where_it_has_a_range() -> None:
    free = {("", "estimator_options"), ("", "noise"), ("", "latency"), ("", "controller_model"),
            ("", "motor"), ("", "paper_result"), ("", "inverter"), ("", "sensors"),
            ("", "magnetics"), ("", "controller")}  # fmt: skip
    for table, keys in KEYS.items():
        for k, key in keys.items():
            assert key.bad is not NO_BAD or (table, k) in free, (table, k)
