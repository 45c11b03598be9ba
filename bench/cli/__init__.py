"""The ``bench`` command line: one small module per subcommand, registered here.

Each module in :data:`SUBCOMMANDS` has ``register(subparsers)``, which adds
its subcommand and sets ``func``, and keeps its heavy imports inside its
command function, so ``bench --help`` and a node's start-up stay fast and a
missing optional dependency breaks only its own subcommand.  What the
modules share (bus, real-time and scenario options; signals) is in
:mod:`bench.cli._common`.

A user's mistake (bad scenario, unknown estimator, unreadable capture,
missing interface) is a :class:`~bench._errors.BenchError`: one line on
stderr, exit code 2, no traceback.  Every such line, and every mistake
argparse finds on the command line, starts alike
(:func:`bench._errors.error_line`: ``bench: error: ...``).  ``bench --version``
prints the package's version and the DBC's.
"""

from __future__ import annotations

import argparse
import builtins
import importlib
import sys
from typing import Any, NoReturn

from bench._errors import BenchError, error_line
from bench.wire._canimport import import_can_without_mf4

# every process of a run starts here: python-can without asammdf (bench.wire._canimport)
import_can_without_mf4()

#: The subcommand modules, in the order ``bench --help`` lists them.
SUBCOMMANDS = (
    "run",
    "show",
    "list",
    "schema",
    "faults",
    "plant",
    "controller",
    "link",
    "analyze",
    "plot",
    "busload",
    "suite",
    "sweep",
    "replay",
    "rerun",
    "monitor",
    "codegen",
    "perf",
    "rtcheck",
    "soak",
)


class _Help(argparse.HelpFormatter):
    """Every option's default in its help line, unless the line already names it.

    Options without a default (None: the scenario's value, or not used) and
    flags (off unless given) get no suffix.
    """

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        d = action.default
        if (
            action.option_strings
            and d is not None
            and d is not False
            and d is not argparse.SUPPRESS
            and "default" not in text
        ):
            text += f" (default: {shown_default(d)})".replace("%", "%%")
        return text


def shown_default(d: object) -> str:
    """An option's default as ``--help`` shows it: numbers as ``%g``, a list joined by commas."""
    # builtins.list: the subcommand module bench.cli.list shadows the name here
    if isinstance(d, builtins.list | tuple):
        return ",".join(map(shown_default, d))
    if isinstance(d, float):
        return f"{d:g}"
    return str(d)


class _Parser(argparse.ArgumentParser):
    """Command-line mistakes as one line (with where to look), exit code 2;
    defaults shown in ``--help`` (:class:`_Help`)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", _Help)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        self.exit(2, error_line(f"{message} (see {self.prog} --help)") + "\n")


def versions() -> str:
    """``bench --version``: the package's version and the DBC's (the wire protocol)."""
    from importlib.metadata import PackageNotFoundError, version

    from bench.wire._codec import default_codec

    try:
        package = version("can-hil-bench")
    except PackageNotFoundError:  # run from a source tree that is not installed
        package = "unknown (not installed)"
    return f"bench (can-hil-bench) {package}, DBC protocol version {default_codec().version}"


class _Version(argparse.Action):
    """``--version``: :func:`versions` (the DBC is read only when it is asked for)."""

    def __init__(self, option_strings: list[str], dest: str, **kwargs: Any) -> None:
        kwargs.update(nargs=0, default=argparse.SUPPRESS)
        super().__init__(option_strings, dest, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, *args: Any, **kwargs: Any) -> None:
        print(versions())
        parser.exit(0)


def build_parser() -> argparse.ArgumentParser:
    ap = _Parser(
        prog="bench",
        description="CAN hardware-in-the-loop bench for sensorless IPMSM control",
    )
    ap.add_argument(
        "--version", action=_Version, help="the package's version and the DBC protocol version"
    )
    sub = ap.add_subparsers(dest="command", required=True)
    for name in SUBCOMMANDS:
        mod = f"bench.cli.{name}"
        try:
            module = importlib.import_module(mod)
        except ModuleNotFoundError as e:
            if e.name != mod:
                raise
            continue
        module.register(sub)
    return ap


def subparsers(ap: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """The subcommands' parsers of ``ap``, by name."""
    for action in ap._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def main(argv: list[str] | None = None) -> int:
    ap = build_parser()
    try:
        args, extra = ap.parse_known_args(argv)
        if extra:  # named with the subcommand whose --help lists what it takes
            subparsers(ap)[args.command].error(f"unrecognized arguments: {' '.join(extra)}")
    except SystemExit as e:  # --help, --version, or a mistake already reported on one line
        return e.code if isinstance(e.code, int) else 2
    try:
        rc: int = args.func(args)
        return rc
    except BenchError as e:
        print(error_line(e), file=sys.stderr)
        return e.exit_code
    except KeyboardInterrupt:
        print("bench: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into head and the like
        sys.stderr.close()
        return 0


if __name__ == "__main__":
    sys.exit(main())
