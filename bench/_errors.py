"""Typed errors of the bench, in the spirit of python-can's ``CanError`` tree.

A :class:`BenchError` is a user's mistake or an unusable environment (bad
scenario file, unknown interface, unreadable capture, broken DBC): the command
line prints ``str(e)`` as one line and exits with status 2, without a
traceback. Anything else is a bug and keeps its traceback.

Each message names the file (or interface), the field and the reason, e.g.
``scenario wen-5.1.toml: field 'duration': must be > 0, got -1``.
"""

from __future__ import annotations

__all__ = [
    "EXIT_COMMANDS_LOST",
    "EXIT_FAULT_EXPECTATION",
    "EXIT_INTERRUPTED",
    "EXIT_LOCK_LOST",
    "EXIT_MODEL_RANGE",
    "EXIT_PLANT_TRIPPED",
    "EXIT_USER_ERROR",
    "BenchError",
    "CaptureError",
    "CommandsLost",
    "DbcError",
    "InterfaceError",
    "ScenarioError",
    "error_line",
]

#: Exit status of a user's mistake or a failure (one line on stderr).
EXIT_USER_ERROR = 2
#: Exit status of ``bench run`` / ``bench analyze`` when the plant tripped a
#: protection (every file written; the metrics are not a scenario result).
EXIT_PLANT_TRIPPED = 3
#: Exit status of ``bench run`` / ``bench analyze`` when the estimator lost the
#: rotor angle (``|dtheta|`` > 90 deg electrical for more than 50 ms after the
#: scoring start; every file written).
EXIT_LOCK_LOST = 4
#: Exit status of ``bench run`` when the controller under test held bench
#: commands only after their step or never (``CtrlTelemetry.cmd_ack``, DBC 2.2;
#: every file written; the run did not follow the scenario's set-points).
EXIT_COMMANDS_LOST = 5
#: Exit status of ``bench run`` / ``bench analyze`` when a fault of the scenario's
#: ``[[faults]]`` timeline did not get the reaction its ``expect`` declares
#: (``metrics.json`` ``faults``; every file written).  A run whose every declared
#: expectation holds exits 0, even when what it expected is a trip.
EXIT_FAULT_EXPECTATION = 6
#: Exit status of ``bench run`` when the plant's current left its flux map's checked
#: range (``plant_rt._machine.FLUX_RANGE``; ``metrics.json`` ``plant_out_of_range_s``; every file
#: written): the plant stayed finite on the map's continuation, but that part of the
#: run is not the modelled motor's (plant_rt/core/plant_machine.c).
EXIT_MODEL_RANGE = 7
#: Exit status of ``bench run`` / ``bench analyze`` when not one period was scored
#: (``metrics.json`` ``scored_steps`` 0 and ``unscored_reason``): the controller was
#: disabled (mode 0) throughout the scored window, the run ended before
#: ``score_from_s``, or no plant period was recorded; every file written.  A run
#: scored without the controller's telemetry (a drive that sends none) is scored on
#: its speed and exits 0.
EXIT_NOT_SCORED = 8
#: Exit status of an interrupted command (Ctrl-C), with the files of the part that ran.
EXIT_INTERRUPTED = 130


#: The start of every one-line error of every command (``bench: error: ...``).
ERROR_PREFIX = "bench: error: "


def error_line(message: object) -> str:
    """The one line a command prints on stderr for a mistake (exit status 2).

    Every command's errors start alike, whether argparse found the mistake
    (``... (see bench run --help)``) or the command did (a :class:`BenchError`),
    so a script matches one prefix.
    """
    return f"{ERROR_PREFIX}{message}"


class BenchError(Exception):
    """Base of every error the bench reports as one line (exit status 2)."""

    exit_code: int = EXIT_USER_ERROR


class ScenarioError(BenchError):
    """A scenario file or name is wrong (missing file, bad TOML, bad field)."""


class InterfaceError(BenchError):
    """A CAN interface cannot be opened (unknown name, missing channel, driver error)."""


class CaptureError(BenchError):
    """A CAN capture (log file) cannot be read or written."""


class DbcError(BenchError):
    """The DBC file is unusable, or a value cannot be encoded with it."""


class CommandsLost(BenchError):
    """The controller under test held commands late or never (exit 5, files written)."""

    exit_code = EXIT_COMMANDS_LOST
