"""run.png of a real-time run and of a controller under test: the late periods, the host
stalls, the periods the recording lacks and a lost tail (in ``bench plot --from/--to``'s
window too) are on the figure; another method's paper band is not (the synthetic run of
tests/test_plots.py)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import can
import numpy as np
import pytest

from bench.cli import main
from bench.runs._plots import late_duty_rows, metrics_text
from bench.runs._results import host_stall_times
from bench.wire._codec import Codec
from tests.test_plots import META, T_S, axes, draw, figs, table, write_run

__all__ = ["figs"]  # the fixture, used by name

RT_META: dict[str, Any] = {**META, "mode": "realtime"}


def late_table() -> dict[str, Any]:
    """The synthetic run with duties 3 periods stale over 1.5-1.6 s and one at 2.2 s; no
    duty at all (255) in the first 50 periods."""
    tab = table()
    age = np.zeros(len(tab["t"]))
    age[:50] = 255.0
    age[(tab["t"] >= 1.5) & (tab["t"] < 1.6)] = 3.0
    age[int(round(2.2 / T_S))] = 1.0
    tab["duty_age"] = age
    return tab


def _spans(ax: Any, gid: str) -> list[tuple[float, float]]:
    """The (start, end) of the bands ``ax.axvspan`` drew with ``gid``."""
    return sorted((p.get_x(), p.get_x() + p.get_width()) for p in ax.patches if p.get_gid() == gid)


def test_late_duty_rows_are_those_older_than_the_runs_usual_duty() -> None:
    tab = late_table()
    late = late_duty_rows(tab)
    assert int(np.count_nonzero(late)) == 1000 + 1  # 0.1 s at 10 kHz, and the one at 2.2 s
    assert not late[:50].any()  # no duty (255) is not a late one
    # a lockstep run with one period of injected delay: every duty has its set age
    tab["duty_age"] = np.where(tab["duty_age"] == 255.0, 255.0, 1.0)
    assert not late_duty_rows(tab).any()


def test_the_late_periods_and_the_stalls_are_shaded_on_every_time_panel(
    figs: list[Any],
) -> None:
    m = {"late_duty_periods": 1001, "steps": 40000, "host_stalls": 2, "host_stall_ms_max": 19.3,
         "periods_skipped": 300}  # fmt: skip
    ax = draw(figs, late_table(), meta=RT_META, metrics=m, stalls=[0.7, 3.1])
    for name in ("error", "speed", "current", "load"):
        late = _spans(ax[name], "late_duty")
        assert late[0] == pytest.approx((1.5, 1.6), abs=2 * T_S), name
        assert len(late) == 2, name  # the lone period is widened to be seen, not dropped
        stalls = _spans(ax[name], "host_stall")
        assert [0.5 * (a + b) for a, b in stalls] == pytest.approx([0.7, 3.1]), name
    labels = [t.get_text() for t in ax["speed"].get_legend().get_texts()]
    assert any("late duty held (1001 periods)" in s for s in labels), labels
    assert any(s.startswith("host stall (2 located") for s in labels), labels


def test_the_box_names_late_duties_stalls_and_missing_periods_where_not_zero() -> None:
    base = {"theta_err_abs_max_deg": 1.0}
    assert "late duty" not in metrics_text({**base, "late_duty_periods": 0, "steps": 10})
    text = metrics_text({**base, "late_duty_periods": 568, "steps": 10001, "host_stalls": 13,
                         "host_stall_ms_max": 19.306, "periods_skipped": 1396,
                         "steps_missing": 12})  # fmt: skip
    assert "late duty 5.7 % of periods" in text
    assert "host stalls 13, longest 19.3 ms" in text and "periods skipped 1396" in text
    assert "steps_missing 12" in text


def test_a_lost_tail_is_marked_and_the_axis_runs_to_the_plants_last_period(
    figs: list[Any],
) -> None:
    tab = {k: v[:30000] for k, v in table().items()}  # the recorder kept 3 of 4 s
    meta = {**RT_META, "node_reports": {"plant": {"steps": 40000}}}
    ax = draw(figs, tab, meta=meta, metrics={"steps_missing": 10000})
    assert ax["speed"].get_xlim() == pytest.approx((0.0, 4.0))
    ends = [ln.get_xdata()[0] for ln in ax["speed"].get_lines() if ln.get_gid() == "recorded_end"]
    assert ends == pytest.approx([3.0])
    assert "the recorder lost the rest" in ax["load"].get_xlabel()
    # a run the plant ended where the recording does: nothing marked
    meta = {**RT_META, "node_reports": {"plant": {"steps": 30000}}}
    ax = draw(figs, tab, meta=meta)
    assert ax["speed"].get_xlim() == pytest.approx((0.0, 3.0))
    assert not [ln for ln in ax["speed"].get_lines() if ln.get_gid() == "recorded_end"]


def test_no_paper_band_for_a_controller_under_test(figs: list[Any]) -> None:
    """An external controller is not the paper's method: no band of its numbers, and the
    error panel is scaled to the run's own error (0.3 deg here), not to the band's 4 deg."""
    meta = {**META, "controller": "external", "controller_name": "ext-py"}
    ax = draw(figs, table(), meta=meta)
    assert not [ln for ln in ax["error"].get_lines() if ln.get_gid() == "paper_bound"]
    lo, hi = ax["error"].get_ylim()
    assert hi < 4.0 and lo > -4.0


def stalled_truth(codec: Codec) -> list[can.Message]:
    """200 periods of ``PlantTruth`` with two 20 ms stalls, before periods 50 and 120."""
    msg = codec.message("PlantTruth")
    frames = []
    t = 100.0
    for k in range(200):
        t += T_S + (0.02 if k in (50, 120) else 0.0)
        sig = {s.name: 0.0 for s in msg.signals if s.name != "crc"}
        sig["step"] = float(k)
        f = codec.encode("PlantTruth", sig)
        f.timestamp = t
        frames.append(f)
    return frames


def test_host_stalls_are_the_gaps_in_the_plants_frames() -> None:
    codec = Codec()
    assert host_stall_times(stalled_truth(codec), codec, T_S) == pytest.approx(
        [50 * T_S, 120 * T_S]
    )


def lost_tail_run(d: Path) -> None:
    """A run folder whose recorder kept 3 of the plant's 4 s."""
    write_run(d, {k: v[:30000] for k, v in table().items()})
    meta = json.loads((d / "meta.json").read_text())
    meta.update(RT_META, node_reports={"plant": {"steps": 40000}}, T_s=T_S)
    (d / "meta.json").write_text(json.dumps(meta))


