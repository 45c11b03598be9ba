"""run.png read as a scope: its axes, limits and marks, from the figure's matplotlib objects.

The synthetic run (:func:`table`): 10 kHz, align 0-0.1 s, polarity test
0.1-0.105 s, a ramp to 100 rpm, a load step at 2 s and a load ramp
2.5-3.0 s sent as a 1 kHz staircase, the last row after the stop (mode 0)
with an estimate that drops to 80 rpm.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bench.cli import main
from bench.runs._analysis import COLUMNS, write_csv
from bench.runs._plots import (
    MIN_SPAN,
    PANELS,
    load_events,
    paper_bounds,
    run_figure,
    run_variations,
)

T_S = 1e-4
WEN_RESULT = {"theta_err_max_deg": 4.0, "theta_err_min_deg": -0.5, "theta_err_mean_deg": 2.0}


def table(n: int = 40000, injection: bool = True) -> dict[str, Any]:
    t = np.arange(n) * T_S
    w_m = 100.0 * np.clip((t - 0.2) / 0.6, 0.0, 1.0)
    theta = np.mod(np.cumsum(w_m * math.pi / 30.0 * 4 * T_S), 2 * math.pi)
    err = np.where(t < 1.0, 30.0 * np.exp(-t / 0.2), 0.3 * np.sin(2 * math.pi * 7 * t))
    mode = np.where(t < 0.1, 1, np.where(t < 0.105, 2, 3)).astype(float)
    mode[-1] = 0.0
    load = np.where(t >= 2.0, 1.0, 0.0) + np.clip(np.floor((t - 2.5) / 1e-3) / 500.0, 0.0, 1.0)
    # acceleration current 3 A, then the load's
    i_q = np.where((t > 0.2) & (t < 0.8), 3.0, 0.2) + load
    i_d = np.where(mode == 2, 8.0, 0.0)  # the polarity pulses
    if injection:
        i_d = i_d + 0.25 * np.cos(2 * math.pi * 500.0 * t)
    w_hat = w_m.copy()
    w_hat[-1] = 80.0  # the disabled controller's last word: not an estimate
    tab: dict[str, Any] = {name: np.zeros(n) for name, _ in COLUMNS}
    tab.update(
        step=np.arange(n, dtype=float),
        t=t,
        theta_e=theta,
        theta_hat=np.mod(theta - np.radians(err), 2 * math.pi),
        theta_err_deg=err,
        w_m_rpm=w_m,
        w_hat_rpm=w_hat,
        w_ref_rpm=w_m,
        mode=mode,
        i_d=i_d,
        i_q=i_q,
        i_a=i_d * np.cos(theta) - i_q * np.sin(theta),
        load_ref_nm=load,
        tau_L=load,
        tau_e=load + 0.1,
    )
    return tab


META: dict[str, Any] = {
    "estimator": "tt-dq",
    "controller": "bench",
    "scenario": {
        "name": "wen-5.x",
        "estimator": "tt-dq",
        "paper": "Wen et al. 2023, Sec. 5.1, Fig. 14, Table 5",
        "paper_result": WEN_RESULT,
    },
}


def axes(fig: Any) -> dict[str, Any]:
    return {a.get_label(): a for a in fig.axes if a.get_label() in PANELS}


@pytest.fixture
def figs() -> Any:
    import matplotlib.pyplot as plt

    made: list[Any] = []
    yield made
    for f in made:
        plt.close(f)


def draw(figs: list[Any], tab: dict[str, Any], **kw: Any) -> dict[str, Any]:
    kw.setdefault("scored_from_s", 1.0)
    kw.setdefault("f_split_hz", 100.0)
    kw.setdefault("meta", META)
    fig = run_figure(tab, n_p=4, **kw)
    figs.append(fig)
    return axes(fig)


def test_every_time_panel_shares_one_time_axis_from_the_first_row(figs: list[Any]) -> None:
    ax = draw(figs, table())
    assert set(ax) == set(PANELS)
    shared = [ax[k] for k in PANELS[1:]]
    for a in shared:
        assert a.get_xlim() == pytest.approx((0.0, 4.0))  # the error panel too, not from 1 s
        assert ax["error"].get_shared_x_axes().joined(ax["error"], a)
    assert not ax["error"].get_shared_x_axes().joined(ax["error"], ax["angle"])  # the zoom


def test_the_error_panel_holds_the_scored_error_and_the_papers_bound(figs: list[Any]) -> None:
    ax = draw(figs, table())
    lo, hi = ax["error"].get_ylim()
    assert lo < -0.5 and hi > 4.0  # Table 5's range drawn inside the panel
    assert hi < 15.0  # the 30-deg start-up transient is not what scales it
    bounds = sorted(ln.get_ydata()[0] for ln in ax["error"].get_lines()
                    if ln.get_gid() == "paper_bound")  # fmt: skip
    assert bounds == [-0.5, 4.0]
    labels = [t.get_text() for t in ax["error"].get_legend().get_texts()]
    assert any("-0.5 .. +4 deg" in s and "tt-dq" in s for s in labels)
    assert paper_bounds({"theta_err_abs_max_rad": 0.1})[0] == pytest.approx(
        [-math.degrees(0.1), math.degrees(0.1)]
    )
    assert paper_bounds({}) == ([], "")


def test_no_paper_bound_without_a_paper_result(figs: list[Any]) -> None:
    meta = {**META, "scenario": {"name": "mine"}}
    ax = draw(figs, table(), meta=meta)
    assert not [ln for ln in ax["error"].get_lines() if ln.get_gid() == "paper_bound"]


def test_the_current_panel_without_injection_is_scaled_to_the_current_and_says_so(
    figs: list[Any],
) -> None:
    tab = table(injection=False)
    ax = draw(figs, tab, f_split_hz=None)
    running = tab["mode"] != 2
    peak = float(np.max(np.abs(tab["i_a"][running])))  # acceleration and load current
    lo, hi = ax["current"].get_ylim()
    assert hi >= peak and -lo >= peak
    assert hi < 2.0 * peak  # not the polarity test's 8 A
    labels = [t.get_text() for t in ax["current"].get_legend().get_texts()]
    assert labels == ["sample"]
    ax = draw(figs, table(), f_split_hz=100.0)
    labels = [t.get_text() for t in ax["current"].get_legend().get_texts()]
    assert labels[0] == "sample (with injection)" and labels[1].startswith("fundamental")


def test_load_torque_is_drawn_and_its_steps_and_ramps_marked(figs: list[Any]) -> None:
    tab = table()
    steps, ramps = load_events(tab["t"], tab["load_ref_nm"])
    assert steps == [pytest.approx(2.0)]
    ((a, b),) = ramps
    assert a == pytest.approx(2.5, abs=2e-3) and b == pytest.approx(3.0, abs=2e-3)
    ax = draw(figs, tab)
    drawn = {ln.get_label(): ln for ln in ax["load"].get_lines()}
    assert np.array_equal(drawn["load torque"].get_ydata(), tab["tau_L"])
    lo, hi = ax["load"].get_ylim()
    assert lo <= 0.0 and hi >= 2.0
    labels = [t.get_text() for t in ax["speed"].get_legend().get_texts()]
    assert "load step" in labels and "load ramp" in labels


def test_a_short_polarity_test_gets_a_visible_band_and_its_length(figs: list[Any]) -> None:
    ax = draw(figs, table())
    (band,) = [p for p in ax["speed"].patches if p.get_gid() == "phase2"]
    x = band.get_transform().transform(band.get_path().vertices)[:, 0]
    width_px = x.max() - x.min()
    axis_px = ax["speed"].get_window_extent().width
    assert width_px >= 0.9 * MIN_SPAN * axis_px and width_px >= 2.0
    labels = [t.get_text() for t in ax["speed"].get_legend().get_texts()]
    assert "polarity test (5 ms)" in labels


def test_no_estimate_is_drawn_after_the_stop_and_in_empty_rows(figs: list[Any]) -> None:
    tab = table()
    tab["theta_hat"][30000:30100] = np.nan  # the controller's telemetry stopped
    tab["w_hat_rpm"][30000:30100] = np.nan
    tab["theta_err_deg"][30000:30100] = np.nan
    ax = draw(figs, tab)
    est = next(ln for ln in ax["speed"].get_lines() if ln.get_label() == "estimated")
    y = np.asarray(est.get_ydata(), dtype=float)
    assert math.isnan(y[-1])  # no 100 -> 80 rpm spike at the right edge
    assert np.isnan(y[30000:30100]).all() and np.isfinite(y[29999])
    lo, hi = ax["speed"].get_ylim()
    assert lo < 0.0 < 100.0 < hi


def test_the_title_names_the_runs_variations(figs: list[Any]) -> None:
    meta = {
        **META,
        "plant": {"profile": "drive"},
        "countermeasures": {"dead_time_compensation": True, "offset_calibration": False},
        "lockstep_delay_steps": 2,
        "scenario": {**META["scenario"], "controller_model": {"L_d": 1.2, "J": 1.0}},
    }
    var = run_variations(meta)
    assert var == ["drive plant", "countermeasures: dead-time comp.", "delay +2 periods",
                   "model L_d x1.2"]  # fmt: skip
    assert run_variations({**meta, "countermeasures": None})[1] == (
        "countermeasures: the controller's own"
    )
    draw(figs, table(), meta=meta)
    title = figs[-1]._suptitle.get_text()
    assert "wen-5.x / tt-dq" in title and "Fig. 14" in title and "delay +2 periods" in title
    draw(figs, table(), meta=META)
    assert "delay" not in figs[-1]._suptitle.get_text()


def write_run(d: Path, tab: dict[str, Any]) -> None:
    write_csv(str(d / "signals.csv"), tab)
    (d / "meta.json").write_text(json.dumps({**META, "scored_from_s": 1.0}))
    whole = {"theta_err_abs_max_deg": 29.99, "theta_err_abs_max_rad": 0.52}
    (d / "metrics.json").write_text(json.dumps(whole))


def test_bench_plot_from_to_applies_to_every_panel_and_the_box(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import matplotlib.pyplot as plt

    write_run(tmp_path, table())
    made: list[Any] = []
    monkeypatch.setattr(plt, "close", made.append)
    assert main(["plot", str(tmp_path), "--from", "1.5", "--to", "2.5"]) == 0
    (fig,) = made
    ax = axes(fig)
    for k in PANELS[1:]:
        x0, x1 = ax[k].get_xlim()
        assert 1.5 <= x0 < 1.501 and 2.5 <= x1 < 2.501, k
    (inset,) = ax["error"].child_axes
    assert inset.get_xlim() == pytest.approx(ax["error"].get_xlim())
    a0, a1 = ax["angle"].get_xlim()
    assert a0 >= 1.5 - 0.05 and a1 <= 2.5 + 0.05
    box = next(t.get_text() for t in ax["error"].texts if "dtheta" in t.get_text())
    assert box.startswith("window 1.5-2.5 s")
    assert "29.99" not in box and "|dtheta| max 0.30 deg" in box  # recomputed, not the run's
    assert "window 1.5-2.5 s" in fig._suptitle.get_text()
    assert (tmp_path / "run.png").is_file()


def test_bench_plot_draws_a_run_with_empty_estimate_cells(tmp_path: Path) -> None:
    tab = table()
    write_run(tmp_path, tab)
    lines = (tmp_path / "signals.csv").read_text().splitlines()
    names = lines[0].split(",")
    blank = [names.index(c) for c in ("theta_hat", "theta_err_deg", "w_hat_rpm", "mode", "est_err")]
    for i in range(30001, 40001):  # the controller's telemetry stopped at 3 s
        cells = lines[i].split(",")
        for j in blank:
            cells[j] = ""
        lines[i] = ",".join(cells)
    (tmp_path / "signals.csv").write_text("\n".join(lines) + "\n")
    assert main(["plot", str(tmp_path)]) == 0
    assert main(["plot", str(tmp_path), "--from", "3.2", "--to", "3.5"]) == 0


def test_legends_the_box_and_the_inset_leave_the_traces_free(figs: list[Any]) -> None:
    ax = draw(figs, table())
    fig = figs[-1]
    fig.canvas.draw()
    for a in ax.values():
        right = a.get_window_extent().x1
        leg = a.get_legend()
        assert leg is not None and leg.get_window_extent().x0 >= right, a.get_label()
    err = ax["error"]
    box = next(t for t in err.texts if "dtheta" in t.get_text())
    assert box.get_window_extent().x0 >= err.get_window_extent().x1
    # the inset sits above every scored error and the paper's bound
    (inset,) = err.child_axes
    top = max(4.0, float(np.nanmax(table()["theta_err_deg"][table()["t"] >= 1.0])))
    inset_bottom = inset.get_window_extent().y0
    y_top = err.transData.transform((0.0, top))[1]
    assert inset_bottom > y_top
