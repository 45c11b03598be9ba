"""The plant's engine: the portable C core (``plant_rt/core/``) through its binding.

Every per-period equation of the plant lives once, in C99 (``plant_rt/core/``:
machine and flux map, RK4, PWM timeline and dead time, DC link, sensors,
protection, the period step), with no Python in it, so that the bench's
native node and a drive's own firmware can link the same code
(``gcc -std=c99 -c plant_rt/core/*.c``). ``plant_rt/_cplant.c`` hands the
parameters and states across. The package therefore needs a C compiler and
Python's headers when it is installed (``tools/need-cc`` installs them;
``make .venv/.installed`` runs it first): without the built core
``import plant_rt`` fails with one line saying so.

Why C. Measured on the average model's period (wen2023, 10 kHz, the
duties of a closed loop replayed, median of 7 runs, one process): the
Python step 5.5 us; the same ``.py`` files compiled by Cython in
pure-Python mode 6.4 us; by mypyc 1.2 us; a numba kernel 0.47 us per call,
after 0.28 s to import numba and a JIT compile at every node start; a C
extension 0.19 us; Rust through PyO3 0.21 us, with a Rust toolchain on every
machine. C needs only gcc and Python's headers, builds in under a second,
imports in a millisecond, and is what a microcontroller runs.

The ``engine`` choice of :class:`plant_rt.Plant` (and ``bench run
--engine``) is kept for the controller and for compatibility: the plant
has one engine, the core, whatever the choice (``"compiled"``).
"""

from __future__ import annotations

from typing import Literal

__all__ = ["ENGINES", "EngineName", "_cplant", "compiled_engine_missing", "resolve_engine"]

EngineName = Literal["auto", "compiled", "python"]
ENGINES: tuple[str, ...] = ("auto", "compiled", "python")
"""The engine choices of :class:`plant_rt.Plant` (``engine=``); the plant runs its C core for each."""

try:
    import plant_rt._cplant as _cplant
except ImportError as e:  # not built on this machine
    raise ImportError(
        f"plant_rt: the plant core (plant_rt/core, C) is not built ({e}): install a C compiler "
        "and Python's headers (tools/need-cc) and reinstall the project (pip install -e .)"
    ) from None


def compiled_engine_missing() -> str | None:
    """None: the plant's core is always built (``import plant_rt`` fails without it)."""
    return None


def resolve_engine(engine: str, meter: bool = False) -> str:
    """The engine a plant runs on: ``"compiled"`` (its C core) for every known choice.

    Parameters
    ----------
    engine : {"auto", "compiled", "python"}
        The choice (kept for the controller's engines and for compatibility).
    meter : bool
        The plant integrates its energy flows (the core does that too).

    Raises
    ------
    ValueError
        For an unknown name.
    """
    if engine not in ENGINES:
        raise ValueError(f"unknown plant engine {engine!r} (known: {', '.join(ENGINES)})")
    return "compiled"
