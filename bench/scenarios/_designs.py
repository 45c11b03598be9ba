"""The controller designs ``bench run`` made before, kept in the user's cache.

A controller's design (its searches' results, :class:`controller.DesignRecord`)
is a pure function of its settings and of the code that designs it. ``bench
run`` keeps each design it makes in ``$XDG_CACHE_HOME/can-hil-bench/designs/``
(``~/.cache/...`` by default), one JSON file named by a digest of everything
the design depends on: the settings (:func:`controller._design.settings_digest`),
the controller package's Python sources, and the numpy and scipy versions. A
run of the same settings with the same code then builds its controller from
the file and searches nothing (nor imports scipy for it); any change of one
of them is another file. Only the shipped estimators are kept (a plug-in's
code lives outside the package). ``CAN_HIL_BENCH_DESIGN_CACHE=off`` keeps no
design and reads none; a file that cannot be read or written is passed over
(the controller is designed as without the cache).
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import json
import os
import tempfile
from pathlib import Path
from typing import Any

from controller import ESTIMATOR_NAMES, ControllerPars, DesignRecord

#: ``off``: no design is read from or written to the cache.
CACHE_ENV = "CAN_HIL_BENCH_DESIGN_CACHE"


def cache_dir() -> Path:
    """Where the designs are kept (module docstring)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "can-hil-bench" / "designs"


@functools.cache
def _code_digest() -> str:
    """The controller package's Python sources and the numerical libraries' versions."""
    import controller

    h = hashlib.sha256()
    for f in sorted(Path(controller.__file__).parent.glob("*.py")):
        h.update(f.name.encode())
        h.update(f.read_bytes())
    for lib in ("numpy", "scipy"):
        try:
            h.update(f"{lib} {importlib.metadata.version(lib)}".encode())
        except importlib.metadata.PackageNotFoundError:
            h.update(f"{lib} none".encode())
    return h.hexdigest()


def _path(pars: ControllerPars) -> Path | None:
    if os.environ.get(CACHE_ENV) == "off" or pars.estimator not in ESTIMATOR_NAMES:
        return None
    from controller._design import settings_digest

    key = hashlib.sha256(f"{settings_digest(pars)} {_code_digest()}".encode()).hexdigest()
    return cache_dir() / f"{key[:32]}.json"


def load_design(pars: ControllerPars) -> DesignRecord | None:
    """The design kept for ``pars`` with the present code, else None."""
    path = _path(pars)
    if path is None:
        return None
    try:
        data: Any = json.loads(path.read_text())
        return DesignRecord(str(data["settings"]), dict(data["results"]))
    except (OSError, ValueError, KeyError, TypeError):
        return None


def store_design(pars: ControllerPars, design: DesignRecord) -> None:
    """Keep ``design`` (of ``pars``) for the next run (an atomic rename; never fails)."""
    path = _path(pars)
    if path is None:
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".design-", dir=path.parent)
        with os.fdopen(fd, "w") as f:
            json.dump({"settings": design.settings, "results": dict(design.results)}, f)
        os.replace(tmp, path)
    except OSError:
        pass
