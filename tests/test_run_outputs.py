"""What a run leaves behind and how it reads: the run folder after a failure,
signals.md, run.png's ingredients, bench plot, the real-time warning from
bench rtcheck, suites that do not overwrite, --help with defaults."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bench._errors import BenchError
from bench.cli import build_parser, main
from bench.runs._analysis import COLUMNS, signals_doc, write_csv
from bench.wire._bus import BusSpec
from tests.ports import free_port

# ---------------------------------------------------------------- a failed run


def test_a_run_that_fails_before_recording_leaves_only_error_txt_and_the_logs(
    tmp_path: Path,
) -> None:
    from bench.runs._run import run_scenario
    from bench.scenarios._schema import load_scenario

    out = tmp_path / "run"
    out.mkdir()
    (out / "run.png").write_text("an earlier run's plot")  # stale: must not survive
    scn = load_scenario("wen-5.1").with_overrides(duration=0.1)
    spec = BusSpec("udp_multicast", "239.74.163.2", free_port())
    with pytest.raises(BenchError, match=r"nothing recorded, see .*error\.txt"):
        run_scenario(
            scn,
            "sensored",
            spec=spec,
            out_dir=out,
            progress=False,
            node_args={"plant": ["--no-such-option"], "controller": []},
        )
    names = sorted(p.name for p in out.iterdir())
    assert [n for n in names if not n.endswith(".log")] == ["error.txt"], names
    assert "plant.log" in names
    text = (out / "error.txt").read_text()
    assert "plant" in text and "nothing was recorded" in text


# ---------------------------------------------------------------- signals.md


def test_signals_md_describes_every_column_and_every_mode_code() -> None:
    from bench.wire._codec import default_codec

    doc = signals_doc()
    for name, what in COLUMNS:
        assert f"| `{name}` | {what} |" in doc
    modes = default_codec().message("CtrlTelemetry").get_signal_by_name("mode").choices
    assert modes
    for code, label in modes.items():
        assert f"| {int(code)} | {label} |" in doc


# ---------------------------------------------------------------- run.png


def _table(n: int = 4000, T_s: float = 1e-3) -> dict[str, Any]:
    """A synthetic run: 100 rpm on a 4-pole-pair motor, align, polarity test, run."""
    t = np.arange(n) * T_s
    w_m = 100.0 * np.minimum(1.0, t / 0.5)
    theta = np.mod(np.cumsum(w_m * math.pi / 30.0 * 4 * T_s), 2 * math.pi)
    err = np.where(t < 1.0, 30.0 * np.exp(-t / 0.2), 0.3 * np.sin(2 * math.pi * 7 * t))
    mode = np.where(t < 0.1, 1, np.where(t < 0.15, 2, 3)).astype(float)
    i_d, i_q = np.zeros(n), 2.0 + 0.5 * np.cos(2 * math.pi * 250.0 * t)  # fundamental + HF
    tab: dict[str, Any] = {name: np.zeros(n) for name, _ in COLUMNS}
    tab.update(
        step=np.arange(n, dtype=float),
        t=t,
        theta_e=theta,
        theta_hat=np.mod(theta - np.radians(err), 2 * math.pi),
        theta_err_deg=err,
        w_m_rpm=w_m,
        w_hat_rpm=w_m,
        w_ref_rpm=w_m,
        mode=mode,
        i_d=i_d,
        i_q=i_q,
        i_a=i_d * np.cos(theta) - i_q * np.sin(theta),
    )
    return tab


def test_phase_spans_follow_the_mode_column() -> None:
    from bench.runs._plots import _spans

    tab = _table()
    t = tab["t"]
    assert _spans(tab["mode"] == 1, t) == [(0.0, pytest.approx(0.1))]
    (a, b), *rest = _spans(tab["mode"] == 2, t)
    assert not rest and (a, b) == (pytest.approx(0.1), pytest.approx(0.15))


def test_the_fundamental_current_drops_the_injection_and_keeps_the_fundamental() -> None:
    from bench.runs._plots import fundamental_a

    tab = _table(n=6000)
    fund = fundamental_a(tab, 1e-3, 50.0)  # 250 Hz HF, corner 50 Hz
    th = tab["theta_e"]
    expect = -2.0 * np.sin(th)  # i_q = 2 A turned back to phase A
    mid = slice(1000, 5000)  # away from the filter's edges
    assert np.max(np.abs(fund[mid] - expect[mid])) < 0.01
    assert np.max(np.abs(tab["i_a"][mid] - expect[mid])) > 0.4  # the raw one carries the HF


def test_metrics_box_names_a_trip_and_a_lost_lock() -> None:
    from bench.runs._plots import metrics_text

    base = {"theta_err_abs_max_deg": 0.66, "theta_err_abs_max_rad": 0.0115}
    assert "TRIP" not in metrics_text(base) and "LOCK" not in metrics_text(base)
    text = metrics_text(
        base | {"plant_fault": "over_current", "lock_lost": True, "lock_lost_at_s": 2.5}
    )
    assert "TRIP: over_current" in text and "LOCK LOST at 2.500 s" in text
    assert "0.66 deg (0.011 rad)" in text


def test_the_title_names_the_controller_from_meta_json_and_the_papers_figure() -> None:
    from bench.runs._plots import controller_label, paper_figure

    assert controller_label({"estimator": "tt-dq"}) == "tt-dq"
    assert controller_label({"estimator": "tt-dq", "controller": "bench"}) == "tt-dq"
    ext = {"estimator": "external", "controller": "external", "controller_name": "my-drive"}
    assert controller_label(ext) == "external controller my-drive"
    assert paper_figure("Wen et al. 2023, Sec. 5.1, Fig. 14, Table 5") == "Wen et al. 2023, Fig. 14"
    assert paper_figure("Xue et al. 2022, Sec. 4, Fig. 13") == "Xue et al. 2022, Fig. 13"
    assert paper_figure("") is None


def test_run_png_scales_the_error_panel_to_the_scored_window(tmp_path: Path) -> None:
    """The start-up transient (30 deg) stays in the inset; the main panel shows +-0.3 deg."""
    import matplotlib.pyplot as plt

    from bench.runs import _plots

    figs: list[Any] = []
    real_close = plt.close
    plt.close = lambda fig=None: figs.append(fig)
    try:
        _plots.plot_run(
            _table(),
            tmp_path,
            title="synthetic",
            metrics={"plant_fault": "over_current", "plant_fault_step": 3000},
            scored_from_s=1.0,
            f_split_hz=50.0,
            n_p=4,
        )
    finally:
        plt.close = real_close
    fig = figs[0]
    ax_err = fig.axes[1]
    lo, hi = ax_err.get_ylim()
    assert -1.0 < lo < -0.3 and 0.3 < hi < 2.0  # scaled to the scored +-0.3 deg
    x0, x1 = ax_err.get_xlim()  # the time axis the other panels share (tests/test_plots.py)
    assert x0 == pytest.approx(0.0) and x1 == pytest.approx(4.0)
    legend = [t.get_text() for t in fig.axes[2].get_legend().get_texts()]
    for label in ("align (100 ms)", "polarity test (50 ms)", "scoring start", "trip: over_current"):
        assert label in legend
    real_close(fig)
    assert (tmp_path / "run.png").stat().st_size > 10_000


# ---------------------------------------------------------------- bench plot


def test_bench_plot_draws_chosen_columns_and_names_unknown_ones(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    write_csv(str(tmp_path / "signals.csv"), _table())
    assert (
        main(["plot", str(tmp_path), "--signals", "theta_e,i_q", "--from", "1", "--to", "2"]) == 0
    )
    assert (tmp_path / "plot.png").is_file()
    assert main(["plot", str(tmp_path), "-s", "theta_e,nope"]) == 2
    assert "unknown column nope" in capsys.readouterr().err
    assert main(["plot", str(tmp_path), "--from", "2", "--to", "1"]) == 2
    assert main(["plot", str(tmp_path), "-o", str(tmp_path / "again.png")]) == 0
    assert (tmp_path / "again.png").is_file()


# ---------------------------------------------------------------- real time


def test_a_realtime_run_is_warned_from_this_hosts_rtcheck() -> None:
    from bench.studies._rtcheck import host_warning

    res = json.loads(Path("docs/realtime/rtcheck.json").read_text())
    assert "not measured" in (host_warning(1000.0, False, None) or "")
    assert host_warning(1000.0, True, res) is None  # measured 'yes' with SCHED_FIFO
    warn = host_warning(1000.0, False, res) or ""
    r = res["rates"]["1000"]["normal"]
    assert f"'{r['verdict']}' at 1000 Hz with normal scheduling" in warn
    assert f"wake-up p99 {r['p99']:.0f} us" in warn and "--rt-priority" in warn
    assert "bench rtcheck --rate 2" in (host_warning(2000.0, False, res) or "")


# ---------------------------------------------------------------- suites and --help


def test_a_suite_does_not_overwrite_earlier_results_unless_told(tmp_path: Path) -> None:
    from bench.cli.suite import _check_new

    _check_new(tmp_path, overwrite=False)  # empty: fine
    (tmp_path / "summary.json").write_text("{}")
    with pytest.raises(BenchError, match="--overwrite"):
        _check_new(tmp_path, overwrite=False)
    _check_new(tmp_path, overwrite=True)


def _parsers(p: argparse.ArgumentParser) -> list[argparse.ArgumentParser]:
    out = [p]
    for a in p._actions:
        if isinstance(a, argparse._SubParsersAction):
            for sub in dict.fromkeys(a.choices.values()):
                out += _parsers(sub)
    return out


def test_help_shows_every_default_and_no_virtual_bus() -> None:
    for p in _parsers(build_parser()):
        text = p.format_help()
        # bench replay alone may send onto python-can's in-process virtual bus
        assert "virtual" not in text or p.prog == "bench replay", p.prog
        for a in p._actions:
            if not a.option_strings or a.help in (None, argparse.SUPPRESS):
                continue
            if a.default in (None, False, argparse.SUPPRESS):
                continue
            assert "default" in p._get_formatter()._expand_help(a), (p.prog, a.dest)


# ---------------------------------------------------------------- sweep plots


def test_sweep_plots_mark_lost_lock_and_label_every_panel_and_fit(tmp_path: Path) -> None:
    import matplotlib.pyplot as plt

    from bench.studies._sweep import lost_points, plot_sweeps

    old = {"x": [0.0, 0.2, 0.4], "theta_err_abs_max_deg": [1.0, 66.0, 180.0]}
    assert lost_points(old).tolist() == [False, False, True]  # an older summary: max > 90 deg
    new = dict(old, lock_lost=[False, True, True])
    assert lost_points(new).tolist() == [False, True, True]  # the runs' own lock_lost
    meth = dict(new, theta_err_mean_deg=[0.5, 3.0, -80.0], slope=2.0, intercept_deg=0.4)
    sweeps = {"noise": {"label": "current noise (A)", "fit": True, "slope_per": 1.0,
                        "slope_unit": "deg per A", "methods": {"tt-dq": meth}}}  # fmt: skip
    figs: list[Any] = []
    real_close = plt.close
    plt.close = lambda fig=None: figs.append(fig)
    try:
        assert plot_sweeps(sweeps, tmp_path) == ["sweep-noise.png"]
    finally:
        plt.close = real_close
    for ax in figs[0].axes:
        labels = [t.get_text() for t in ax.get_legend().get_texts()]
        assert "tt-dq" in labels and "lost lock (mean meaningless)" in labels
    labels = [t.get_text() for t in figs[0].axes[0].get_legend().get_texts()]
    assert "tt-dq fit: +2.00 deg per A" in labels
    real_close(figs[0])
