"""``bench replay`` and ``bench rerun``: a capture back onto a bus, or through an estimator.

``bench analyze`` (the third way to use a capture) is registered in
:mod:`bench.cli`; the work of all three is in :mod:`bench._replay` and
:mod:`bench._rerun`.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

_LOG_HELP = "a capture python-can reads (.blf, .asc, .log, .trc, .csv, .mf4) or a run folder"


def _ids(text: str, option: str) -> list[int]:
    from bench._replay import parse_id

    return [parse_id(t, option) for t in text.split(",") if t.strip()]


def _channels(text: str) -> list[int]:
    from bench._errors import BenchError

    try:
        return [int(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise BenchError(
            f"--channel-filter: expected bus tags like 1 or 1,2, got {text!r}"
        ) from None


def cmd_replay(args: argparse.Namespace) -> int:
    from bench._errors import BenchError
    from bench._replay import (
        CLOCKS,
        incomplete_warning,
        open_buses,
        parse_channel_map,
        parse_id_map,
        plan_replay,
        read_capture,
        replay_frames,
    )
    from bench._run import BusSpec
    from bench.cli import _spec

    # every option first: a mistake is reported before the capture is read or a bus opened
    if not (args.speed > 0 and math.isfinite(args.speed)):
        raise BenchError(f"--speed must be > 0, got {args.speed:g}")
    if args.loop < 0:
        raise BenchError(f"--loop must be >= 0 (0 = until interrupted), got {args.loop}")
    if args.max_gap is not None and not args.max_gap > 0:
        raise BenchError(f"--max-gap must be > 0, got {args.max_gap:g}")
    if args.clock not in CLOCKS:
        raise BenchError(f"--clock: unknown {args.clock!r} (known: {', '.join(CLOCKS)})")
    ids = None if args.id is None else [i for s in args.id for i in _ids(s, "--id")]
    exclude = [i for s in args.exclude_id or [] for i in _ids(s, "--exclude-id")]
    channels = (
        None
        if args.channel_filter is None
        else [c for s in args.channel_filter for c in _channels(s)]
    )
    id_map = parse_id_map(args.map or [])
    channel_map = parse_channel_map(
        args.channel_map or [], bitrate=args.bitrate, data_bitrate=args.data_bitrate
    )
    _spec(argparse.Namespace(**vars(args)), announce=False, one_process=True)  # check only

    def default_bus() -> BusSpec:
        """The --interface/--channel bus (or the default), for frames of unmapped channels."""
        spec: BusSpec = _spec(args, announce=True, one_process=True)
        if args.interface is None and args.port is None and spec.interface == "udp_multicast":
            spec = BusSpec(spec.interface, spec.channel, None)  # python-can's default port
        return spec

    path = Path(args.log)
    frames, problem = read_capture(path)
    if problem:
        print(incomplete_warning(path, problem, len(frames)), file=sys.stderr)
    plan = plan_replay(
        frames,
        default=default_bus,
        channel_map=channel_map,
        ids=ids,
        exclude_ids=exclude,
        channels=channels,
        id_map=id_map,
    )
    chosen = plan.frames
    if not chosen:
        raise BenchError(f"{args.log}: no frame passed the filters ({len(frames)} in the capture)")
    span = chosen[-1].timestamp - chosen[0].timestamp
    # a missing interface is reported before anything is sent; every bus is shut down after
    with open_buses(plan.buses) as buses:
        print(
            f"replay: {len(chosen)} of {len(frames)} frames, {span:.3f} s of capture "
            f"at x{args.speed:g} -> {plan.describe()}",
            file=sys.stderr,
        )
        res = replay_frames(
            buses,
            chosen,
            speed=args.speed,
            loops=args.loop,
            clock=args.clock,
            max_gap_s=args.max_gap,
            route=plan.route,
            bus_names=[b.describe() for b in plan.buses],
        )
    print(res.summary())
    lag = res.lag_warning()
    if lag:
        print(lag, file=sys.stderr)
    return 0


def _files_line(out_dir: Path, names: list[str]) -> str:
    return f"files: {out_dir}/ ({', '.join(names)})"


def cmd_analyze(args: argparse.Namespace) -> int:
    """``bench analyze``: the metrics table with the paper's column, and the files written."""
    from bench._replay import analyze_capture
    from bench._run import format_metrics

    plots = not getattr(args, "no_plots", False)
    res = analyze_capture(
        Path(args.log),
        out_dir=Path(args.out) if args.out else None,
        scenario=args.scenario,
        plots=plots,
    )
    scn = res.meta.get("scenario", {})
    print(format_metrics(res.metrics, scn.get("paper_result"), scn.get("estimator")))
    names = ["signals.csv", "metrics.json", "meta.json"] + (["run.png"] if plots else [])
    print(_files_line(res.out_dir, names))
    return 0


