"""docs/REALTIME.md's native block is ``bench perf``'s rendering of docs/perf/perf.json.

The block names each issue-29 target of the native nodes with its figure,
verdict and, where missed, the limit the same run measured.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

from bench.studies._perf import (
    NATIVE_DOC_BEGIN,
    NATIVE_DOC_END,
    NATIVE_NOTE,
    NATIVE_TARGET_LIST,
    native_verdicts,
    recorder_frames_lost,
    render_realtime_native,
    update_realtime_doc,
)

ROOT = Path(__file__).resolve().parents[1]


def _committed() -> dict[str, Any]:
    return json.loads((ROOT / "docs" / "perf" / "perf.json").read_text())


def test_the_committed_page_is_the_rendering_of_the_committed_json() -> None:
    doc = (ROOT / "docs" / "REALTIME.md").read_text()
    assert doc.count(NATIVE_DOC_BEGIN) == 1 and doc.count(NATIVE_DOC_END) == 1
    assert update_realtime_doc(doc, _committed()) == doc


def _measured(missed_10k: float, frames_lost: float) -> dict[str, Any]:
    """The committed perf.json with native figures: the SCHED_FIFO rows as the native ones."""
    res = copy.deepcopy(_committed())
    nat = {
        k: {**v, "note": NATIVE_NOTE, "recorder_frames_lost": 0.0}
        for k, v in copy.deepcopy(res["realtime_fifo"]).items()
    }
    nat["10kHz"].update(
        missed_pct=missed_10k,
        late_outside_stalls_pct=0.5,
        periods_skipped=300.0,
        host_stalls=4.0,
        busy_us_median=8.0,
        recorder_frames_lost=frames_lost,
    )
    nat["4kHz"].update(missed_pct=0.5)
    res["realtime_native"] = {**nat, "recorder_frames_lost": recorder_frames_lost(nat)}
    res["lockstep_native"] = {**res["lockstep"], "steps_per_s": 25000.0, "note": NATIVE_NOTE}
    return res


def test_each_target_has_its_verdict_and_a_missed_one_its_limit() -> None:
    res = _measured(missed_10k=18.2, frames_lost=12.0)
    v = native_verdicts(res)
    assert v is not None and set(v) == {t.key for t in NATIVE_TARGET_LIST}
    assert v["native_busy_us_p50_10khz"]["met"] and v["native_missed_pct_4khz"]["met"]
    assert v["native_lockstep_periods_per_s"]["met"]
    assert not v["native_missed_pct_10khz"]["met"]
    assert "host stalls: 4 stalls" in v["native_missed_pct_10khz"]["limit"]
    assert "300 periods" in v["native_missed_pct_10khz"]["limit"]
    assert v["native_recorder_frames_lost"] == {**v["native_recorder_frames_lost"], "value": 12.0}
    assert not v["native_recorder_frames_lost"]["met"]
    text = render_realtime_native(res)
    rows = [ln for ln in text.splitlines() if ln.startswith("| ") and "missed" in ln]
    assert sum("**missed**" in ln for ln in rows) == 2
    assert "| 10kHz | " in text and "18.2 %" in text
    met = render_realtime_native(_measured(missed_10k=2.0, frames_lost=0.0))
    assert "**missed**" not in met


def test_a_transport_that_does_not_say_is_not_a_zero() -> None:
    """-1 (the transport does not report drops) makes the total unknown, never 0 frames."""
    res = _measured(missed_10k=2.0, frames_lost=-1.0)
    assert res["realtime_native"]["recorder_frames_lost"] == -1.0
    v = native_verdicts(res)
    assert v is not None and not v["native_recorder_frames_lost"]["met"]
    assert v["native_recorder_frames_lost"]["limit"] == "not said by the transport"
