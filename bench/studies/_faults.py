"""``bench suite faults``: what each shipped estimator's drive does for each fault kind.

Every fault kind a lockstep run applies (:data:`bench.scenarios._faults.KINDS`)
is inserted once, at :data:`AT_S`, into a short in-process run
(:data:`DURATION_S`) of the ``drive`` plant, for every shipped estimator
(``controller.ESTIMATOR_NAMES``): the square-wave family from ``xue-fig13``
(1 kHz), every other estimator from ``wen-5.1`` (10 kHz), each from
standstill with the scenario's start-up. The controller runs its
supervision (:mod:`controller._supervision`; on in every scenario with a
``[[faults]]`` timeline). Each run's ``metrics.json`` ``faults`` entry is
classified (:func:`outcome`):

- ``detected``: the controller reported a detection in its mode
  (``detected_by`` ``controller_*``) before any plant protection tripped;
- ``tripped``: a plant protection tripped first (``watchdog``, ``over_voltage``, ...);
- ``ridden through``: nothing detected it and the estimator kept the rotor angle;
- ``lock lost``: nothing detected it and the estimator lost the angle;
- ``failed``: the run did not complete (its one line is kept): a result, not a crash.

The catalogue (:func:`catalogue`) gives each kind one setting a drive must
survive or see: a DC-link sag to 60 % and a surge to 118 % of the nominal
voltage (the plant's own trip is at 120 %), 30 % demagnetisation, 50 %
resistance rise, sensor faults on phase a (the wire carries ``i_a`` and
``i_b``: the controller computes ``i_c``), a 50 ms burst of lost or corrupt
duties, of lost samples and of silence (longer than the plant's duty watchdog;
lockstep applies the sample side under its retransmission rules,
:mod:`bench.nodes._fault_bus`), 5 periods of extra duty delay, a babbling node,
phase a open and phase a's upper switch open (the phase of the sensor faults, so
that the table sets an open phase beside a lost sensor: the controller reads both
as a phase without current).

Where the controller runs (:data:`CONTROLLERS`, each record's ``controller``):

- ``in-process``: plant and controller nodes in the study's process
  (:func:`bench.runs._local.run_local`), the whole catalogue for every estimator;
- ``python``: the Python controller node (with the compiled core) and ``native``:
  the native controller node (:mod:`bench.nodes.native.controller_node`), each a
  process beside the Python plant node over udp_multicast, as ``bench run`` runs them
  (:func:`bench.runs._run.run_scenario`);
- ``external``: no controller of the bench's; the controller under test is the
  repository's example external controller (:data:`EXTERNAL_CONTROLLER`, a sensored
  drive written from docs/PROTOCOL.md), scored as ``bench run --controller external``
  scores it. It has no supervision of its own: only the plant's protections detect.

A process run costs several times the wall time of an in-process one (square-wave,
1.2 s: 31 s against 7 s measured on a loaded 2-core host), so the process
variants run a reduced catalogue by default (:data:`PROCESS_CATALOGUES`): the bus kinds
(:data:`BUS_KINDS`, where the transport matters) with :data:`PROCESS_ESTIMATOR` only.
``full`` runs the whole catalogue for every estimator (``--process-catalogue full``).

The JSON (``faults.json``) is the result; :func:`render_doc` writes
docs/FAULTS.md from it and :func:`readme_block` the README's block.
"""

from __future__ import annotations

import contextlib
import json
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from bench._errors import BenchError

