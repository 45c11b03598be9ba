"""``bench sweep``'s line plot: a log axis only over a wide range, the scenario's name as title.

Read from the figure's own data (scale, limits, title), no picture compared.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import pytest

from bench.studies._grid import PLOT_METRIC, Plan, line_figure, plot_sweep, use_log_axis


def _records(values: dict[float, float], estimator: str = "tt-dq") -> list[dict[str, Any]]:
    return [
        {
            "estimator": estimator,
            "scenario": f"wen-5.1-p{k}",
            "values": {"seed": x},
            "metrics": {PLOT_METRIC: y, "lock_lost": y > 90.0},
        }
        for k, (x, y) in enumerate(values.items())
    ]


def test_a_narrow_range_gets_a_linear_axis_that_shows_it() -> None:
    recs = _records({1: 0.68, 2: 0.88, 3: 0.75})
    fig = line_figure(recs, "seed", ("tt-dq",), "wen-5.1: vs seed")
    ax = fig.axes[0]
    try:
        assert ax.get_yscale() == "linear"
        lo, hi = ax.get_ylim()
        # the range fills the axis: a difference of 0.2 deg is most of its height
        assert lo <= 0.68 and hi >= 0.88 and (0.88 - 0.68) / (hi - lo) > 0.5
        inside = [t for t in ax.get_yticks() if 0.68 <= t <= 0.88]
        assert len(inside) >= 2  # labelled ticks between the extremes
    finally:
        plt.close(fig)


def test_a_range_over_a_decade_keeps_the_log_axis() -> None:
    recs = _records({1: 0.7, 2: 0.9, 3: 170.0})  # a point that lost the rotor
    fig = line_figure(recs, "seed", ("tt-dq",), "t")
    try:
        assert fig.axes[0].get_yscale() == "log"
    finally:
        plt.close(fig)
    assert not use_log_axis([0.68, 0.88]) and use_log_axis([0.5, 6.0])
    assert not use_log_axis([0.5, 5.0])  # exactly a decade: still linear
    # the paper's bound counts as a shown value
    fig = line_figure(_records({1: 0.7, 2: 0.9}), "seed", ("tt-dq",), "t", bound=10.0)
    try:
        assert fig.axes[0].get_yscale() == "log"
    finally:
        plt.close(fig)


def test_the_title_is_the_scenarios_name_not_its_path(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    scn = tmp_path / "deep" / "folder" / "my-motor.toml"
    scn.parent.mkdir(parents=True)
    scn.write_text('extends = "wen-5.1"\nname = "my-motor"\n')
    plan = Plan(str(scn), ("tt-dq",), grid={"seed": [1, 2, 3]})
    titles: list[str] = []
    orig = plt.Figure.savefig

    def keep_title(fig: Any, *a: Any, **k: Any) -> None:
        titles.append(fig.axes[0].get_title())
        orig(fig, *a, **k)

    monkeypatch.setattr(plt.Figure, "savefig", keep_title)
    names = plot_sweep(_records({1: 0.7, 2: 0.8, 3: 0.9}), plan, tmp_path / "plots")
    assert names == ["plots/line-seed.png"] and (tmp_path / "plots" / "line-seed.png").is_file()
    assert titles == ["my-motor: vs seed"]
    assert str(tmp_path) not in titles[0]
