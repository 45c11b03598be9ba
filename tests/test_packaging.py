"""What a wheel ships: every folder of the project's packages that holds Python or C is a
listed package, and its C sources are package data (the native loop, ``bench codegen`` and
the firmware compile them from the installed project)."""

from __future__ import annotations

import fnmatch
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TOP = ("bench", "plant_rt", "controller", "dbc")


def _config() -> tuple[list[str], dict[str, list[str]]]:
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    return list(cfg["packages"]), dict(cfg["package-data"])


def _folders() -> list[Path]:
    out = []
    for top in TOP:
        for d in [ROOT / top, *(p for p in (ROOT / top).rglob("*") if p.is_dir())]:
            if "__pycache__" in d.parts or d.name.startswith("."):
                continue
            if any(d.glob("*.py")) or any(d.glob("*.c")) or any(d.glob("*.h")):
                out.append(d)
    return out


def test_every_source_folder_is_a_listed_package() -> None:
    packages, _ = _config()
    missing = [
        ".".join(d.relative_to(ROOT).parts)
        for d in _folders()
        if ".".join(d.relative_to(ROOT).parts) not in packages
    ]
    assert not missing, f"pyproject.toml [tool.setuptools] packages lacks {missing}"


def test_every_c_source_is_package_data() -> None:
    _, data = _config()
    unshipped = []
    for d in _folders():
        pkg = ".".join(d.relative_to(ROOT).parts)
        patterns = data.get(pkg, [])
        for f in [*d.glob("*.c"), *d.glob("*.h")]:
            if not any(fnmatch.fnmatch(f.name, pat) for pat in patterns):
                unshipped.append(str(f.relative_to(ROOT)))
    assert not unshipped, f"C sources not in [tool.setuptools.package-data]: {unshipped}"
