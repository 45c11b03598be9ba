"""The bench's Python API: a run from Python, for scripts and a user's own CI.

::

    import bench

    run = bench.run("wen-5.1", estimator="tt-dq", duration=1.5)
    run.metrics["theta_err_abs_mean_deg"]   # every key of metrics.json
    run.signals["theta_err_deg"]            # numpy arrays, the columns of signals.csv
    run.exit_status                         # as bench run would exit (0, 3, 4, ...)
    run.save("signals.mf4")                 # ASAM MDF4 (or .parquet, .csv)

Every function here goes through what the command line runs: the scenario
through :func:`bench.scenarios._schema.load_scenario` (and the dotted keys of
``bench sweep --grid``, :mod:`bench.scenarios._dotted`), a run in this
process through :func:`bench.runs._local.run_local` (what the suite's quick
runs take), a run over a bus through :func:`bench.runs._run.run_scenario`
(what ``bench run`` calls), a capture through
:func:`bench.captures._read.analyze_capture` (``bench analyze``), and the
exit status through :func:`bench.runs._local.exit_status`.  A user's
mistake raises the :class:`~bench._errors.BenchError` the command line would
print, with the same line.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import sys
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bench._errors import BenchError, CaptureError, DbcError, InterfaceError, ScenarioError
from bench.wire._bus import bus_of

if TYPE_CHECKING:
    import numpy as np
    import pandas

    from bench.runs._results import RunResult
    from bench.scenarios._schema import Scenario
    from bench.wire._bus import BusSpec
    from controller import DesignRecord

__all__ = [
    "CONTROLLERS",
    "ENGINES",
    "MODES",
    "BenchError",
    "CaptureError",
    "DbcError",
    "InterfaceError",
    "Run",
    "ScenarioError",
    "analyze",
    "estimators",
    "list_scenarios",
    "load_scenario",
    "run",
]

#: ``mode=``: as ``bench run --mode``.
MODES = ("lockstep", "realtime")
#: ``engine=``: as ``bench run --engine`` (``plant_rt.ENGINES``, tested equal).
ENGINES = ("auto", "compiled", "python")
#: ``controller=``: the bench's own controller, or a controller under test on the bus.
CONTROLLERS = ("bench", "external")
#: The transport of a run in this process, as ``Run.transport`` names it.
INPROCESS = "in-process"


@dataclass(eq=False)
class Run:
    """One run's results, as its folder holds them.

    Attributes
    ----------
    metrics : dict
        Every key of ``metrics.json`` (docs/RUNS.md), as the file holds it
        (a metric without a value is None).
    exit_status : int
        What ``bench run`` (or ``bench analyze``) would exit with: 0 done
        (also when every declared fault expectation held, a trip included),
        3 the plant tripped a protection, 4 the estimator lost the rotor
        angle, 5 commands held late or never, 6 a fault expectation missed
        (``[[faults]]`` ``expect``), 7 the plant's current left its flux
        map's checked range (``plant_out_of_range_s``), 130 interrupted
        (DESIGN.md).
    folder : Path or None
        The run folder (``out=``); None when the run was given none (its
        files were read and removed).
    transport : str
        Where the run ran: ``in-process``, or the bus (``socketcan:vcan0``,
        ``udp_multicast:ff15:7079:7468:6f6e:6465:6d6f:6d63:6173 port 44012``).
    warnings : list of str
        The warning lines ``bench run`` prints: real time not kept, recorded frames not
        scored, those of the exit status (a trip, a lost angle, a fault's expectation
        missed) and periods without a row.
    meta : dict
        ``meta.json``: the configuration, presets, gains, seeds, versions.
    """

    metrics: dict[str, Any]
    exit_status: int
    folder: Path | None
    transport: str
    warnings: list[str] = field(default_factory=list)
    meta: dict[str, Any] = field(default_factory=dict, repr=False)
    _signals: dict[str, np.ndarray] | None = field(default=None, repr=False)

    @property
    def signals(self) -> dict[str, np.ndarray]:
        """The columns of ``signals.csv`` (docs/RUNS.md, ``signals.md``), one array each."""
        if self._signals is None:
            self._signals = _read_signals(self.folder)
        return self._signals

    def to_pandas(self) -> pandas.DataFrame:
        """:attr:`signals` as a pandas DataFrame, one row per PWM period (index ``t``, s).

        pandas is an optional extra (``pip install 'can-hil-bench[pandas]'``);
        without it this raises a :class:`~bench._errors.BenchError` that says so.
        """
        try:
            import pandas as pd
        except ImportError:
            raise BenchError(
                "Run.to_pandas(): pandas is not installed "
                "(pip install 'can-hil-bench[pandas]', or use Run.signals: numpy arrays)"
            ) from None
        return pd.DataFrame(self.signals).set_index("t", drop=False)

    def save(self, path: str | os.PathLike[str], format: str | None = None) -> Path:
        """Write :attr:`signals` to ``path`` as ``format``: ``"csv"``, ``"mf4"`` or ``"parquet"``.

        Without ``format``, the suffix of ``path`` names it (``.csv``, ``.mf4``,
        ``.parquet``).  ``mf4`` is ASAM MDF4 (asammdf, the ``[mf4]`` extra),
        ``parquet`` needs pyarrow (the ``[parquet]`` extra); both carry each
        column's unit and description (``signals.md``).  A missing library or
        an unknown format raises a :class:`~bench._errors.BenchError` that
        says so; the run itself is untouched.  Returns ``path``.
        """
        from bench.runs._export import format_of, write_signals

        fmt = format_of(path, format)
        scenario = self.meta.get("scenario")
        name = scenario.get("name", "") if isinstance(scenario, dict) else ""
        title = " ".join(str(x) for x in (name, self.meta.get("estimator", "")) if x)
        return write_signals(self.signals, path, fmt, title=title)

    @property
    def ok(self) -> bool:
        """Whether the run is a result (exit status 0)."""
        return self.exit_status == 0


def _read_signals(folder: Path | None) -> dict[str, np.ndarray]:
    from bench.runs._analysis import read_csv

    if folder is None or not (folder / "signals.csv").is_file():
        raise BenchError(f"run {folder}: no signals.csv (the run recorded no complete period)")
    return read_csv(str(folder / "signals.csv"))


def _run_from(res: RunResult, folder: Path | None, *, analysis: bool = False) -> Run:
    """The :class:`Run` of a finished run or analysis whose files are in ``res.out_dir``."""
    from bench.runs._local import exit_status
    from bench.runs._results import run_warnings

    out = Path(res.out_dir)
    status, lines = exit_status(res, analysis=analysis)
    metrics = json.loads((out / "metrics.json").read_text())
    meta = json.loads((out / "meta.json").read_text())
    if not analysis:  # the lines bench run prints (bench analyze prints its own)
        lines = run_warnings(metrics, meta, lines)
    run = Run(
        metrics=metrics,
        exit_status=status,
        folder=folder,
        transport=str(meta.get("transport", INPROCESS)),
        warnings=lines,
        meta=meta,
    )
    if folder is None and (out / "signals.csv").is_file():
        run._signals = _read_signals(out)  # read before the folder goes
    return run


def load_scenario(
    scenario: str | os.PathLike[str] | Scenario, overrides: Mapping[str, Any] | None = None
) -> Scenario:
    """A scenario: a shipped name (``wen-5.1``), a TOML file, or a :class:`Scenario` as it is.

    ``overrides`` sets dotted keys as ``bench sweep --grid`` takes them
    (``{"controller_model.L_q": 1.2, "inverter.t_dead": 2e-6}``); a wrong
    key or value is the :class:`~bench._errors.ScenarioError` naming it.
    """
    from bench.scenarios._schema import Scenario
    from bench.scenarios._schema import load_scenario as load

    if isinstance(scenario, Scenario):
        if not overrides:
            return scenario
        table = {k: v for k, v in scenario.to_dict().items() if v is not None and k != "source"}
        base: tuple[dict[str, Any], str] = (table, scenario.source)
    else:
        name = os.fspath(scenario)
        if not overrides:
            return load(name)
        from bench.scenarios._dotted import scenario_table

        load(name)  # a missing or wrong file: its own line first
        base = scenario_table(name)
    from bench.scenarios._dotted import scenario_with

    return scenario_with(base, dict(overrides))


def list_scenarios() -> list[str]:
    """The shipped scenarios' names (``bench list``)."""
    from bench.scenarios._schema import SHIPPED

    return list(SHIPPED)


