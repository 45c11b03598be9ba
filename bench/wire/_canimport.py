"""python-can imported without its MF4 support, which is loaded when a ``.mf4`` capture is read.

``import can`` imports its MF4 reader and writer, and they import asammdf (and
through it pandas) whenever it is installed (the ``[mf4]`` extra): about 0.6 s
of CPU on the 2-core machine of docs/BENCHMARKS.md, in every process of a run
(``bench run``, its plant and its controller node), for a format none of them
writes.  The command line (:mod:`bench.cli`) imports python-can through
:func:`import_can_without_mf4`; the one place that reads a ``.mf4`` capture
(:mod:`bench.captures._read`) calls :func:`load_mf4` first, which gives
python-can its MF4 support back when asammdf is installed.  The bench's own
``signals.mf4`` (:mod:`bench.runs._export`) imports asammdf directly and is not
concerned.  A Python program that imports :mod:`bench` (the API) gets python-can
as it is.
"""

from __future__ import annotations

import importlib
import sys

__all__ = ["import_can_without_mf4", "load_mf4"]


def import_can_without_mf4() -> None:
    """Import python-can with its MF4 module's ``import asammdf`` failing, as without asammdf
    (nothing when python-can or asammdf is imported already)."""
    if "can" in sys.modules or "asammdf" in sys.modules:
        return
    sys.modules["asammdf"] = None  # type: ignore[assignment]  # import asammdf: ImportError
    try:
        import can  # noqa: F401
    finally:
        del sys.modules["asammdf"]


def load_mf4() -> None:
    """Give python-can its MF4 reader and writer when asammdf is installed.

    The MF4 module is executed again in place (:func:`importlib.reload`): its
    classes, already registered by suffix in python-can's ``LogReader`` and
    ``Logger``, read ``asammdf`` from that module's globals when used.  Without
    asammdf python-can says so itself, as it always did.
    """
    import can.io.mf4 as mf4

    if mf4.asammdf is not None:
        return
    try:
        import asammdf  # noqa: F401
    except ImportError:
        return
    importlib.reload(mf4)