#: Simulated seconds of every run, and when its fault starts (s).
DURATION_S = 1.5
AT_S = 0.5
#: Length of the bus bursts (drop, corrupt) (s): longer than the plant's duty watchdog.
BURST_S = 0.05
#: The plant profile of the study.
PLANT_PROFILE = "drive"
#: The outcomes, in the order the headline counts them.
OUTCOMES = ("detected", "tripped", "ridden through", "lock lost", "failed")
#: Where the controller runs (module docstring), in the order of the tables.
CONTROLLERS = ("in-process", "python", "native", "external")
IN_PROCESS = CONTROLLERS[0]
EXTERNAL = CONTROLLERS[3]
#: The ``--engine`` of the controller process per variant: the Python node steps the
#: compiled core (the in-process runs' engine), ``native`` asks for the native node.
CONTROLLER_ENGINE = {"python": "compiled", "native": "native"}
#: The kinds whose frames cross the bus (the transport matters): the reduced catalogue.
BUS_KINDS = ("drop", "delay", "corrupt", "silence", "babble")
#: The one estimator of the reduced catalogue of the python and native variants: the
#: wen-5.1 family's reference estimator.
PROCESS_ESTIMATOR = "tt-dq"
#: What the process variants run: ``bus`` (default) or ``full`` (module docstring).
PROCESS_CATALOGUES = ("bus", "full")
#: The repository's example external controller (the one of tests/test_external_controller.py).
EXTERNAL_CONTROLLER = Path(__file__).resolve().parents[2] / "tests" / "ext_controller.py"
#: Its name in ``meta.json`` and in the tables.
EXTERNAL_NAME = "ext_controller.py"
#: The scenario the external controller is studied from (a sensored drive at wen-5.1's speed).
EXTERNAL_SCENARIO = "wen-5.1"
#: Wait for the external controller's first valid duty (s): ``bench run``'s default.
DUT_TIMEOUT_S = 30.0

README_BEGIN = "<!-- fault-study:begin (bench suite faults --readme) -->"
README_END = "<!-- fault-study:end -->"


def scenario_for(estimator: str) -> str:
    """The scenario an estimator is studied from (module docstring)."""
    from controller._registry import injection_family

    if estimator == EXTERNAL:
        return EXTERNAL_SCENARIO
    return "xue-fig13" if injection_family(estimator) == "square" else "wen-5.1"


def catalogue(u_dc: float) -> list[tuple[str, dict[str, Any]]]:
    """``(label, [[faults]] entry)`` of every case, for a drive of nominal DC link ``u_dc`` (V).

    One case a kind (two for ``dc_link_step``: a sag and a surge; two for ``drop``: of
    the duties and of the samples), in the order of
    :data:`bench.scenarios._faults.KINDS`; every
    entry starts at :data:`AT_S` and lasts to the end of the run, but the bus
    bursts (:data:`BURST_S`).
    """
    at: dict[str, Any] = {"at_s": AT_S}
    burst = {"at_s": AT_S, "duration_s": BURST_S}
    return [
        ("open_phase: a", {**at, "kind": "open_phase", "phase": "a"}),
        (
            "open_switch: a upper",
            {**at, "kind": "open_switch", "phase": "a", "device": "upper"},
        ),
        ("dc_link_step: sag to 60 %", {**at, "kind": "dc_link_step", "u_dc_v": 0.6 * u_dc}),
        ("dc_link_step: surge to 118 %", {**at, "kind": "dc_link_step", "u_dc_v": 1.18 * u_dc}),
        ("demagnetisation: psi_f x0.7", {**at, "kind": "demagnetisation", "psi_f_factor": 0.7}),
        ("resistance_drift: R_s x1.5", {**at, "kind": "resistance_drift", "R_s_factor": 1.5}),
        ("current_offset: a +1 A", {**at, "kind": "current_offset", "phase": "a", "a": 1.0}),
        ("current_gain: a x0.5", {**at, "kind": "current_gain", "phase": "a", "factor": 0.5}),
        ("current_stuck: a", {**at, "kind": "current_stuck", "phase": "a"}),
        ("current_lost: a", {**at, "kind": "current_lost", "phase": "a"}),
        (
            "dc_voltage_offset: -30 % of u_dc",
            {**at, "kind": "dc_voltage_offset", "v": -0.3 * u_dc},
        ),
        ("position_sensor_lost", {**at, "kind": "position_sensor_lost"}),
        (
            f"drop: PwmDuty for {1e3 * BURST_S:g} ms",
            {**burst, "kind": "drop", "message": "PwmDuty", "prob": 1.0},
        ),
        (
            f"drop: PhaseSamples for {1e3 * BURST_S:g} ms",
            {**burst, "kind": "drop", "message": "PhaseSamples", "prob": 1.0},
        ),
        ("delay: PwmDuty +5 periods", {**at, "kind": "delay", "message": "PwmDuty", "steps": 5}),
        (
            f"corrupt: PwmDuty for {1e3 * BURST_S:g} ms",
            {**burst, "kind": "corrupt", "message": "PwmDuty"},
        ),
        (f"silence for {1e3 * BURST_S:g} ms", {**burst, "kind": "silence"}),
        ("babble: 100 Hz", {**at, "kind": "babble", "rate_hz": 100.0}),
    ]


