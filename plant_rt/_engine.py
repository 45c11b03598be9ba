"""The plant's engines: the per-period step in pure Python or compiled.

``"python"``: :class:`plant_rt.Plant` as written in :mod:`plant_rt._plant`.
``"compiled"``: the same step in C (``plant_rt/_cplant.c``, built by
``pip install`` when the machine has a C compiler and Python's headers), a
second implementation that mirrors the Python one operation for operation
and gives the same trace bit for bit (``tests/test_plant_engine.py``). It
covers the enabled periods of the average and the switching model; the
disabled bridge, the energy meter and the sensors stay in Python on the
same state. ``"auto"``: compiled when it is built, else Python.

Why C. Measured on the average model's period (wen2023, 10 kHz, the
duties of a closed loop replayed, median of 7 runs, one process): the
Python step 5.5 us; the same ``.py`` files compiled by Cython in
pure-Python mode 6.4 us (no gain without rewriting them in Cython's
types); by mypyc 1.2 us (4.5x, and 20 us for the switching model's
sample and step); a numba kernel 0.47 us per call, after 0.28 s to import
numba and a JIT compile at the first start of every node process unless
its cache is kept; a C extension 0.19 us; Rust through PyO3 0.21 us, with
a Rust toolchain and crates to fetch on every machine. C needs only what
any compiled option needs (gcc and Python's headers, which
``tools/need-cc`` installs), builds in under a second, imports in a
millisecond, and lets both engines live in one process, so that the test
compares them directly; its cost is the second implementation, which the
bit-for-bit tests keep equal to this one.
"""

from __future__ import annotations

from types import ModuleType
from typing import Literal

EngineName = Literal["auto", "compiled", "python"]
ENGINES: tuple[str, ...] = ("auto", "compiled", "python")
"""The engine choices of :class:`plant_rt.Plant` (``engine=``)."""

_cplant: ModuleType | None
_why_not: str | None
try:
    import plant_rt._cplant as _built
except ImportError as e:  # not built on this machine
    _cplant = None
    _why_not = (
        f"the compiled plant engine is not built ({e}; it needs a C compiler and Python's "
        "headers when the project is installed): the plant runs in pure Python"
    )
else:
    _cplant = _built
    _why_not = None


def compiled_engine_missing() -> str | None:
    """None when the compiled engine is built, else one line saying why the plant runs in Python."""
    return _why_not


def resolve_engine(engine: str, meter: bool = False) -> str:
    """The engine a plant runs on, ``"compiled"`` or ``"python"``.

    Parameters
    ----------
    engine : {"auto", "compiled", "python"}
        The choice; ``"auto"`` takes the compiled engine when it is built.
    meter : bool
        The plant integrates its energy flows (only the Python engine does).

    Raises
    ------
    ValueError
        For an unknown name, or ``"compiled"`` when it is not built or with
        the energy meter.
    """
    if engine not in ENGINES:
        raise ValueError(f"unknown plant engine {engine!r} (known: {', '.join(ENGINES)})")
    if engine == "python":
        return "python"
    if engine == "compiled":
        if _why_not is not None:
            raise ValueError(_why_not)
        if meter:
            raise ValueError("the energy meter (meter=True) runs on the python engine only")
        return "compiled"
    return "compiled" if _why_not is None and not meter else "python"
