"""The controller core's binding (``controller/_cctl.c``), or one line saying it is not built.

The engine (:mod:`controller._engine`) and the public per-period blocks
(:class:`controller.PIController`, :func:`controller.svpwm`, ...) import it from here.
"""

from __future__ import annotations

try:
    import controller._cctl as _cctl
except ImportError as e:  # not built on this machine
    raise ImportError(
        f"controller: the controller core (controller/core, C) is not built ({e}): install a C "
        "compiler and Python's headers (tools/need-cc) and reinstall the project (pip install -e .)"
    ) from None

__all__ = ["_cctl"]
