"""run.png marks each fault's window and its detection (bench/runs/_plots.py)."""

from __future__ import annotations

from typing import Any

from bench.runs._plots import metrics_text, run_figure
from tests.test_plots import META, axes, figs, table  # noqa: F401  (figs: the fixture)


def test_each_fault_window_is_hatched_and_its_detection_drawn(figs: list[Any]) -> None:  # noqa: F811
    tab = table()
    t = tab["t"]
    tab["fault_active"] = ((t >= 2.0) & (t < 2.5)).astype(float)
    m = {
        "faults": [
            {"kind": "dc_link_step", "at_s": 2.0, "detected_at_s": 2.0125,
             "detected_by": "over_voltage", "reaction_ms": 12.5, "met": True},
        ]
    }  # fmt: skip
    fig = run_figure(tab, n_p=4, metrics=m, scored_from_s=1.0, f_split_hz=100.0, meta=META)
    figs.append(fig)
    ax = axes(fig)
    (band,) = [p for p in ax["speed"].patches if p.get_gid() == "fault"]
    x0, x1 = band.get_x(), band.get_x() + band.get_width()
    assert x0 == 2.0 and abs(x1 - 2.5) < 2 * (t[1] - t[0])
    det = [ln for ln in ax["speed"].get_lines() if ln.get_label() == "fault detected"]
    assert len(det) == 1 and list(det[0].get_xdata()) == [2.0125, 2.0125]
    labels = [x.get_text() for x in ax["speed"].get_legend().get_texts()]
    assert "fault active" in labels and "fault detected" in labels
    assert "fault dc_link_step @ 2 s: over_voltage +12.5 ms, met" in metrics_text(m)