def test_a_window_over_the_lost_tail_marks_it_and_runs_to_the_windows_end(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import matplotlib.pyplot as plt

    lost_tail_run(tmp_path)
    made: list[Any] = []
    monkeypatch.setattr(plt, "close", made.append)

    def ends(ax: Any) -> list[float]:
        return [ln.get_xdata()[0] for ln in ax.get_lines() if ln.get_gid() == "recorded_end"]

    assert main(["plot", str(tmp_path), "--from", "2.5", "--to", "3.5"]) == 0
    ax = axes(made[-1])
    assert ax["speed"].get_xlim() == pytest.approx((2.5, 3.5))
    assert ends(ax["speed"]) == pytest.approx([3.0]) and ends(ax["load"]) == pytest.approx([3.0])
    assert "the recorder lost the rest" in ax["load"].get_xlabel()
    assert "window 2.5-3.5 s" in made[-1]._suptitle.get_text()
    # without --to: on to the plant's last period
    assert main(["plot", str(tmp_path), "--from", "2.5"]) == 0
    ax = axes(made[-1])
    assert ax["speed"].get_xlim() == pytest.approx((2.5, 4.0))
    assert ends(ax["speed"]) == pytest.approx([3.0])
    # a window that ends before the recorded data do: nothing marked
    assert main(["plot", str(tmp_path), "--from", "1.5", "--to", "2.5"]) == 0
    ax = axes(made[-1])
    assert ax["speed"].get_xlim()[1] == pytest.approx(2.5, abs=2 * T_S)
    assert not ends(ax["speed"]) and "lost" not in ax["load"].get_xlabel()


def test_a_window_past_the_recorded_data_says_where_they_end(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    lost_tail_run(tmp_path)
    assert main(["plot", str(tmp_path), "--from", "3.2", "--to", "3.5"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "no rows between --from and --to: the recorded data end at 3.000 s" in err[0]
    assert "the plant ran to 4.000 s" in err[0]


def test_the_stalls_instants_are_kept_in_metrics_json(tmp_path: Path) -> None:
    """A real-time run's stalls, located in its capture, are written beside their count, so
    that a run folder without its capture still knows where they were."""
    from bench.nodes._loops import run_inprocess
    from bench.runs._results import finish_run
    from bench.scenarios._schema import load_scenario
    from bench.scenarios._setup import sample_period

    scn = load_scenario("wen-5.1").with_overrides(duration=0.05)
    codec = Codec()
    T_s = sample_period(scn)
    frames = list(run_inprocess(scn, "sensored", codec, loop="python"))
    truth_id = codec.frame_id("PlantTruth")
    # the wire's times: one period per PlantTruth, and a 20 ms stall before the 300th
    k = -1
    for f in frames:
        k += f.arbitration_id == truth_id
        f.timestamp = 100.0 + max(k, 0) * T_s + (0.02 if k >= 300 else 0.0)
    report = {"jitter": {"stalls": 1, "stall_total": 2e4, "stall_max": 2e4, "skipped": 200}}
    res = finish_run(frames, codec, scn, tmp_path, wall_s=1.0, capture=None, plots=False,
                     meta={"estimator": "sensored", "node_reports": {"plant": report}})  # fmt: skip
    written = json.loads((tmp_path / "metrics.json").read_text())
    assert res.metrics["host_stall_at_s"] == pytest.approx([300 * T_s])
    assert written["host_stall_at_s"] == pytest.approx([300 * T_s])


def test_bench_plot_marks_the_stalls_of_a_folder_without_its_capture(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import matplotlib.pyplot as plt

    write_run(tmp_path, late_table())
    (tmp_path / "meta.json").write_text(json.dumps({**RT_META, "capture": "capture.blf"}))
    m = {"host_stalls": 2, "host_stall_ms_max": 19.3, "host_stall_at_s": [0.7, 3.1]}
    (tmp_path / "metrics.json").write_text(json.dumps(m))
    assert not (tmp_path / "capture.blf").exists()
    made: list[Any] = []
    monkeypatch.setattr(plt, "close", made.append)
    assert main(["plot", str(tmp_path)]) == 0
    for name in ("error", "speed", "current", "load"):
        stalls = _spans(axes(made[-1])[name], "host_stall")
        assert [0.5 * (a + b) for a, b in stalls] == pytest.approx([0.7, 3.1]), name
    # a folder of an older run, without the instants: from its capture
    (tmp_path / "metrics.json").write_text(json.dumps({"host_stalls": 2}))
    with can.BLFWriter(str(tmp_path / "capture.blf")) as w:
        for f in stalled_truth(Codec()):
            w.on_message_received(f)
    assert main(["plot", str(tmp_path)]) == 0
    stalls = _spans(axes(made[-1])["speed"], "host_stall")
    assert [0.5 * (a + b) for a, b in stalls] == pytest.approx([50 * T_S, 120 * T_S])
    (tmp_path / "capture.blf").unlink()
    # without the instants nor the capture: said, not guessed
    (tmp_path / "metrics.json").write_text(json.dumps({"host_stalls": 2}))
    capsys.readouterr()
    assert main(["plot", str(tmp_path)]) == 0
    assert not _spans(axes(made[-1])["speed"], "host_stall")
    err = capsys.readouterr().err
    assert f"note: 2 host stalls not marked: {tmp_path} has no capture" in err, err
