"""``bench replay``: a capture back onto a bus with its recorded timing (absolute deadlines).

``--time wall`` (the default) keeps the capture's timestamps; ``--time sim``
places the frames by their plant step in simulated time
(:func:`bench.captures._replay.sim_timestamps`), for a lockstep run's
capture, whose timestamps carry the slowed pace of the lockstep processes.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

from bench.cli._common import LOG_HELP, add_bus, bus_spec

#: ``--time`` choices: :data:`bench.captures._replay.TIMES` (not imported here: the
#: parser stays light; tests/test_replay_sim_time.py checks they agree).
TIMES = ("wall", "sim")


def _ids(text: str, option: str) -> list[int]:
    from bench.captures._replay import (
        parse_id,
    )

    return [parse_id(t, option) for t in text.split(",") if t.strip()]


def _channels(text: str) -> list[int]:
    from bench._errors import BenchError

    try:
        return [int(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise BenchError(
            f"--channel-filter: expected bus tags like 1 or 1,2, got {text!r}"
        ) from None


def _period(path: Path, scenario: str | None) -> float:
    """The PWM period of a capture (``--scenario``, else its ``meta.json``)."""
    from bench._errors import BenchError
    from bench.captures._read import capture_scenario
    from bench.scenarios._setup import sample_period

    try:
        scn, _ = capture_scenario(path, scenario)
    except BenchError as e:
        raise BenchError(f"--time sim: {e}") from None
    return sample_period(scn)


def _mode_of(path: Path) -> str:
    """The ``mode`` of the run whose ``meta.json`` is beside the capture ("" without one)."""
    import json

    meta = (path if path.is_dir() else path.parent) / "meta.json"
    try:
        return str(json.loads(meta.read_text()).get("mode", ""))
    except (OSError, ValueError, AttributeError):
        return ""


def cmd_replay(args: argparse.Namespace) -> int:
    from bench._errors import BenchError
    from bench.captures._read import (
        incomplete_warning,
        read_capture_counted,
        skipped_warning,
    )
    from bench.captures._replay import (
        CLOCKS,
        open_buses,
        parse_channel_map,
        parse_id_map,
        plan_replay,
        replay_frames,
    )
    from bench.wire._bus import BusSpec

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
    bus_spec(argparse.Namespace(**vars(args)), announce=False, one_process=True)  # check only

    def default_bus() -> BusSpec:
        """The --interface/--channel bus (or the default), for frames of unmapped channels."""
        spec: BusSpec = bus_spec(args, announce=True, one_process=True)
        if args.interface is None and args.port is None and spec.interface == "udp_multicast":
            spec = BusSpec(spec.interface, spec.channel, None)  # python-can's default port
        return spec

    path = Path(args.log)
    if args.scenario is not None and args.time != "sim":
        raise BenchError("--scenario: only --time sim needs a scenario (for its T_s)")
    T_s = _period(path, args.scenario) if args.time == "sim" else 0.0
    got = read_capture_counted(path)
    frames, problem = got.frames, got.problem
    if problem:
        print(incomplete_warning(path, problem, len(frames)), file=sys.stderr)
    if got.lines_skipped:
        print(skipped_warning(path, got.lines_skipped), file=sys.stderr)
    if args.time == "sim" and frames:
        from bench.captures._replay import sim_timestamps, with_timestamps
        from bench.wire._codec import default_codec

        stamps = sim_timestamps(frames, default_codec(), T_s)
        wall = frames[-1].timestamp - frames[0].timestamp
        frames = with_timestamps(frames, stamps)
        print(
            f"replay: --time sim: {max(stamps) - min(stamps):.3f} s of simulated time "
            f"(T_s {T_s:g} s) for {wall:.3f} s of capture",
            file=sys.stderr,
        )
    elif _mode_of(path) == "lockstep":
        print(
            "note: a lockstep run's capture, replayed at the pace it was recorded at "
            "(--time wall, the default); --time sim replays it in simulated time",
            file=sys.stderr,
        )
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
            f"replay: {len(chosen)} of {len(frames)} frames, {span:.3f} s of "
            f"{'simulated time' if args.time == 'sim' else 'capture'} "
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


def register(sub: Any) -> None:
    p = sub.add_parser(
        "replay", help="send a capture onto a bus with its recorded timing (absolute deadlines)"
    )
    p.add_argument("log", help=LOG_HELP)
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
    p.add_argument(
        "--time",
        choices=TIMES,
        default="wall",
        help="wall: the capture's own timestamps (a real bus's or a real-time run's pace, "
        "and what replay has always sent); sim: by the plant step of each frame in simulated "
        "time (step x T_s), for a lockstep run's capture, recorded at the slower pace of the "
        "lockstep processes",
    )
    p.add_argument(
        "--scenario",
        metavar="NAME_OR_FILE",
        help="with --time sim: the scenario that gives T_s (default: the meta.json beside the "
        "capture)",
    )
    p.add_argument("--max-gap", type=float, help="shorten silences longer than this (s)")
    add_bus(p)
    p.set_defaults(func=cmd_replay)