def estimators() -> list[str]:
    """The estimators ``estimator=`` takes by name: the built-in ones, then the installed
    plug-ins (entry-point group ``can_hil_bench.estimators``); a user's own also works as
    ``package.module:factory`` (docs/ESTIMATORS.md)."""
    from controller._registry import ESTIMATOR_NAMES, entry_point_names

    return [*ESTIMATOR_NAMES, *(e for e in entry_point_names() if e not in ESTIMATOR_NAMES)]


def _choice(what: str, value: str, choices: Sequence[str]) -> str:
    if value not in choices:
        raise BenchError(
            f"{what}: invalid choice: {value!r} (choose from {', '.join(map(repr, choices))})"
        )
    return value


@contextlib.contextmanager
def _engine(engine: str) -> Iterator[str]:
    """``engine=`` checked as ``bench run --engine`` checks it, and in force for the
    controllers built meanwhile (:data:`bench.scenarios._setup.ENGINE_ENV`, which node
    processes inherit)."""
    from bench.scenarios._setup import ENGINE_ENV
    from plant_rt import resolve_engine

    _choice("--engine", engine, ENGINES)
    try:
        resolve_engine(engine)
    except ValueError as e:
        raise BenchError(f"--engine {engine}: {e}") from None
    before = os.environ.get(ENGINE_ENV)
    os.environ[ENGINE_ENV] = engine
    try:
        yield engine
    finally:
        if before is None:
            os.environ.pop(ENGINE_ENV, None)
        else:
            os.environ[ENGINE_ENV] = before