def not_run() -> dict[str, str]:
    """The kinds the study cannot run, with why (module docstring)."""
    from bench.scenarios._faults import KINDS

    return {k.name: str(k.refused) for k in KINDS.values() if k.refused}


def _toml_value(v: Any) -> str:
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, bool):
        return "true" if v else "false"
    return repr(v)


def case_toml(scenario: str, fault: dict[str, Any], duration: float) -> str:
    """The scenario file of one case: ``scenario`` with one ``[[faults]]`` entry."""
    lines = [
        f"extends = {json.dumps(scenario)}",
        f"duration = {duration!r}",
        f"plant_profile = {json.dumps(PLANT_PROFILE)}",
        "",
        "[[faults]]",
    ]
    lines += [f"{k} = {_toml_value(v)}" for k, v in fault.items()]
    return "\n".join(lines) + "\n"


def run_case(
    estimator: str,
    label: str,
    fault: dict[str, Any],
    duration: float,
    controller: str = IN_PROCESS,
) -> dict[str, Any]:
    """One run of the study: its ``faults`` entry, exit status and :func:`outcome`.

    ``controller`` is where the controller runs (:data:`CONTROLLERS`; ``external``
    ignores ``estimator``). Never raises for a run that fails: the record says
    ``failed`` with its one line.
    """
    from bench.runs._local import exit_status
    from bench.scenarios._schema import load_scenario

    if controller == EXTERNAL:
        estimator = EXTERNAL
    scenario = scenario_for(estimator)
    rec: dict[str, Any] = {
        "estimator": estimator,
        "controller": controller,
        "fault": label,
        "kind": fault["kind"],
    }
    try:
        with tempfile.TemporaryDirectory() as d:
            path = Path(d) / "case.toml"
            path.write_text(case_toml(scenario, fault, duration), encoding="utf-8")
            scn = load_scenario(str(path))
            res = _run(scn, estimator, controller, path, Path(d) / "run")
            status = exit_status(res)[0]
            metrics = json.loads((Path(d) / "run" / "metrics.json").read_text())
        f = metrics["faults"][0] if metrics.get("faults") else {}
        rec.update(
            exit_status=status,
            detected_by=f.get("detected_by"),
            reaction_ms=f.get("reaction_ms"),
            lock_kept=f.get("lock_kept"),
            theta_err_abs_max_deg=f.get("theta_err_abs_max_deg"),
            error=None,
        )
        if controller != IN_PROCESS:
            # the node that served: a native node that could not serve leaves the Python one
            rec["node_engine"] = (res.meta.get("node_engines") or {}).get("controller")
    except Exception as e:  # a failed case is a result of the study, never its end
        rec.update(
            exit_status=None,
            detected_by=None,
            reaction_ms=None,
            lock_kept=None,
            theta_err_abs_max_deg=None,
            error=(str(e).strip().splitlines() or [type(e).__name__])[0],
        )
    rec["outcome"] = outcome(rec)
    return rec


def _run(scn: Any, estimator: str, controller: str, path: Path, out: Path) -> Any:
    """The run of one case: in this process, or the controller as a process over CAN."""
    from bench.runs._local import run_local

    if controller == IN_PROCESS:
        return run_local(scn, estimator, out, plots=False)
    from bench.runs._run import run_scenario
    from bench.wire._bus import bus_of

    spec = bus_of("udp_multicast")  # a port of the run's own: parallel cases never meet
    if controller == EXTERNAL:
        with _external_controller(path, spec, out.parent):
            return run_scenario(
                scn,
                EXTERNAL,
                spec=spec,
                out_dir=out,
                progress=False,
                controller=EXTERNAL,
                dut_timeout=DUT_TIMEOUT_S,
                dut_name=EXTERNAL_NAME,
            )
    return run_scenario(
        scn,
        estimator,
        spec=spec,
        out_dir=out,
        progress=False,
        node_args={"controller": ["--engine", CONTROLLER_ENGINE[controller]]},
    )


