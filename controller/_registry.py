"""Estimators by name, imported lazily.

Each estimator module exposes ``create(motor, T_s, **options) -> Estimator``.
The names are part of the command-line contract (DESIGN.md): ``sfhf``,
``tt-ab``, ``tt-dq``, ``square-wave``, ``square-wave-nocic``, ``sensored``,
``hybrid-tt-dq``, ``hybrid-square-wave`` (the injection family of a hybrid is
its injection estimator's: it injects below its transition band).
"""

from __future__ import annotations

import importlib
from typing import Any

from controller._api import Estimator
from controller._params import MotorModel

#: name -> (module, fixed keyword options, injection family)
_ESTIMATORS: dict[str, tuple[str, dict[str, Any], str]] = {
    "sfhf": ("controller._sfhf", {}, "rotating"),
    "tt-ab": ("controller._tt_ab", {}, "rotating"),
    "tt-dq": ("controller._tt_dq", {}, "rotating"),
    "square-wave": ("controller._square_wave", {"cic": True}, "square"),
    "square-wave-nocic": ("controller._square_wave", {"cic": False}, "square"),
    "sensored": ("controller._sensored", {}, "none"),
    "hybrid-tt-dq": ("controller._hybrid", {"hf": "tt-dq"}, "rotating"),
    "hybrid-square-wave": ("controller._hybrid", {"hf": "square-wave"}, "square"),
}

ESTIMATOR_NAMES: tuple[str, ...] = tuple(_ESTIMATORS)


class UnknownEstimatorError(ValueError):
    """Raised for an estimator name that is not in :data:`ESTIMATOR_NAMES`."""


def injection_family(name: str) -> str:
    """``"rotating"`` (Wen), ``"square"`` (Xue) or ``"none"`` (sensored)."""
    try:
        return _ESTIMATORS[name][2]
    except KeyError:
        raise UnknownEstimatorError(
            f"unknown estimator {name!r}; known: {', '.join(ESTIMATOR_NAMES)}"
        ) from None


def make_estimator(name: str, motor: MotorModel, T_s: float, **options: Any) -> Estimator:
    """Build the estimator called ``name`` for a controller sampling every ``T_s`` s.

    Parameters
    ----------
    name : str
        One of :data:`ESTIMATOR_NAMES`.
    motor : MotorModel
        The controller's own (estimated) motor parameters.
    T_s : float
        Control period = PWM period (s).
    **options
        Estimator-specific settings (injection amplitude, frequency, filter
        corners, observer bandwidth); unknown keys raise ``TypeError``.
    """
    injection_family(name)
    module_name, fixed, _ = _ESTIMATORS[name]
    module = importlib.import_module(module_name)
    est: Estimator = module.create(motor, T_s, **fixed, **options)
    return est
