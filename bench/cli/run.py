"""``bench run``: a scenario between two processes over CAN, recorded and scored."""

from __future__ import annotations

import argparse
import atexit
import gc
import shlex
import sys
import threading
from pathlib import Path
from typing import Any

from bench._errors import EXIT_USER_ERROR, BenchError, error_line
from bench.cli._common import (
    POS_FLOAT,
    add_bus,
    add_engine,
    add_plant_profile,
    add_rt,
    add_scenario_overrides,
    bus_spec,
    estimator_help,
    plant_engine,
    scenario_from_args,
    writable_dir,
)
from bench.scenarios._setup import check_estimator_name, checked_design


def run_node_args(args: argparse.Namespace) -> dict[str, list[str]]:
    """Options ``bench run`` passes on to its plant and controller processes."""
    out: dict[str, list[str]] = {"plant": ["--engine", args.engine], "controller": []}
    if args.engine == "native":  # the controller's engine is else the one it inherits
        out["controller"] += ["--engine", "native"]
    if args.watchdog_ms is not None:
        out["plant"] += ["--watchdog-ms", repr(args.watchdog_ms)]
    if args.rt_priority is not None:
        # the plant keeps the clock: it goes first; the controller one below
        out["plant"] += ["--rt-priority", str(args.rt_priority)]
        out["controller"] += ["--rt-priority", str(max(1, args.rt_priority - 1))]
    return out


def _import_scoring_libraries() -> None:
    """Import what ``run.png`` is drawn with (matplotlib, about a third of a second) and
    what the scoring filters with (scipy.signal, as long: a controller built from a kept
    design imported none of it, :mod:`bench.scenarios._designs`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot
    import scipy.signal  # noqa: F401 (imported for the scoring, in this thread)


class _View:
    """``bench run --monitor``: the live view in a thread of its own while the run goes on."""

    def __init__(self, spec: Any, scenario: Path, title: str) -> None:
        from bench.monitor import run_monitor

        self.stop = threading.Event()
        self.thread = threading.Thread(
            target=run_monitor,
            args=(spec, None, self.stop, title),
            kwargs={"scenario": scenario},
            daemon=True,
        )
        self.thread.start()

    def close(self) -> None:
        """Close the view and restore the terminal before the run's report is printed."""
        self.stop.set()
        self.thread.join(timeout=10.0)


def _start_monitor(spec: Any, scn: Any, est: str, mode: str, out: Path) -> _View:
    from bench.scenarios._schema import write_effective

    out.mkdir(parents=True, exist_ok=True)
    scenario = write_effective(scn, out / "scenario.json")  # the run writes the same file
    return _View(spec, scenario, f"{scn.name} {est} {mode}")


def dut_command(args: argparse.Namespace) -> list[str] | None:
    """``--dut COMMAND`` as an argument list (split as a POSIX shell splits it), or None."""
    if args.dut is None:
        return None
    if args.controller != "external":
        raise BenchError("--dut: only with --controller external (the controller under test)")
    try:
        argv = shlex.split(args.dut)
    except ValueError as e:  # an unclosed quote
        raise BenchError(f"--dut: {args.dut!r}: {e}") from None
    if not argv:
        raise BenchError("--dut: an empty command (give the controller's command line)")
    return argv


