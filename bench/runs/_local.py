"""A run in this process, scored as a run over CAN is, and the exit status of any run.

:func:`run_local` is the in-process route of a run: the same DBC frames
between the same node objects as two processes over a bus
(:func:`bench.nodes._loops.run_inprocess`, the reference trace), scored by
the one path from frames to files (:func:`bench.runs._results.finish_run`).
The paper suite's in-process runs, the sweeps' points
(:func:`bench.studies._sweep.run_point`) and the Python API (``bench.run``
without a transport) take it.

:func:`exit_status` is the status ``bench run`` and ``bench analyze`` exit
with and ``bench.run(...).exit_status`` holds: one function, so the command
line and the API cannot disagree about a result.
"""

from __future__ import annotations

import time
from pathlib import Path

from bench._errors import EXIT_INTERRUPTED
from bench.runs._results import RunResult, finish_run, outcome, run_metadata
from bench.scenarios._schema import Scenario
from bench.wire._codec import Codec

__all__ = ["INPROCESS", "exit_status", "run_local"]

#: The transport of an in-process run, as ``meta.json`` names it.
INPROCESS = "in-process"


def run_local(
    scn: Scenario,
    estimator: str,
    out_dir: Path,
    *,
    engine: str = "auto",
    plots: bool = True,
    codec: Codec | None = None,
    overshoot: bool | None = None,
) -> RunResult:
    """Run ``scn`` with ``estimator`` in lockstep in this process; the run's files in ``out_dir``.

    ``engine`` is the plant's (:class:`plant_rt.Plant`); the controller's
    follows :data:`bench.scenarios._setup.ENGINE_ENV` as in a controller
    process.  ``plots=False`` leaves out ``run.png`` (seconds of matplotlib).
    ``overshoot`` is :func:`~bench.runs._results.finish_run`'s.
    """
    from bench.nodes._loops import run_inprocess
    from bench.runs._run import clear_run_files

    codec = codec or Codec()
    out_dir.mkdir(parents=True, exist_ok=True)
    clear_run_files(out_dir)  # an earlier run's capture or plot must not pass for this one's
    t0 = time.perf_counter()
    frames = run_inprocess(scn, estimator, codec, engine=engine)
    meta = run_metadata(scn, estimator, mode="lockstep", transport=INPROCESS, link=False)
    return finish_run(
        frames,
        codec,
        scn,
        out_dir,
        meta=meta,
        wall_s=time.perf_counter() - t0,
        capture=None,
        plots=plots,
        overshoot=overshoot,
    )


def exit_status(res: RunResult, *, analysis: bool = False) -> tuple[int, list[str]]:
    """The exit status of a finished run or ``analysis`` of a capture, and its warning lines.

    :func:`bench.runs._results.outcome` of its metrics (3 a plant trip, 4 the
    rotor angle lost, 0 done; DESIGN.md), and 130 for a run that was
    interrupted (its files are those of the part that ran).  An analysis is
    never interrupted, whatever the ``meta.json`` of the run it reads says.
    """
    status, lines = outcome(res.metrics, float(res.meta.get("T_s") or 0.0))
    if res.meta.get("interrupted") and not analysis:
        return EXIT_INTERRUPTED, lines
    return status, lines
