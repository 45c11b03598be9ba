"""The controller under test's process, started for a run and stopped after it.

``bench run --dut COMMAND`` and ``bench.run(dut=[...])`` both start it here:
its arguments' placeholders filled from the run's bus, mode, scenario and
folder, its environment naming the bus as python-can reads it, its output in
the run folder's ``dut.log``.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bench._errors import BenchError

if TYPE_CHECKING:
    from bench.runs._run import DutProcess
    from bench.scenarios._schema import Scenario
    from bench.wire._bus import BusSpec

#: The placeholders of a controller's command (``{interface}``, ...), in the order
#: the error line lists them.
PLACEHOLDERS = ("interface", "channel", "port", "mode", "scenario", "folder")


@contextlib.contextmanager
def started_dut(
    cmd: Sequence[str] | None,
    spec: BusSpec,
    scn: Scenario,
    folder: Path,
    mode: str,
    label: str = "dut",
) -> Iterator[DutProcess | None]:
    """The controller under test's process for the run (none without ``cmd``).

    ``label`` names the option in an error line (``dut`` of the API, ``--dut``
    of the command line)."""
    if not cmd:
        yield None
        return
    from bench.runs._run import DutProcess
    from bench.scenarios._schema import write_effective

    folder.mkdir(parents=True, exist_ok=True)
    scenario = write_effective(scn, folder / "scenario.json")  # the run writes the same
    values = (
        spec.interface,
        spec.channel,
        "" if spec.port is None else str(spec.port),
        mode,
        str(scenario),
        str(folder),
    )
    fill = dict(zip(PLACEHOLDERS, values, strict=True))
    try:
        argv = [str(a).format(**fill) for a in cmd]
    except (KeyError, IndexError, ValueError) as e:
        raise BenchError(
            f"{label}: {list(cmd)}: unknown placeholder {e} (known: "
            + ", ".join("{" + k + "}" for k in fill)
            + ")"
        ) from None
    conf: dict[str, Any] = {"fd": True}
    if spec.port is not None:
        conf["port"] = spec.port
    env = dict(
        os.environ,
        PYTHONUNBUFFERED="1",
        CAN_INTERFACE=spec.interface,
        CAN_CHANNEL=spec.channel,
        CAN_CONFIG=json.dumps(conf),
    )
    log_path = folder / "dut.log"
    log = log_path.open("w")
    try:
        proc = subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT, env=env)
    except OSError as e:
        log.close()
        raise BenchError(f"{label}: cannot start {argv[0]}: {e.strerror or e}") from None
    try:
        yield DutProcess(proc, log_path)
    finally:
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        log.close()
