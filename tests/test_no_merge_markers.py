"""No file of the project carries a merge's conflict markers (a page once did: two
versions of a row, one under the other, each half of the truth)."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DIRS = ("bench", "controller", "plant_rt", "dbc", "docs", "firmware", "tests", "tools")
SUFFIXES = {".py", ".md", ".c", ".h", ".toml", ".json", ".dbc", ".txt", ".cfg", ".sh", ""}
MARKER = re.compile(r"^(<{7}|>{7}|={7})( |$)", re.MULTILINE)


def _files() -> list[Path]:
    out = [ROOT / "README.md", ROOT / "pyproject.toml", ROOT / "Makefile"]
    for d in DIRS:
        out += [
            p
            for p in (ROOT / d).rglob("*")
            if p.is_file()
            and p.suffix in SUFFIXES
            and not any(
                part.startswith((".", "_build")) or part == "__pycache__"
                for part in p.relative_to(ROOT).parts
            )
        ]
    return out


def test_no_file_has_conflict_markers() -> None:
    files = _files()
    assert len(files) > 300
    bad = []
    for p in files:
        try:
            text = p.read_text(encoding="utf-8")
        except (UnicodeDecodeError, OSError):
            continue
        if m := MARKER.search(text):
            line = text.count("\n", 0, m.start()) + 1
            bad.append(f"{p.relative_to(ROOT)}:{line}")
    assert not bad, bad
