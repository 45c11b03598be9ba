"""metrics.json is strict JSON: an undefined value is null, never NaN."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import pytest

from bench import _jsonio as jsonio
from bench.cli import main


def strict_load(text: str) -> object:
    def refuse(name: str) -> object:
        raise ValueError(f"not strict JSON: {name}")

    return json.loads(text, parse_constant=refuse)


def test_non_finite_values_become_null_at_any_depth() -> None:
    data = {"a": math.nan, "b": [1.0, math.inf, {"c": -math.inf}], "d": (2, math.nan), "e": 1.5}
    text = jsonio.dumps(data, sort_keys=True)
    assert strict_load(text) == {"a": None, "b": [1.0, None, {"c": None}], "d": [2, None], "e": 1.5}
    with pytest.raises(ValueError):
        strict_load(json.dumps(data))  # what the plain writer gives


def test_an_analysed_capture_copied_alone_writes_strict_metrics(tmp_path: Path) -> None:
    run = tmp_path / "run"
    assert (
        main(["run", "xue-fig13", "-e", "sensored", "--duration", "0.3", "--out", str(run), "-q"])
        == 0
    )
    strict_load((run / "metrics.json").read_text())
    lone = tmp_path / "lone"
    lone.mkdir()
    shutil.copy(run / "capture.blf", lone / "capture.blf")
    out = tmp_path / "again"
    argv = ["analyze", str(lone / "capture.blf"), "--scenario", "xue-fig13", "--out", str(out)]
    assert main(argv) == 0
    m = strict_load((out / "metrics.json").read_text())
    assert isinstance(m, dict) and "theta_err_max_deg" in m
