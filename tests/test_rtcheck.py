"""``bench rtcheck``: its verdict rule, its output files, and docs/REALTIME.md against its JSON."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import pytest

from bench._errors import BenchError
from bench.cli import main
from bench.studies._rtcheck import (
    DOC_BEGIN,
    DOC_END,
    Latency,
    render_doc_block,
    update_doc,
    verdict,
)

ROOT = Path(__file__).resolve().parent.parent


def lat(p99: float, median: float, c_p99: float, c_med: float) -> Latency:
    return Latency(1000.0, 100, median, p99, p99, p99, 0, True, (), c_med, c_p99)


def test_the_verdict_follows_the_stated_rule() -> None:
    # T = 100 us: p99s within 80 % -> yes; medians within T -> marginal; else no
    assert verdict(100.0, lat(p99=20.0, median=1.0, c_p99=59.0, c_med=30.0)) == "yes"
    assert verdict(100.0, lat(p99=30.0, median=1.0, c_p99=59.0, c_med=30.0)) == "marginal"
    assert verdict(100.0, lat(p99=900.0, median=50.0, c_p99=300.0, c_med=51.0)) == "no"


def test_rtcheck_measures_and_writes_its_json_and_the_doc_block(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    doc = tmp_path / "REALTIME.md"
    doc.write_text(f"# x\n\n{DOC_BEGIN}\nold\n{DOC_END}\n\nafter\n")
    rc = main(
        ["rtcheck", "--seconds", "0.3", "--rate", "1", "--out", str(tmp_path), "--doc", str(doc)]
    )
    assert rc == 0
    res = json.loads((tmp_path / "rtcheck.json").read_text())
    row = res["rates"]["1000"]
    for setting in ("normal", "sched_fifo"):
        r = row[setting]
        assert r["n"] > 100 and r["period_us"] == 1000.0
        assert 0.0 <= r["median"] <= r["p99"] <= r["p999"] <= r["max"]
        assert 0.0 < r["compute_median"] <= r["compute_p99"]
        assert r["verdict"] in ("yes", "marginal", "no", "not granted")
    out = capsys.readouterr().out
    assert "sustained:" in out and "1000 Hz" in out
    text = doc.read_text()
    assert "old" not in text and text.endswith("after\n")
    assert render_doc_block(res) in text


def test_the_committed_doc_is_the_committed_measurement() -> None:
    res = json.loads((ROOT / "docs" / "realtime" / "rtcheck.json").read_text())
    doc = (ROOT / "docs" / "REALTIME.md").read_text()
    assert render_doc_block(res) in doc
    assert update_doc(doc, res) == doc


def _ends_without_result(T_s: float, seconds: float, fifo: bool, q: object) -> None:
    os._exit(3)


def test_a_measuring_process_that_dies_is_one_line_not_a_wait(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The child is waited for while it lives; one that ends without a result is named."""
    import bench.studies._rtcheck as rc

    monkeypatch.setattr(rc, "_measure_wakeups", _ends_without_result)
    t0 = time.monotonic()
    with pytest.raises(BenchError, match=r"ended without a result \(exit status 3\)"):
        rc.wakeup_latency(1e-3, 0.1, fifo=False)
    assert time.monotonic() - t0 < rc.START_LIMIT_S