@contextlib.contextmanager
def _external_controller(scenario: Path, spec: Any, folder: Path) -> Iterator[None]:
    """:data:`EXTERNAL_CONTROLLER` on ``spec``'s bus, listening, for the run.

    It reads the scenario's motor and PWM rate from ``bench show SCENARIO --json``, as
    tests/test_external_controller.py starts it.
    """
    if not EXTERNAL_CONTROLLER.is_file():
        raise BenchError(f"{EXTERNAL_CONTROLLER}: the example external controller is missing")
    show = folder / "show.json"
    out = subprocess.run(
        [sys.executable, "-m", "bench", "show", str(scenario), "--json"],
        capture_output=True,
        text=True,
        check=False,
    )
    if out.returncode != 0:
        raise BenchError(f"bench show {scenario}: {out.stderr.strip() or out.returncode}")
    show.write_text(out.stdout, encoding="utf-8")
    argv = [sys.executable, str(EXTERNAL_CONTROLLER), "--show", str(show)]
    argv += ["-i", spec.interface, "-c", spec.channel, "--idle-s", "30"]
    argv += ["-p", str(spec.port)] if spec.port is not None else []
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline().strip()
        if line != "READY":
            raise BenchError(f"{EXTERNAL_NAME}: did not start (said {line!r})")
        yield
    finally:
        proc.kill()
        proc.wait()


def outcome(rec: dict[str, Any]) -> str:
    """One of :data:`OUTCOMES` for a record (module docstring)."""
    if rec.get("error"):
        return "failed"
    by = rec.get("detected_by")
    if by is not None:
        return "detected" if str(by).startswith("controller_") else "tripped"
    return "ridden through" if rec.get("lock_kept") is not False else "lock lost"


def shortest_duration() -> float:
    """The shortest run the study takes (s): past the fault's start and the scenarios'
    scoring start (a run must score something)."""
    from bench.scenarios._schema import load_scenario

    return max(AT_S, *(load_scenario(s).score_from_s for s in ("wen-5.1", "xue-fig13")))


def _u_dc(scenario: str) -> float:
    from bench.scenarios._schema import load_scenario
    from bench.scenarios._setup import plant_setup

    scn = load_scenario(scenario).with_overrides(plant_profile=PLANT_PROFILE)
    return float(plant_setup(scn)[1].inverter.u_dc)


def cases_of(
    estimators: Sequence[str],
    kinds: Sequence[str] | None,
    controllers: Sequence[str],
    process_catalogue: str = "bus",
) -> list[tuple[str, str, str, dict[str, Any]]]:
    """``(controller, estimator, label, fault)`` of every case to run (module docstring):
    the ``kinds`` given (None: all) of the catalogue, reduced for the process variants
    unless ``process_catalogue`` is ``full``."""
    out: list[tuple[str, str, str, dict[str, Any]]] = []
    for ctl in controllers:
        full = ctl == IN_PROCESS or process_catalogue == "full"
        if ctl == EXTERNAL:
            ests: Sequence[str] = (EXTERNAL,)
        elif full:
            ests = estimators
        else:
            ests = [e for e in estimators if e == PROCESS_ESTIMATOR] or list(estimators[:1])
        for est in ests:
            for label, fault in catalogue(_u_dc(scenario_for(est))):
                if kinds is not None and fault["kind"] not in kinds:
                    continue
                if not full and fault["kind"] not in BUS_KINDS:
                    continue
                out.append((ctl, est, label, fault))
    return out


def _order(rec: dict[str, Any]) -> tuple[int, int, int]:
    """Tables' order: controller, estimator, then the catalogue's order."""
    from controller import ESTIMATOR_NAMES

    names = (*ESTIMATOR_NAMES, EXTERNAL)
    labels = [label for label, _ in catalogue(1.0)]
    ctl = rec.get("controller", IN_PROCESS)
    return (
        CONTROLLERS.index(ctl) if ctl in CONTROLLERS else len(CONTROLLERS),
        names.index(rec["estimator"]) if rec["estimator"] in names else len(names),
        labels.index(rec["fault"]) if rec["fault"] in labels else len(labels),
    )


def _key(rec: dict[str, Any]) -> tuple[str, str, str]:
    return (rec.get("controller", IN_PROCESS), rec["estimator"], rec["fault"])