def cmd_rerun(args: argparse.Namespace) -> int:
    from bench._rerun import rerun_capture

    res = rerun_capture(
        Path(args.log),
        args.estimator,
        scenario=args.scenario,
        out_dir=Path(args.out) if args.out else None,
        plots=not args.no_plots,
    )
    from bench._run import format_metrics

    r: dict[str, Any] = res.report
    est = r["estimate"]
    print(format_metrics(res.metrics, res.paper_result, res.paper_method))
    if r["recorded_metrics"] is not None:
        rm = r["recorded_metrics"]
        print(
            f"recorded ({r['recorded_estimator'] or '?'}): theta_err max {rm['theta_err_max_deg']:.3f}"
            f" min {rm['theta_err_min_deg']:.3f} rms {rm['theta_err_rms_deg']:.3f} deg"
        )
    print(
        f"estimate vs recorded: {est['steps_identical']}/{est['steps_compared']} steps identical"
        + (" (bit for bit)" if est["reproduces_recorded_bit_for_bit"] else "")
    )
    print(f"note: {r['comparison']}")
    print(_files_line(res.out_dir, res.files))
    return 0


def register(sub: Any) -> None:
    from bench.cli import _add_bus

    p = sub.add_parser(
        "replay", help="send a capture onto a bus with its recorded timing (absolute deadlines)"
    )
    p.add_argument("log", help=_LOG_HELP)
    p.add_argument("--speed", type=float, default=1.0, help="time compression (2 = twice as fast)")
    p.add_argument("--loop", type=int, default=1, help="times to send the capture (0 = forever)")
    p.add_argument(
        "--id", action="append", help="only these IDs (0x11,0x100; repeatable)", metavar="IDS"
    )
    p.add_argument("--exclude-id", action="append", help="drop these IDs", metavar="IDS")
    p.add_argument(
        "--channel-filter",
        action="append",
        metavar="TAGS",
        help="only frames recorded on these buses (1 = plant side, 2 = controller side)",
    )
    p.add_argument(
        "--map", action="append", metavar="OLD=NEW", help="rename an ID (0x10=0x210; repeatable)"
    )
    p.add_argument(
        "--channel-map",
        action="append",
        metavar="CH=INTERFACE:CHANNEL",
        help=(
            "send the frames of capture channel CH (as python-can reads it: 1, 2, can1) on "
            "this bus instead (repeatable; 2=socketcan:can1, 1=virtual:a); for udp_multicast "
            "CHANNEL is GROUP, GROUP:PORT, :PORT or [IPv6-GROUP]:PORT; frames of channels not "
            "mapped go to the --interface/--channel bus (or the default transport)"
        ),
    )
    p.add_argument(
        "--clock",
        choices=("deadline", "messagesync"),
        default="deadline",
        help="deadline: sleep then spin to each absolute deadline; messagesync: python-can's",
    )
    p.add_argument("--max-gap", type=float, help="shorten silences longer than this (s)")
    _add_bus(p)
    p.set_defaults(func=cmd_replay)

    p = sub.add_parser(
        "rerun", help="feed a capture's samples into an estimator offline and score it"
    )
    p.add_argument("log", help=_LOG_HELP)
    p.add_argument(
        "--estimator",
        "-e",
        required=True,
        help="sfhf, tt-ab, tt-dq, square-wave, square-wave-nocic, sensored",
    )
    p.add_argument("--scenario", help="scenario of the capture (default: from meta.json beside it)")
    p.add_argument(
        "--out", "-o", help="output folder (default: rerun-ESTIMATOR beside the capture)"
    )
    p.add_argument("--no-plots", action="store_true", help="skip run.png")
    p.set_defaults(func=cmd_rerun)
