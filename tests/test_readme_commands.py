"""Every command block of the README and of the guides its reference moved to runs as written,
in order, on a copy of the repository.

A fenced ``sh`` block is run with bash (``set -e``: every command must exit 0)
unless the line before it is ``<!-- readme-test: skip (reason) -->``, which
the README puts on blocks that need hardware, a terminal, real time or many
minutes.  The blocks run one after another in one folder that holds the
repository's files (the project's environment on the PATH, as after
``. .venv/bin/activate``), so a block may use what an earlier one wrote
(``runs/demo`` of ``make demo``).  Two changes keep it short, and only
these: every ``bench run`` gets ``--duration`` :data:`DURATION` in place of
its own, and ``make TARGET`` runs the target's recipe from the Makefile
(without reinstalling the environment).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: The files whose command blocks run here, in this order: the README, then the guides of
#: the bench's use (docs/USAGE.md: the README's runs/demo is there by then).
FILES = ("README.md", "docs/USAGE.md", "docs/HARDWARE.md", "docs/SUITE.md", "docs/DEVELOPMENT.md")
README = (ROOT / "README.md").read_text(encoding="utf-8")
#: Simulated seconds of every ``bench run`` of the README here.
DURATION = 1.2
SKIP = re.compile(r"<!-- readme-test: skip \(([^)]+)\) -->")


def blocks(text: str) -> list[tuple[int, str, str | None]]:
    """``(line, code, skip reason or None)`` of every fenced ``sh`` block."""
    out = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        if lines[i].strip() == "```sh":
            j = i + 1
            while lines[j].strip() != "```":
                j += 1
            prev = next((ln for ln in reversed(lines[:i]) if ln.strip()), "")
            m = SKIP.fullmatch(prev.strip())
            out.append((i + 1, "\n".join(lines[i + 1 : j]), m.group(1) if m else None))
            i = j
        i += 1
    return out


def all_blocks() -> list[tuple[str, str, str | None]]:
    """``(file and line, code, skip reason or None)`` of every block of :data:`FILES`."""
    out = []
    for name in FILES:
        for line, code, why in blocks((ROOT / name).read_text(encoding="utf-8")):
            out.append((f"{name} line {line}", code, why))
    return out


def make_recipe(target: str) -> list[str]:
    """The recipe lines of ``target`` in the Makefile, ``$(BIN)`` made the environment's."""
    text = (ROOT / "Makefile").read_text()
    m = re.search(rf"^{re.escape(target)}:[^\n]*\n((?:\t[^\n]*\n)+)", text, re.M)
    assert m, f"make {target}: no such target in the Makefile"
    bindir = str(Path(sys.executable).parent)
    return [ln[1:].replace("$(BIN)", bindir) for ln in m.group(1).splitlines()]


def shorten(line: str) -> str:
    """``--duration`` :data:`DURATION` on a ``bench run`` line."""
    if not re.search(r"(^|\s|/)bench run\s", line):
        return line
    line = re.sub(r"\s--duration\s+\S+", "", line)
    head, sep, comment = line.partition("  #")
    return f"{head.rstrip()} --duration {DURATION}" + (f"  {sep.strip()}{comment}" if sep else "")


def runnable(code: str) -> str:
    out = []
    for raw in code.replace("\\\n", " ").splitlines():
        m = re.match(r"\s*make\s+(\S+)", raw)
        lines = make_recipe(m.group(1)) if m else [raw]
        out += [shorten(ln) for ln in lines]
    return "\n".join(out)


def test_the_readme_marks_what_it_does_not_run() -> None:
    found = all_blocks()
    run = [b for b in found if b[2] is None]
    skipped = [b for b in found if b[2] is not None]
    assert len(run) >= 4 and len(skipped) >= 4
    joined = "\n".join(code for _, code, _ in run)
    for cmd in (
        "make demo",
        "bench list",
        "bench run",
        "bench plot",
        "bench analyze",
        "bench rerun",
    ):
        assert cmd in joined, cmd
    # what is not run says why, and every real-time or hardware command is among it
    for _, code, why in found:
        if "--mode realtime" in code or "-i socketcan" in code or "-i pcan" in code:
            assert why, code


def test_shorten_and_make_recipe() -> None:
    assert shorten("bench run wen-5.2 -e sfhf --duration 6 --out x  # c") == (
        f"bench run wen-5.2 -e sfhf --out x --duration {DURATION}  # c"
    )
    assert shorten("bench plot runs/x") == "bench plot runs/x"
    assert any("bench run wen-5.1" in ln for ln in make_recipe("demo"))


@pytest.mark.slow
def test_every_readme_command_block_runs_as_written(tmp_path: Path) -> None:
    work = tmp_path / "clone"
    work.mkdir()
    for entry in ROOT.iterdir():
        if entry.name in ("runs", ".git"):
            continue
        if entry.name == "docs":  # commands may write there: a copy
            shutil.copytree(entry, work / "docs")
        else:
            (work / entry.name).symlink_to(entry)
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}:{os.environ['PATH']}")
    env.pop("CAN_INTERFACE", None)
    for where, code, why in all_blocks():
        if why is not None:
            continue
        script = "set -euo pipefail\n" + runnable(code)
        r = subprocess.run(
            ["bash", "-c", script], cwd=work, env=env, capture_output=True, text=True,
            timeout=600,
        )  # fmt: skip
        assert r.returncode == 0, (
            f"{where}: exit {r.returncode}\n{script}\n--- stdout\n"
            f"{r.stdout[-2000:]}\n--- stderr\n{r.stderr[-3000:]}"
        )
    assert (work / "runs" / "demo" / "run.png").is_file()


def test_the_real_time_block_is_rtchecks() -> None:
    from bench.studies._rtcheck import render_doc_block

    res = json.loads((ROOT / "docs" / "realtime" / "rtcheck.json").read_text())
    assert render_doc_block(res) in (ROOT / "docs" / "REALTIME.md").read_text()
