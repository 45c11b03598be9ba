"""The controller's engine: the portable C core ``controller/core/``, whatever the name.

Every per-period equation of the controller lives once, in C99
(``controller/core/``, no ``Python.h``, one file per block: PI, filters,
PLL, Luenberger, CIC, each demodulator, the flux observer, the hybrid band,
the polarity test, the countermeasures, the supervision, FOC), bound to
Python by ``controller/_cctl.c`` and built by ``pip install`` beside the
plant's core (both need a C compiler and Python's headers, ``tools/need-cc``;
without the built core ``import controller`` fails with one line saying so).
Python designs every gain, filter and threshold (:mod:`controller._compiled`
hands the designed values to the core's ``_init`` functions); the core runs
every period, the start-up included, and keeps every state. The
:class:`controller.Controller` holds it by composition and forwards its
commands.

The ``engine`` choice of :class:`controller.Controller` (and ``bench run
--engine``) is kept for compatibility, as the plant's (:mod:`plant_rt._engine`):
``"auto"``, ``"compiled"`` and ``"python"`` all run the core, with the same
bits the Python step gave when it was an engine. That Python step, the
readable reference, is the oracle of the tests (``tests/oracle/``): the core
is checked against it bit for bit, tolerance 0.

Every shipped estimator has its kind in the core (:data:`COMPILED_ESTIMATORS`,
from the registry): ``tt-dq``, ``tt-ab``, ``sfhf``, ``self-demod`` and
``epf`` (Wen's references [27] and [25]) with either normalisation and
either position observer, ``square-wave``, ``square-wave-nocic``,
``sensored``, and the hybrids ``hybrid-tt-dq`` and ``hybrid-square-wave``.
Their options all fit it: the square-wave estimators' CIC delay ``M`` is a
typed option range, ``1 .. CIC_MAX`` (the core's fixed delay line,
:class:`controller._square_wave.SquareWaveOptions`), so a longer one is a
scenario error of one line rather than a controller outside the core. A
user's Python estimator (a plug-in, :data:`KIND_EXTERNAL`) runs in the core
too: the core runs the controller and calls the estimator's ``update``,
``injection`` and ``reset`` through the estimator interface
(``controller/core/cc_estimator.h``); an exception the estimator raises
leaves the step unchanged. A user's estimator in C
(:func:`controller.c_estimator`, a shared library) is called by the core
directly, with no Python in the period.

Purity is kept: the core reads a measurement's ``theta_e`` and ``w_e`` only
for the sensored baseline.

Why C, as for the plant (:mod:`plant_rt._engine`): the Python step cost
about 5.5 us per period at 10 kHz with tt-dq, of which 1.2 us was only the
construction of the frozen :class:`controller.ControlOutput`; mypyc on the
unchanged modules gave 1.4x on the whole loop. The C step (0.24 us against
5.1 us for the Python step in the same ``bench perf`` run,
docs/BENCHMARKS.md) fills the output's slots directly, reads the
measurement's the same way, and is called without a Python frame.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from controller._built import _cctl
from controller._registry import SPECS  # the estimators, the square-wave's CIC_MAX among them

ENGINES: tuple[str, ...] = ("auto", "compiled", "python")
"""The engine choices of :class:`controller.Controller` (``engine=``); each runs the core."""

#: estimator name -> the kind of the compiled core (controller/_cctl.c), from the registry
_KINDS = {s.name: s.compiled_kind for s in SPECS.values() if s.compiled_kind is not None}


#: The estimators the compiled core covers, by name, with their kernels in C.
COMPILED_ESTIMATORS: tuple[str, ...] = tuple(_KINDS)

#: The core's kind of an estimator outside it, a user's Python estimator: the core calls
#: its ``update``, ``injection`` and ``reset`` each period (``controller/core/cc_estimator.h``,
#: adapted by ``controller/_cctl.c``).
KIND_EXTERNAL: int = _cctl.KIND_EXTERNAL


def core_sources() -> list[Path]:
    """The portable controller core's files (``controller/core/*.h``, ``*.c``): plain C99,
    no Python, the code ``firmware/`` builds on and ``bench codegen`` ships."""
    return sorted((Path(__file__).parent / "core").glob("cc_*.[ch]"))


def compiled_controller_missing() -> str | None:
    """None: the controller's core is always built (``import controller`` fails without it).

    Public API kept for the scripts that call it (as :func:`plant_rt.compiled_engine_missing`);
    nothing in the bench branches on it."""
    return None


def core_kind(pars: Any) -> int:
    """The core's kind of the estimator ``pars`` names (a ``ControllerPars``): the
    registry's compiled kind of a shipped estimator's name, :data:`KIND_EXTERNAL` for a
    plug-in's name. The kind a controller runs is its estimator's as built
    (:func:`controller._compiled.instance_kind`): a plug-in that returns a shipped
    estimator unchanged runs as that estimator's kind."""
    return _KINDS.get(pars.estimator, KIND_EXTERNAL)


def resolve_controller_engine(engine: str, pars: Any) -> tuple[str, str | None]:
    """The engine a controller runs on: ``("compiled", None)`` (its C core) for every known
    choice; the pair is kept for compatibility (the second item said why a controller ran
    in Python).

    Parameters
    ----------
    engine : {"auto", "compiled", "python"}
        The choice, kept for compatibility.
    pars : ControllerPars
        The controller's settings (every shipped estimator and option, and every plug-in,
        runs in the core).

    Raises
    ------
    ValueError
        For an unknown name.
    """
    if engine not in ENGINES:
        raise ValueError(f"unknown controller engine {engine!r} (known: {', '.join(ENGINES)})")
    return "compiled", None
