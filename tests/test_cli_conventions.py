"""What every subcommand shares: ``--version``, one error prefix, defaults in ``--help``."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import pytest

from bench._errors import ERROR_PREFIX, BenchError, error_line
from bench.cli import SUBCOMMANDS, build_parser, main, shown_default, subparsers

ROOT = Path(__file__).resolve().parent.parent


def _parsers() -> list[tuple[str, argparse.ArgumentParser]]:
    """Every parser of the command line: bench, each subcommand, and theirs (suite paper, ...)."""
    out = []

    def walk(name: str, p: argparse.ArgumentParser) -> None:
        out.append((name, p))
        for sub_name, sub in subparsers(p).items():
            walk(f"{name} {sub_name}", sub)

    walk("bench", build_parser())
    return out


def test_every_subcommand_is_walked() -> None:
    names = {n for n, _ in _parsers()}
    assert {f"bench {s}" for s in SUBCOMMANDS} <= names
    assert "bench suite paper" in names  # and the subcommands' own subcommands


def test_every_option_with_a_default_shows_it_in_help() -> None:
    missing = []
    checked = 0
    for name, p in _parsers():
        fmt = p._get_formatter()
        for a in p._actions:
            d = a.default
            if not a.option_strings or d is None or d is False or d is argparse.SUPPRESS:
                continue
            checked += 1
            text = fmt._get_help_string(a) or ""
            if "default" not in text or shown_default(d) not in text:
                missing.append(f"{name} {a.option_strings[0]} (default {d!r}): {text!r}")
    assert checked > 30
    assert not missing, "\n".join(missing)
    # and as a user reads it: the formatted --help of one command
    assert "(default: 1,4,10)" in subparsers(build_parser())["busload"].format_help()


def test_version_names_the_package_and_the_dbc(capsys: pytest.CaptureFixture[str]) -> None:
    from importlib.metadata import version

    from bench.wire._codec import default_codec

    assert main(["--version"]) == 0
    out = capsys.readouterr().out.strip()
    assert out == (
        f"bench (can-hil-bench) {version('can-hil-bench')}, "
        f"DBC protocol version {default_codec().version}"
    )


@pytest.mark.parametrize(
    "argv",
    [
        ["run", "wen-5.1", "--no-such-option"],  # argparse, after the subcommand
        ["run", "wen-5.1", "--mode", "realtime", "--rt-priority", "0"],  # a bad value
        ["suite", "nope"],  # a sub-subcommand
        ["show", "wen-9.9"],  # the command's own BenchError
        ["replay", "/nonexistent.blf"],
        ["codegen", "/dev/null"],
        ["perf", "--out", "/proc/no/such/folder"],
        ["no-such-command"],
    ],
)
def test_every_error_is_one_line_with_one_prefix(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(ERROR_PREFIX), err


def test_argparse_mistakes_name_the_subcommands_help(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", "wen-5.1", "--no-such-option"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == error_line("unrecognized arguments: --no-such-option (see bench run --help)")
    assert error_line(BenchError("x: y")) == "bench: error: x: y"


def test_the_monitors_own_entry_point_uses_the_prefix() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "bench.cli.monitor", "--interface", "no-such-interface"],
        cwd=ROOT, capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    assert out.returncode == 2
    assert out.stderr.startswith(ERROR_PREFIX) and out.stderr.count("\n") == 1, out.stderr
