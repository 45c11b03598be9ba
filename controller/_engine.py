"""The controller's engines: the per-period step in pure Python or compiled.

``"python"``: :meth:`controller.Controller.step` as written in
:mod:`controller._controller` and the estimators' modules. ``"compiled"``:
the same step in the portable C core ``controller/core/`` (C99, no
``Python.h``, one file per block: PI, filters, PLL, Luenberger, CIC, each
demodulator, the flux observer, the hybrid band, the polarity test, FOC),
bound to Python by ``controller/_cctl.c`` and built by ``pip install``
beside the plant's engine when the machine has a C compiler and Python's
headers. It repeats the Python blocks operation for operation and gives the
same trace bit for bit (``tests/test_controller_engine.py``).
``"auto"``: compiled when it is built and covers the controller, else Python.

What it covers (:func:`compiled_cover`): the speed and current control of
the alignment and run modes with the shipped estimators of
:data:`COMPILED_ESTIMATORS`: ``tt-dq``,
``tt-ab``, ``sfhf``, ``self-demod`` and ``epf`` (Wen's references [27] and
[25]), each with the model or the measured normalisation (``normalise``;
the core's ``cc_hypot`` rounds as CPython's ``math.hypot``) and the PLL or
the mechanical position observer (``observer``), ``square-wave``,
``square-wave-nocic``, ``sensored``, and the hybrids ``hybrid-tt-dq`` and
``hybrid-square-wave`` (flux observer, hand-over band, trackers: tt-dq's
PLL or mechanical observer, square-wave's Luenberger observer), with the
current fed to the PIs filtered or raw, and the drive countermeasures of
:mod:`controller._compensation` (dead-time feed-forward, cross-saturation
correction, offset calibration: ``controller/core/cc_compensation.c``), and
tt-dq's acceleration feed-forward (``accel_ff``, with the speed loop's
reference model ``controller/core/cc_reference.c``). A user's Python
estimator (a plug-in, :data:`KIND_EXTERNAL`) runs in it too: the core runs
the controller and calls the estimator's ``update``, ``injection`` and
``reset`` through the estimator interface (``controller/core/cc_estimator.h``),
so the trace is the Python engine's bit for bit, and an exception the
estimator raises leaves the step as it leaves the Python step. A user's
estimator in C (:func:`controller.c_estimator`, a shared library) is
called by the core directly, with no Python in the period. A controller
outside it runs in
Python whatever the choice, and says why in one line
(:attr:`controller.Controller.engine_note`; ``bench run`` and ``bench
controller`` print it, and the controller node's report keeps it): of the
shipped estimators' options only a CIC delay line longer than the core's
(square-wave's ``M`` above 64). Inside it the core runs every period,
the start-up included, and keeps every state; the
:class:`controller.Controller` holds it by composition and forwards its
commands (:mod:`controller._compiled`).

Equal means equal bits, not a tolerance: the C functions repeat the Python
operations in the same order (Python's float ``%`` included), without fused
multiply-adds, and call the same ``libm``; the CIC's re-anchoring sums its
delay line left to right as Python 3.11's ``sum`` does. Purity is
kept: the core reads a measurement's ``theta_e`` and ``w_e`` only for the
sensored baseline.

Why C, as for the plant (:mod:`plant_rt._engine`): the Python step costs
about 5.5 us per period at 10 kHz with tt-dq, of which 1.2 us is only the
construction of the frozen :class:`controller.ControlOutput`; mypyc on the
unchanged modules gave 1.4x on the whole loop. The C step (0.24 us against
5.1 us for Python in the same ``bench perf`` run, docs/BENCHMARKS.md) fills
the output's slots directly, reads the measurement's the same way, and is
called without a Python frame.
"""

from __future__ import annotations

from pathlib import Path
from types import ModuleType
from typing import Any

from controller._registry import SPECS

ENGINES: tuple[str, ...] = ("auto", "compiled", "python")
"""The engine choices of :class:`controller.Controller` (``engine=``)."""

_cctl: ModuleType | None
_why_not: str | None
try:
    import controller._cctl as _built
except ImportError as e:  # not built on this machine
    _cctl = None
    _why_not = (
        f"the compiled controller engine is not built ({e}; it needs a C compiler and Python's "
        "headers when the project is installed): the controller runs in pure Python"
    )
else:
    _cctl = _built
    _why_not = None

#: estimator name -> the kind of the compiled core (controller/_cctl.c), from the registry
_KINDS = {s.name: s.compiled_kind for s in SPECS.values() if s.compiled_kind is not None}


#: The estimators the compiled core covers, by name, with their kernels in C.
COMPILED_ESTIMATORS: tuple[str, ...] = tuple(_KINDS)

#: The core's kind of an estimator outside it, a user's Python estimator: the core calls
#: its ``update``, ``injection`` and ``reset`` each period (``controller/core/cc_estimator.h``,
#: adapted by ``controller/_cctl.c``).
KIND_EXTERNAL = 10

#: The kinds with tt-dq's PLL, which take ``accel_ff`` (tt-dq, hybrid-tt-dq). The core runs
#: every rotating-injection demodulator (tt-dq, tt-ab, sfhf, hybrid-tt-dq, self-demod, epf)
#: with either ``normalise`` and either ``observer``.
_ACCEL_FF_KINDS = (1, 6)


def core_sources() -> list[Path]:
    """The portable controller core's files (``controller/core/*.h``, ``*.c``): plain C99,
    no Python, the code ``firmware/`` builds on and ``bench codegen`` ships."""
    return sorted((Path(__file__).parent / "core").glob("cc_*.[ch]"))


def compiled_controller_missing() -> str | None:
    """None when the compiled engine is built, else one line saying why the controller runs
    in Python."""
    return _why_not


def compiled_cover(pars: Any) -> tuple[int, str | None]:
    """``(kind, None)`` when the compiled core covers the controller ``pars`` describes,
    else ``(0, why)``: the one line saying what keeps it in Python.

    An estimator the registry gives no compiled kind (a plug-in) is
    :data:`KIND_EXTERNAL`: the core runs the controller and calls the estimator's
    Python methods each period, with the options the plug-in takes itself."""
    name = pars.estimator
    kind = _KINDS.get(name, KIND_EXTERNAL)
    if kind == KIND_EXTERNAL:
        return kind, None
    opts = dict(pars.estimator_options)
    if kind not in _ACCEL_FF_KINDS and opts.get("accel_ff", False):
        return 0, f"{name} with accel_ff is not compiled: the controller runs in Python"
    if kind in (4, 7) and int(opts.get("M", 2)) > 64:
        return 0, f"{name} with a CIC delay M > 64 is not compiled: Python"
    return kind, None


def resolve_controller_engine(engine: str, pars: Any) -> tuple[str, str | None]:
    """The engine a controller runs on, ``"compiled"`` or ``"python"``, and why not compiled.

    Parameters
    ----------
    engine : {"auto", "compiled", "python"}
        The choice; ``"auto"`` and ``"compiled"`` take the compiled engine
        when it is built and covers ``pars`` (:func:`compiled_cover`).
    pars : ControllerPars
        The controller's settings.

    Raises
    ------
    ValueError
        For an unknown name, or ``"compiled"`` when the engine is not built.
    """
    if engine not in ENGINES:
        raise ValueError(f"unknown controller engine {engine!r} (known: {', '.join(ENGINES)})")
    if engine == "python":
        return "python", None
    if _why_not is not None:
        if engine == "compiled":
            raise ValueError(_why_not)
        return "python", _why_not
    kind, why = compiled_cover(pars)
    return ("compiled", None) if kind else ("python", why)