def _out_dir(out: str | os.PathLike[str]) -> Path:
    path = Path(out)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise BenchError(
            f"--out {path}: cannot write there ({e.strerror or type(e).__name__})"
        ) from None
    return path


def run(
    scenario: str | os.PathLike[str] | Scenario,
    *,
    estimator: str | None = None,
    plant_profile: str | None = None,
    mode: str = "lockstep",
    duration: float | None = None,
    seed: int | None = None,
    overrides: Mapping[str, Any] | None = None,
    engine: str = "auto",
    out: str | os.PathLike[str] | None = None,
    transport: str | None = None,
    controller: str = "bench",
    dut: Sequence[str] | None = None,
    dut_timeout: float = 30.0,
    dut_name: str | None = None,
) -> Run:
    """Run a scenario, score it, and return its :class:`Run`: ``bench run`` from Python.

    Parameters
    ----------
    scenario : str, path or Scenario
        A shipped name (:func:`list_scenarios`), a TOML file, or a scenario
        from :func:`load_scenario`.
    estimator : str, optional
        As ``--estimator`` (:func:`estimators`, or ``package.module:factory``);
        default the scenario's.
    plant_profile : {"ideal", "drive"}, optional
        As ``--plant-profile``; default the scenario's.
    mode : {"lockstep", "realtime"}
        As ``--mode``. Real time needs a bus: without ``transport`` it runs
        on ``bench run``'s default bus.
    duration : float, optional
        Simulated seconds (as ``--duration``).
    seed : int, optional
        Seed of noise and jitter (as ``--seed``).
    overrides : dict, optional
        Dotted scenario keys, as ``bench sweep --grid`` takes them
        (``{"controller_model.L_q": 1.2}``).
    engine : {"auto", "compiled", "python"}
        As ``--engine``.
    out : path, optional
        The run folder (every file of ``bench run --out``). Without it the
        files are written to a temporary folder, read, and removed (no
        ``run.png`` for an in-process run then).
    transport : str, optional
        None: the bench's controller runs in this process, lockstep (the
        two-process trace at in-process speed: the same DBC frames between
        the same nodes, :func:`bench.nodes._loops.run_inprocess`).
        ``"udp_multicast"``, ``"socketcan:vcan0"``, ``"NAME:CHANNEL"``: the
        nodes run as processes over that bus, as ``bench run`` runs them.
    controller : {"bench", "external"}
        ``"external"``: no controller of the bench's; the controller under
        test is ``dut`` (or any node on the bus), as ``bench run
        --controller external``: without ``dut``, udp_multicast without a
        port is python-can's default port, where a device told nothing finds it.
    dut : list of str, optional
        With ``controller="external"``: the command of the controller under
        test, started for the run and stopped after it (its output in
        ``dut.log`` of the run folder).  ``{interface}``, ``{channel}``,
        ``{port}``, ``{mode}`` (``lockstep`` or ``realtime``), ``{scenario}``
        (the run's effective ``scenario.json``) and ``{folder}`` in its
        arguments are replaced; a process that ends before its first valid
        duty ends the run at once (its exit status and ``dut.log`` named); its environment
        carries the bus as python-can reads it (``CAN_INTERFACE``,
        ``CAN_CHANNEL``, ``CAN_CONFIG``), so ``can.Bus()`` finds it.
    dut_timeout : float
        Seconds to wait for its first valid duty (``--dut-timeout``).
    dut_name : str, optional
        Its name in ``meta.json`` and the plot titles (``--dut-name``).

    Raises
    ------
    BenchError
        A user's mistake or a run that failed, with the line ``bench run``
        prints (its subclasses :class:`~bench._errors.ScenarioError`,
        :class:`~bench._errors.InterfaceError`, ...).
    """
    from bench.scenarios._setup import check_estimator_name, checked_design

    _choice("--mode", mode, MODES)
    _choice("--controller", controller, CONTROLLERS)
    if duration is not None and not duration > 0:
        raise BenchError(f"--duration must be > 0, got {duration}")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
        raise BenchError(f"--seed: expected a whole number >= 0, got {seed!r}")
    if plant_profile is not None:
        from plant_rt import PROFILE_NAMES

        _choice("--plant-profile", plant_profile, PROFILE_NAMES)
    external = controller == "external"
    if dut is not None and not external:
        raise BenchError('dut: only with controller="external" (the controller under test)')
    if isinstance(dut, str):
        raise BenchError("dut: a command as a list of arguments, e.g. ['python', 'ctl.py']")
    scn = load_scenario(scenario, overrides).with_overrides(
        duration=duration, seed=seed, plant_profile=plant_profile
    )
    if external:
        if estimator:
            raise BenchError(
                "--estimator: not with --controller external (the estimator is the device's)"
            )
        est = "external"
        design = None
    else:
        est = estimator or scn.estimator
        check_estimator_name(est)
        # designed once, here: the controller node gets it in the run's plan (as bench run)
        note, design = checked_design(scn, est)
        if note:
            print(note, file=sys.stderr)
    local = transport is None and not external and mode == "lockstep"
    spec = None if local else bus_of(transport, known_port=external and not dut)
    folder = _out_dir(out) if out is not None else None
    with _engine(engine), _folder(folder) as where:
        if spec is None:
            from bench.runs._local import run_local

            res = run_local(scn, est, where, engine=engine, plots=folder is not None)
        else:
            res = _run_on_bus(
                scn, est, spec, where, mode, engine, dut, dut_timeout, dut_name, design
            )
        return _run_from(res, folder)


