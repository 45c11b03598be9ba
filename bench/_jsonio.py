"""Strict JSON for the files outside scripts read (``metrics.json``).

Python's ``json`` writes ``NaN`` and ``Infinity`` by default, which no
strict JSON parser accepts.  A metric that has no value (a THD without a
window, a real-time factor without a plant report) is written as ``null``.
"""

from __future__ import annotations

import json
import math
from typing import Any


def strict(obj: Any) -> Any:
    """``obj`` with every non-finite float (at any depth) replaced by ``None``."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: strict(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [strict(v) for v in obj]
    return obj


def dumps(obj: Any, **kw: Any) -> str:
    """``json.dumps`` of :func:`strict` ``(obj)``; refuses anything still not strict JSON."""
    return json.dumps(strict(obj), allow_nan=False, **kw)
