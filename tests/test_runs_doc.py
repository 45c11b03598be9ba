"""docs/RUNS.md describes every key metrics.json can hold and every file of a run folder."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
DOC = (ROOT / "docs" / "RUNS.md").read_text(encoding="utf-8")


def _documented() -> list[re.Pattern[str]]:
    """The keys of the metrics table, each a pattern (``<a|b|c>`` alternatives)."""
    section = DOC.split("## metrics.json", 1)[1]
    pats = []
    for line in section.splitlines():
        if not line.startswith("| `"):
            continue
        cell = line.split(" | ")[0]
        for key in re.findall(r"`([^`]+)`", cell):
            alt = re.sub(r"<([^>]+)>", lambda m: "(" + m.group(1).replace("\\|", "|") + ")", key)
            pats.append(re.compile(alt + r"\Z"))
    return pats


def _written_keys() -> set[str]:
    """Every key the analysis writes: a real run's, the optional ones of the metrics,
    the per-band ones, and every ``m["..."]`` the run and capture code assigns."""
    from bench.nodes._loops import run_inprocess
    from bench.runs._metrics import BAND_QUANTITIES, BANDS, compute_metrics
    from bench.runs._results import finish_run, run_metadata
    from bench.scenarios._schema import load_scenario
    from bench.wire._codec import Codec

    keys: set[str] = set()
    scn = load_scenario("wen-5.1").with_overrides(duration=0.2)
    codec = Codec()
    frames = run_inprocess(scn, "sensored", codec)
    meta = run_metadata(scn, "sensored", mode="lockstep", transport="in-process", link=False)
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        res = finish_run(frames, codec, scn, Path(d), meta=meta, wall_s=1.0, capture=None,
                         plots=False)  # fmt: skip
    keys |= set(res.metrics)
    n = 2000
    t = np.arange(n) * 1e-3
    w = np.where(t < 0.5, 0.0, 100.0) + 5.0 * np.exp(-np.maximum(t - 0.5, 0) / 0.05)
    table = {"t": t, "theta_e": t, "theta_hat": t, "w_m_rpm": w, "w_hat_rpm": w,
             "w_ref_rpm": np.where(t < 0.5, 0.0, 100.0), "i_a": np.sin(40 * t)}  # fmt: skip
    keys |= set(compute_metrics(table, T_s=1e-3, n_p=4, thd_window_s=(1.0, 2.0), overshoot=True))
    keys |= {f"band_{b}_{q}" for b in BANDS for q in BAND_QUANTITIES}
    for f in ("bench/runs/_results.py", "bench/runs/_metrics.py", "bench/runs/_run.py",
              "bench/captures/_read.py"):  # fmt: skip
        src = (ROOT / f).read_text()
        keys |= set(re.findall(r'(?:\bm|metrics)\["([a-z_0-9]+)"\]\s*=', src))
        keys |= set(re.findall(r'"(band_[a-z]+_(?:rpm|hz))"', src))
    return keys


def test_every_metrics_key_the_analysis_writes_is_documented() -> None:
    pats = _documented()
    keys = _written_keys()
    assert len(keys) > 50
    missing = sorted(k for k in keys if not any(p.match(k) for p in pats))
    assert not missing, f"metrics.json keys not in docs/RUNS.md: {missing}"


def test_every_rejection_reason_is_documented() -> None:
    from bench.nodes import _counters
    from bench.wire._codec import REJECT_REASONS

    reasons = set(REJECT_REASONS) | {
        v for k, v in vars(_counters).items() if k.startswith("REJECT_") and isinstance(v, str)
    }
    for r in reasons:
        assert f"`{r}`" in DOC, r


def test_every_file_of_a_run_folder_is_described() -> None:
    from bench.runs._run import RUN_FILES

    table = DOC.split("## metrics.json", 1)[0]
    for name in (*RUN_FILES, "plant.log", "controller.log", "link.log", "plot.png"):
        if name.startswith("capture."):
            continue
        assert f"`{name}`" in table, name
    assert "`capture.blf`" in table and "--log-format" in table


def test_the_plant_record_of_meta_json_is_documented() -> None:
    """Every key of the plant record ``meta.json`` carries (and of its ``preset``)."""
    from bench.runs._results import plant_record
    from bench.scenarios._schema import load_scenario

    section = DOC.split("## meta.json", 1)[1].split("\n## ", 1)[0]
    named = set(re.findall(r"`([a-z_A-Z]+)`", section))
    rec = plant_record(load_scenario("wen-5.1"))
    missing = sorted(k for k in [*rec, *rec["preset"], *rec["plant"]] if k not in named)
    assert not missing, f"meta.json keys not in docs/RUNS.md's meta.json section: {missing}"


def test_every_key_of_the_committed_runs_meta_json_is_documented() -> None:
    """Every top-level key of the reference runs' ``meta.json`` (docs/results) is named
    in the files table's ``meta.json`` row."""
    import json

    row = next(ln for ln in DOC.splitlines() if ln.startswith("| `meta.json` |"))
    keys: set[str] = set()
    for f in (ROOT / "docs" / "results" / "runs").rglob("meta.json"):
        keys |= set(json.loads(f.read_text()))
    assert len(keys) > 20
    missing = sorted(k for k in keys if f"`{k}`" not in row)
    assert not missing, f"meta.json keys not in docs/RUNS.md's files table: {missing}"
