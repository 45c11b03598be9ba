"""``bench plot``: a run folder's figure again, or a custom one from its ``signals.csv``."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from bench._errors import BenchError
from bench.cli._common import NONNEG_FLOAT


def _json(path: Path) -> dict[str, Any]:
    if not path.is_file():
        return {}
    data = json.loads(path.read_text())
    return data if isinstance(data, dict) else {}


def _scenario(run: Path, meta: dict[str, Any]) -> Any:
    """The run's scenario (``scenario.json``, else ``meta.json``'s), or None."""
    from bench._errors import ScenarioError
    from bench.scenarios._schema import load_scenario, scenario_from_dict

    try:
        if (run / "scenario.json").is_file():
            return load_scenario(str(run / "scenario.json"))
        if isinstance(meta.get("scenario"), dict):
            return scenario_from_dict(meta["scenario"], str(run / "meta.json"))
    except ScenarioError:  # an unreadable scenario: the figure without the fundamental
        return None
    return None


def _pole_pairs(scenario: Any) -> int | None:
    if scenario is None:
        return None
    from bench.scenarios._setup import get_preset

    return int(get_preset(scenario).motor.n_p)


def _stalls(run: Path, meta: dict[str, Any], metrics: dict[str, Any], T_s: float) -> Any:
    """Where the run's host stalls were (s): ``metrics.json``'s ``host_stall_at_s``, else
    (a folder written before that key) the gaps of the plant's frames in its capture;
    None, with a note, when the folder has neither."""
    if not metrics.get("host_stalls"):
        return None
    if isinstance(at := metrics.get("host_stall_at_s"), list):
        return [float(s) for s in at]
    capture = run / str(meta.get("capture") or "")
    if not (meta.get("capture") and capture.is_file()):
        print(
            f"note: {int(metrics['host_stalls'])} host stalls not marked: {run} has no capture "
            "and its metrics.json no host_stall_at_s",
            file=sys.stderr,
        )
        return None
    from bench.captures._read import read_capture
    from bench.runs._results import host_stall_times
    from bench.wire._codec import Codec

    frames, _ = read_capture(capture)
    return host_stall_times(frames, Codec(), T_s)


def cmd_plot(args: argparse.Namespace) -> int:
    from bench.runs._analysis import COLUMNS, read_csv
    from bench.runs._plots import controller_label, plot_run, plot_signals

    run = Path(args.run_dir)
    csv = run / "signals.csv"
    if not csv.is_file():
        raise BenchError(f"{run}: no signals.csv (a run folder of bench run or bench analyze)")
    if args.t_from is not None and args.t_to is not None and args.t_to <= args.t_from:
        raise BenchError(f"--to {args.t_to} must be after --from {args.t_from}")
    table = read_csv(str(csv))
    units = dict(COLUMNS)
    meta, metrics = _json(run / "meta.json"), _json(run / "metrics.json")
    scn = meta.get("scenario") or {}
    title = f"{scn.get('name', run.name)} / {controller_label(meta)}"
    sel = table["t"] >= (args.t_from if args.t_from is not None else -1e300)
    if args.t_to is not None:
        sel &= table["t"] <= args.t_to
    t_all = table["t"]
    T_s = float(meta.get("T_s") or (t_all[1] - t_all[0] if len(t_all) > 1 else 1.0))
    recorded_end = float(t_all[-1]) + T_s if len(t_all) else 0.0
    plant_steps = ((meta.get("node_reports") or {}).get("plant") or {}).get("steps")
    run_end = max(recorded_end, int(plant_steps or 0) * T_s)
    if not sel.any():
        lost = (
            f": the recorded data end at {recorded_end:.3f} s, the plant ran to "
            f"{run_end:.3f} s (the recorder lost the rest)"
            if run_end > recorded_end + 0.5 * T_s
            and args.t_from is not None
            and args.t_from >= recorded_end
            else ""
        )
        raise BenchError(f"{csv}: no rows between --from and --to{lost}")
    if args.signals:
        names = [s.strip() for s in args.signals.split(",") if s.strip()]
        unknown = [s for s in names if s not in table]
        if unknown or not names:
            raise BenchError(
                f"--signals: unknown column {', '.join(unknown) or '(none given)'} "
                f"(columns of signals.csv: {', '.join(table)})"
            )
        out = Path(args.out) if args.out else run / "plot.png"
        plot_signals(table, names, out, t_from=args.t_from, t_to=args.t_to, title=title,
                     units=units)  # fmt: skip
    else:
        from bench.runs._results import fundamental_corner_hz

        part = {k: v[sel] for k, v in table.items()}
        f_c = None
        scenario = _scenario(run, meta)
        if scenario is not None:
            # the controller as the run's node reported it (none: built from the scenario)
            design = ((meta.get("node_reports") or {}).get("controller") or {}).get("design")
            f_c = fundamental_corner_hz(scenario, str(meta.get("estimator", "")), part, design)
        out = Path(args.out) if args.out else run / "run.png"
        t = part["t"]
        window = (
            float(t[0]) if args.t_from is None else float(args.t_from),
            run_end if args.t_to is None else min(float(args.t_to), run_end),
        )
        stalls = _stalls(run, meta, metrics, T_s)
        windowed = args.t_from is not None or args.t_to is not None
        plot_run(
            part,
            out.parent,
            title=title,
            meta=meta,
            metrics=metrics,  # the whole run's; a window's are recomputed from its rows
            scored_from_s=float(meta.get("scored_from_s", scn.get("score_from_s", 0.0)) or 0.0),
            f_split_hz=f_c,
            n_p=_pole_pairs(scenario),
            window=window if windowed else None,
            name=out.name,
            stalls=stalls,
            recorded_end_s=recorded_end,
        )
    print(f"plot: {out}")
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser(
        "plot",
        help="draw a run folder's run.png again, or chosen columns of its signals.csv",
        description="Without --signals: run.png again (over --from/--to when given). With "
        "--signals: one panel per column of signals.csv (see signals.md in the run folder).",
    )
    p.add_argument("run_dir", help="run folder holding signals.csv (and meta.json, metrics.json)")
    p.add_argument("--signals", "-s", help="comma-separated columns, e.g. theta_e,theta_hat,i_d")
    p.add_argument("--from", dest="t_from", type=NONNEG_FLOAT, metavar="S",
                   help="start of the time window, s (default: the run's start)")  # fmt: skip
    p.add_argument("--to", dest="t_to", type=NONNEG_FLOAT, metavar="S",
                   help="end of the time window, s (default: the run's end)")  # fmt: skip
    p.add_argument("--out", "-o",
                   help="PNG to write (default RUN_DIR/plot.png with --signals, else RUN_DIR/run.png)")  # fmt: skip
    p.set_defaults(func=cmd_plot)
