"""``bench perf --quick`` runs and writes a complete perf.json (no timing assertion)."""

import json
import math
from pathlib import Path

from bench.cli import main


def _numbers(x: object) -> list[float]:
    if isinstance(x, bool):
        return []
    if isinstance(x, int | float):
        return [float(x)]
    if isinstance(x, dict):
        return [v for val in x.values() for v in _numbers(val)]
    if isinstance(x, list):
        return [v for val in x for v in _numbers(val)]
    return []


def test_perf_quick_writes_every_section(tmp_path: Path, capsys) -> None:
    assert main(["perf", "--quick", "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "perf.json").read_text())
    for section in ("inprocess", "lockstep", "realtime", "codec", "busload", "verdicts"):
        assert res[section], section
    for est in ("sfhf", "tt-ab", "tt-dq", "square-wave", "square-wave-nocic", "sensored"):
        assert res["inprocess"][est]["us_per_step"] > 0
    assert set(res["realtime"]) == {"1kHz", "4kHz", "10kHz"}
    assert res["lockstep"]["steps_per_s"] > 0
    assert res["codec"]["analyze_frames_per_s"] > 0
    assert len(res["busload"]) >= 4
    nums = [v for s in ("inprocess", "lockstep", "codec", "busload") for v in _numbers(res[s])]
    assert all(math.isfinite(v) and v > 0 for v in nums)
    assert set(res["realtime_fifo"]) == {"1kHz", "4kHz", "10kHz"}
    for sec in ("realtime", "realtime_fifo"):
        for name in ("1kHz", "4kHz", "10kHz"):
            r = res[sec][name]
            assert (
                r["steps"] > 0
                and r["overrun_pct"] >= 0
                and r["jitter_us_max"] >= r["jitter_us_median"]
                and r["busy_us_p99"] >= r["busy_us_median"] > 0
            )
            assert r["policy"] in ("normal", "fifo")
        assert all(r["policy"] == "normal" for r in res["realtime"].values())
    for v in res["verdicts"].values():
        assert v["config"]
    out = capsys.readouterr().out
    assert "targets:" in out and "perf.json" in out