@contextlib.contextmanager
def _folder(folder: Path | None) -> Iterator[Path]:
    """``folder``, or a temporary one removed afterwards."""
    if folder is not None:
        yield folder
        return
    tmp = Path(tempfile.mkdtemp(prefix="bench-run-"))
    try:
        yield tmp
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _run_on_bus(
    scn: Scenario,
    est: str,
    spec: BusSpec,
    folder: Path,
    mode: str,
    engine: str,
    dut: Sequence[str] | None,
    dut_timeout: float,
    dut_name: str | None,
    design: DesignRecord | None,
) -> RunResult:
    """The run as ``bench run`` runs it: nodes as processes on ``spec``'s bus, the
    controller node built from ``design`` (the one :func:`run` made)."""
    from bench.runs._run import run_scenario

    external = est == "external"
    kw: dict[str, Any] = {}
    if external:
        kw = {"controller": "external", "dut_timeout": dut_timeout, "dut_name": dut_name}
    from bench.runs._dut import started_dut

    with started_dut(dut, spec, scn, folder, mode) as process:
        return run_scenario(
            scn,
            est,
            spec=spec,
            out_dir=folder,
            mode=mode,
            progress=False,
            node_args={"plant": ["--engine", engine], "controller": []},
            dut_process=process,
            design=design,
            **kw,
        )


def analyze(
    capture: str | os.PathLike[str],
    *,
    scenario: str | None = None,
    out: str | os.PathLike[str] | None = None,
    duration: float | None = None,
    dut_name: str | None = None,
    plots: bool = True,
) -> Run:
    """The :class:`Run` of a capture file or run folder: ``bench analyze`` from Python.

    The files are written to ``out`` (default: beside the capture, as
    ``bench analyze`` writes them); ``scenario`` defaults to the one in the
    ``meta.json`` beside the capture.  Its ``exit_status`` is ``bench
    analyze``'s.
    """
    from bench.captures._read import analyze_capture

    out_dir = _out_dir(out) if out is not None else None
    res = analyze_capture(
        Path(capture),
        out_dir=out_dir,
        scenario=scenario,
        plots=plots,
        duration=duration,
        dut_name=dut_name,
    )
    return _run_from(res, Path(res.out_dir), analysis=True)