def cmd_run(args: argparse.Namespace) -> int:
    from bench.runs._dut import started_dut
    from bench.runs._export import EXPORT_FILES, check_formats, export_signals, parse_formats
    from bench.runs._local import exit_status
    from bench.runs._results import format_metrics, run_warnings
    from bench.runs._run import run_scenario
    from bench.scenarios._setup import countermeasures_text, sample_period

    dut = dut_command(args)
    scn = scenario_from_args(args)
    external = args.controller == "external"
    design = None
    if external:
        if args.estimator:
            raise BenchError(
                "--estimator: not with --controller external (the estimator is the device's)"
            )
        est = "external"
    else:
        est = args.estimator or scn.estimator
        check_estimator_name(est)
        # a misfit (e.g. an injection estimator on a motor without saliency) is one
        # line before any process starts: the controller is built and designed here
        # once, and its node gets the design in the run's plan
        note, design = checked_design(scn, est)
        if note:
            print(note, file=sys.stderr)
    plant_engine(args)
    if args.monitor and not (sys.stdin.isatty() and sys.stdout.isatty() and sys.stderr.isatty()):
        raise BenchError("--monitor: needs a terminal (run bench monitor beside it instead)")
    if external and dut is None and args.interface is None and args.port is None:
        # a controller under test told nothing must find the bus: python-can's own
        # default port (one started with --dut is told the run's own port)
        from bench.wire._bus import UDP_DEFAULT_PORT

        args.port = UDP_DEFAULT_PORT
    out = writable_dir(
        Path(args.out) if args.out else Path("runs") / f"{scn.name}-{est.replace(':', '-')}"
    )
    formats = parse_formats(args.signals_format or [])
    check_formats(formats)  # a missing library costs no run
    spec = bus_spec(args, announce=True)
    who = f"external controller {args.dut_name}" if external and args.dut_name else est
    if external and not args.dut_name:
        who = "an external controller"
    # the heading of the report on stdout: stderr carries progress and errors only
    print(f"run: {scn.name} with {who}, {args.mode}, {spec.describe()} -> {out}", flush=True)
    if args.mode == "realtime":
        from bench.studies._rtcheck import host_warning, load_host_result

        f_sw = 1.0 / sample_period(scn)
        if warn := host_warning(f_sw, args.rt_priority is not None, load_host_result()):
            print(warn, file=sys.stderr, flush=True)
    for name in EXPORT_FILES:  # an earlier run's, which this run would not replace
        (out / name).unlink(missing_ok=True)
    view = _start_monitor(spec, scn, est, args.mode, out) if args.monitor else None
    # matplotlib and scipy.signal are imported while the nodes start and run (the
    # parent mostly waits then), so that the run is scored and drawn at once when it ends
    threading.Thread(target=_import_scoring_libraries, daemon=True).start()
    try:
        with started_dut(dut, spec, scn, out, args.mode, label="--dut") as process:
            res = run_scenario(
                scn,
                est,
                spec=spec,
                out_dir=out,
                mode=args.mode,
                log_format=args.log_format,
                progress=not (args.quiet or args.monitor),
                node_args=run_node_args(args),
                controller=args.controller,
                dut_timeout=args.dut_timeout,
                dut_name=args.dut_name,
                dut_process=process,
                design=design,
            )
    finally:
        if view is not None:
            view.close()
    for role, rep in res.meta.get("node_reports", {}).items():
        for why in ((rep or {}).get("rt") or {}).get("refused", []):
            print(f"{role}: real-time setting refused: {why}", file=sys.stderr)
    # a controller under test's results are headed with its name (meta.json controller_name)
    column = str(res.meta.get("controller_name") or "bench")
    print(format_metrics(res.metrics, scn.paper_result, scn.estimator, est, column))
    print(f"countermeasures: {countermeasures_text(res.meta.get('countermeasures'))}")
    if engines := res.meta.get("node_engines"):  # which loop served each node
        print("node engines: " + ", ".join(f"{r} {e}" for r, e in sorted(engines.items())))
    status, warnings = exit_status(res)
    for line in run_warnings(res.metrics, res.meta, warnings):
        print(line, file=sys.stderr)
    try:
        export_signals(out, formats, title=f"{scn.name} {est}")
    except BenchError as e:  # every file of the run is written: keep them, say what is not
        print(error_line(e), file=sys.stderr)
        status = status or EXIT_USER_ERROR
    names = [
        f"capture{Path(res.capture).suffix}",
        "signals.csv",
        *EXPORT_FILES,
        "signals.md",
        "metrics.json",
        "meta.json",
        "dut.log",  # the controller under test's output, when --dut started it
    ]
    written = [n for n in [*names, "run.png"] if (out / n).is_file()]
    print(f"files: {out}/ ({', '.join(written)})")
    if res.meta.get("interrupted"):
        print("bench: interrupted", file=sys.stderr)
    # every file is written and closed: at the interpreter's exit its collector need not
    # walk the run's objects again (the frames, the figure's; a few tenths of a second)
    atexit.register(gc.freeze)
    # the status says the run is not a scenario result
    return status


def register(sub: Any) -> None:
    p = sub.add_parser("run", help="run a scenario: plant and controller as two processes over CAN")
    p.add_argument(
        "scenario", help="shipped scenario name (wen-5.1, xue-fig13, ...) or a .toml path"
    )
    p.add_argument(
        "--estimator",
        "-e",
        help=estimator_help("default: the scenario's estimator"),
    )
    add_scenario_overrides(p)
    add_plant_profile(p)
    add_bus(p)
    p.add_argument(
        "--controller",
        choices=("bench", "external"),
        default="bench",
        help="external: start no controller; the controller under test is any node on the bus "
        "(docs/PROTOCOL.md)",
    )
    p.add_argument(
        "--dut",
        metavar="COMMAND",
        help="--controller external: the controller under test's command, started for the run "
        "and stopped after it (one string, split as a shell splits it; {interface}, {channel}, "
        "{port}, {mode}, {scenario}, {folder} replaced; its output in dut.log)",
    )
    p.add_argument(
        "--dut-timeout",
        type=POS_FLOAT,
        default=30.0,
        metavar="S",
        help="--controller external: wait this long (s) for its first valid PwmDuty, counted "
        "from the bench nodes being ready",
    )
    p.add_argument(
        "--dut-name", help="--controller external: its name in meta.json and the plot titles"
    )
    p.add_argument("--out", "-o", help="run folder (default runs/SCENARIO-ESTIMATOR)")
    p.add_argument(
        "--log-format", choices=("blf", "asc", "log"), default="blf", help="capture format"
    )
    p.add_argument(
        "--signals-format",
        action="append",
        metavar="FORMAT",
        help="also write the signals as mf4 (ASAM MDF4, needs asammdf: the [mf4] extra) "
        "and/or parquet (needs pyarrow: the [parquet] extra), with units and descriptions; "
        "repeat it or list them (mf4,parquet); signals.csv is always written (default: csv)",
    )
    p.add_argument("--quiet", "-q", action="store_true", help="no progress line")
    p.add_argument(
        "--monitor",
        action="store_true",
        help="show the live view (bench monitor) of this run in place of the progress line",
    )
    p.add_argument(
        "--watchdog-ms",
        type=POS_FLOAT,
        help="real time: the plant's safe state after this long without a valid duty",
    )
    add_engine(p)
    add_rt(p, cpu=False)
    p.set_defaults(func=cmd_run)