def run_fault_study(
    out: Path,
    *,
    estimators: Sequence[str],
    kinds: Sequence[str] | None = None,
    controllers: Sequence[str] = CONTROLLERS,
    process_catalogue: str = "bus",
    duration: float = DURATION_S,
    jobs: int = 1,
    keep: dict[str, Any] | None = None,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Run the catalogue for ``estimators`` (only the ``kinds`` given, None: all) with the
    controller where ``controllers`` say (:func:`cases_of`) and write ``out/faults.json``
    and ``out/report.md``; return the summary.

    ``keep``: an earlier summary of the same duration whose records of the cases not run
    now stay in this one (the study updated in part).
    """
    from bench.wire._codec import default_codec

    cases = cases_of(estimators, kinds, controllers, process_catalogue)
    records: list[dict[str, Any]] = []
    if jobs > 1:
        with ProcessPoolExecutor(max_workers=jobs) as ex:
            futs = [ex.submit(run_case, e, lab, f, duration, c) for c, e, lab, f in cases]
            for fut in futs:
                records.append(fut.result())
                if progress:
                    progress(_line(records[-1]))
    else:
        for c, e, lab, f in cases:
            records.append(run_case(e, lab, f, duration, c))
            if progress:
                progress(_line(records[-1]))
    if keep is not None:
        if keep.get("duration_s") != duration:
            raise BenchError(
                f"the kept study ran {keep.get('duration_s')} s per case, this one {duration:g}"
            )
        new = {_key(r) for r in records}
        records += [r for r in keep["records"] if _key(r) not in new]
    records.sort(key=_order)
    ests = dict.fromkeys(r["estimator"] for r in records)
    summary = {
        "study": "faults",
        "duration_s": duration,
        "at_s": AT_S,
        "plant_profile": PLANT_PROFILE,
        "dbc_version": default_codec().version,
        "scenarios": {e: scenario_for(e) for e in ests},
        "process_catalogue": {
            "bus_kinds": list(BUS_KINDS),
            "estimator": PROCESS_ESTIMATOR,
            "external_controller": EXTERNAL_NAME,
        },
        "not_run": not_run(),
        "records": records,
    }
    out.mkdir(parents=True, exist_ok=True)
    (out / "faults.json").write_text(json.dumps(summary, indent=1, sort_keys=True) + "\n")
    (out / "report.md").write_text(render_doc(summary), encoding="utf-8")
    return summary


def _line(rec: dict[str, Any]) -> str:
    ctl = rec.get("controller", IN_PROCESS)
    return f"{rec['estimator']:>18} {ctl:>10}  {rec['fault']:<34} {cell(rec)}"


def cell(rec: dict[str, Any]) -> str:
    """One record as a table cell."""
    o = rec["outcome"]
    if o == "failed":
        return f"failed: {rec['error']}"
    if o in ("detected", "tripped"):
        by = str(rec["detected_by"]).removeprefix("controller_")
        return f"{o}: {by}, {rec['reaction_ms']:.1f} ms"
    if o == "ridden through":
        err = rec.get("theta_err_abs_max_deg")
        return "not detected, ridden through" + ("" if err is None else f" ({err:.1f} deg)")
    return "not detected, lock lost"


def headline(summary: dict[str, Any]) -> dict[tuple[str, str], dict[str, int]]:
    """Per estimator and controller, how many cases had each outcome."""
    out: dict[tuple[str, str], dict[str, int]] = {}
    for r in summary["records"]:
        c = out.setdefault(
            (r["estimator"], r.get("controller", IN_PROCESS)), dict.fromkeys(OUTCOMES, 0)
        )
        c[r["outcome"]] += 1
    return out


def _estimator_cell(est: str) -> str:
    return f"`{EXTERNAL_NAME}`" if est == EXTERNAL else f"`{est}`"


def _headline_table(summary: dict[str, Any]) -> list[str]:
    lines = [
        "| estimator | controller | scenario | cases | " + " | ".join(OUTCOMES) + " |",
        "|---|---|---|---|" + "---|" * len(OUTCOMES),
    ]
    for (est, ctl), c in headline(summary).items():
        n = sum(c.values())
        lines.append(
            f"| {_estimator_cell(est)} | {ctl} | {summary['scenarios'][est]} | {n} | "
            + " | ".join(str(c[o]) for o in OUTCOMES)
            + " |"
        )
    return lines


def render_doc(summary: dict[str, Any]) -> str:
    """docs/FAULTS.md from the study's JSON."""
    recs = summary["records"]
    ests = list(dict.fromkeys(r["estimator"] for r in recs))
    faults = list(dict.fromkeys(r["fault"] for r in recs))
    ctls = list(dict.fromkeys(r.get("controller", IN_PROCESS) for r in recs))
    by = {(r["fault"], r.get("controller", IN_PROCESS), r["estimator"]): r for r in recs}
    proc = summary.get("process_catalogue") or {}
    lines = [
        "# Fault study",
        "",
        "<!-- written by `bench suite faults --out docs/faults --doc docs/FAULTS.md` from "
        "docs/faults/faults.json; do not edit -->",
        "",
        f"Every fault kind a lockstep run applies, inserted at {summary['at_s']:g} s into a "
        f"{summary['duration_s']:g} s lockstep run of the `{summary['plant_profile']}` plant, "
        "for every shipped estimator (the square-wave family from `xue-fig13`, the others from "
        "`wen-5.1`, each from standstill), with the controller's supervision on "
        "(docs/PROTECTION.md). `detected`: the controller reported the fault in its "
        "`CtrlTelemetry.mode` (DBC " + str(summary["dbc_version"]) + ") before any plant "
        "protection tripped; `tripped`: a plant protection tripped first; reaction times are "
        "from the fault's start (`metrics.json` `faults`, docs/RUNS.md). A run that fails is "
        "listed as `failed`. The angle in parentheses is the largest |dtheta| while the fault "
        "lasted (electrical degrees).",
        "",
        "The controller column says where the controller ran: `in-process` (plant and "
        "controller nodes in one process, the whole catalogue), `python` (the Python "
        "controller node with the compiled core) and `native` (the native controller node), "
        "each a process beside the plant node over udp_multicast as `bench run` runs them "
        "(the plant node's loop in C where it serves the fault, else Python's: both give "
        "the same frames, docs/DEVELOPMENT.md), and `external` (`bench run --controller external` with the repository's "
        "example external controller, "
        f"`tests/{proc.get('external_controller', EXTERNAL_NAME)}`: a sensored drive from "
        f"`{summary['scenarios'].get(EXTERNAL, EXTERNAL_SCENARIO)}` without supervision, so "
        "only the plant's protections detect). The process variants run the bus kinds ("
        + ", ".join(f"`{k}`" for k in proc.get("bus_kinds", BUS_KINDS))
        + f") with `{proc.get('estimator', PROCESS_ESTIMATOR)}` by default; "
        "`bench suite faults --process-catalogue full` runs them all.",
        "",
        "## Headline",
        "",
        *_headline_table(summary),
        "",
        "## Every case",
        "",
        "| fault | controller | " + " | ".join(_estimator_cell(e) for e in ests) + " |",
        "|---|---|" + "---|" * len(ests),
    ]
    for f in faults:
        for ctl in ctls:
            cells = [cell(by[(f, ctl, e)]) if (f, ctl, e) in by else "-" for e in ests]
            if any(c != "-" for c in cells):
                lines.append(f"| {f} | {ctl} | " + " | ".join(cells) + " |")
    lines += ["", "## Not run", ""]
    lines += [f"- `{k}`: {why}" for k, why in summary["not_run"].items()] or ["None."]
    lines += ["", *_modes_table()]
    return "\n".join(lines)


def _modes_table() -> list[str]:
    """How each bus kind behaves in each mode (:data:`bench.scenarios._faults.KINDS`)."""
    from bench.scenarios._faults import KINDS

    lines = [
        "## The bus kinds in each mode",
        "",
        "As `bench faults` and docs/SCENARIOS.md state them. In lockstep the plant's "
        "retransmission rules apply: the plant never waits for a duty a fault lost, and its "
        "watchdog counts periods as in real time.",
        "",
        "| kind | lockstep | real time |",
        "|---|---|---|",
    ]
    for k in KINDS.values():
        if k.group == "bus":
            lines.append(f"| `{k.name}` | {k.refused or k.lockstep} | {k.refused or k.realtime} |")
    lines.append("")
    return lines


def readme_block(summary: dict[str, Any]) -> str:
    """The README's block: the headline table and a link to docs/FAULTS.md."""
    return "\n".join(
        [
            README_BEGIN,
            "",
            *_headline_table(summary),
            "",
            "Every case with its reaction time: [docs/FAULTS.md](docs/FAULTS.md).",
            "",
            README_END,
        ]
    )


def update_readme(text: str, summary: dict[str, Any]) -> str:
    """``text`` (README.md) with its fault-study block from ``summary``; unchanged without
    markers."""
    if README_BEGIN not in text or README_END not in text:
        return text
    head, _, rest = text.partition(README_BEGIN)
    _, _, tail = rest.partition(README_END)
    return head + readme_block(summary) + tail
