"""Estimators by name, imported lazily, and the user's own as plug-ins.

Each estimator module exposes ``create(motor, T_s, **options) -> Estimator``.
The names are part of the command-line contract (DESIGN.md): ``sfhf``,
``tt-ab``, ``tt-dq``, ``square-wave``, ``square-wave-nocic``, ``sensored``,
``hybrid-tt-dq``, ``hybrid-square-wave`` (the injection family of a hybrid is
its injection estimator's: it injects below its transition band).

Plug-ins (docs/ESTIMATORS.md).  Wherever an estimator name is taken, a
user's estimator is named

- ``package.module:factory``: the callable ``factory`` of an importable
  module, called as ``factory(motor, T_s, **options)``, or
- the name an installed package registers in the entry-point group
  :data:`ENTRY_POINT_GROUP` (``can_hil_bench.estimators``), as python-can
  finds its interfaces; the entry point's object is the factory.

The factory's attribute ``injection_family`` (``"rotating"``, ``"square"``
or ``"none"``, the default) tells the controller whether to run the
HF start-up (alignment and polarity test) before the speed loop.  A
plug-in never receives the plant's truth (only the built-in ``sensored``
baseline does).  The scenario's ``[estimator_options]`` are passed as
keywords; a factory without ``**options`` receives only the keywords it
names.  A plug-in that cannot be imported, or whose estimator lacks a member
of :class:`controller._api.Estimator`, raises :class:`EstimatorPluginError`
with one line naming it.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable
from dataclasses import dataclass
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

#: The built-in estimators.
ESTIMATOR_NAMES: tuple[str, ...] = tuple(_ESTIMATORS)

#: Entry-point group under which installed packages register estimator factories.
ENTRY_POINT_GROUP = "can_hil_bench.estimators"

#: The injection families the controller knows.
FAMILIES = ("rotating", "square", "none")

#: Float attributes and methods every estimator has (:class:`controller._api.Estimator`;
#: ``gains`` is optional).
PROTOCOL_ATTRIBUTES = ("theta_hat", "w_hat", "err", "i_alpha_f", "i_beta_f")
PROTOCOL_METHODS = ("update", "injection", "reset")


class UnknownEstimatorError(ValueError):
    """Raised for an estimator name that is neither built in nor a plug-in."""


class EstimatorPluginError(UnknownEstimatorError):
    """A plug-in that cannot be imported or does not meet the Estimator protocol."""


@dataclass(frozen=True, slots=True)
class Plugin:
    """A user's estimator factory, resolved from its name.

    Parameters
    ----------
    name : str
        ``package.module:factory`` or an entry-point name.
    factory : callable
        ``factory(motor, T_s, **options) -> Estimator``.
    family : str
        Injection family (one of :data:`FAMILIES`).
    keywords : tuple of str or None
        The keywords the factory names, None when it takes ``**options``.
    """

    name: str
    factory: Callable[..., Any]
    family: str
    keywords: tuple[str, ...] | None


_PLUGINS: dict[str, Plugin] = {}


def is_plugin_name(name: str) -> bool:
    """True for ``package.module:factory`` (a name with a colon)."""
    return ":" in name


def entry_point_names() -> tuple[str, ...]:
    """The estimator names installed packages register (:data:`ENTRY_POINT_GROUP`)."""
    from importlib.metadata import entry_points

    return tuple(sorted({ep.name for ep in entry_points(group=ENTRY_POINT_GROUP)}))


def _fail(name: str, why: str) -> EstimatorPluginError:
    return EstimatorPluginError(f"estimator plug-in {name!r}: {why} (docs/ESTIMATORS.md)")


def _import_user_module(mod_name: str) -> Any:
    """Import ``mod_name``; a module in the working folder is found too (as ``python -m`` does),
    also when the ``bench`` script's own folder, not the working folder, heads ``sys.path``."""
    import os
    import sys

    try:
        return importlib.import_module(mod_name)
    except ModuleNotFoundError as e:
        cwd = os.getcwd()
        if e.name != mod_name.partition(".")[0] or cwd in sys.path or "" in sys.path:
            raise
        sys.path.append(cwd)
        return importlib.import_module(mod_name)


def _load_factory(name: str) -> Callable[..., Any] | None:
    """The factory object named ``name``; None when no plug-in has that name."""
    if is_plugin_name(name):
        mod_name, _, attr = name.partition(":")
        if not mod_name or not attr:
            raise _fail(name, "expected package.module:factory")
        try:
            module = _import_user_module(mod_name)
        except Exception as e:  # the user's code: any error is the plug-in's
            raise _fail(name, f"cannot import {mod_name}: {type(e).__name__}: {e}") from None
        obj: Any = module
        for part in attr.split("."):
            if not hasattr(obj, part):
                raise _fail(name, f"module {mod_name} has no {attr!r}")
            obj = getattr(obj, part)
        return obj
    from importlib.metadata import entry_points

    eps = [ep for ep in entry_points(group=ENTRY_POINT_GROUP) if ep.name == name]
    if not eps:
        return None
    try:
        return eps[0].load()
    except Exception as e:
        raise _fail(
            name, f"entry point {eps[0].value} cannot be loaded: {type(e).__name__}: {e}"
        ) from None


def plugin(name: str) -> Plugin | None:
    """The plug-in called ``name`` (cached), or None when there is none."""
    if name in _PLUGINS:
        return _PLUGINS[name]
    factory = _load_factory(name)
    if factory is None:
        return None
    if not callable(factory):
        raise _fail(name, f"{type(factory).__name__} object is not callable")
    family = getattr(factory, "injection_family", "none")
    if family not in FAMILIES:
        raise _fail(name, f"injection_family {family!r} is not one of {', '.join(FAMILIES)}")
    keywords: tuple[str, ...] | None = None
    try:
        params = list(inspect.signature(factory).parameters.values())
    except (TypeError, ValueError):
        params = []
    else:
        if not any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params):
            keywords = tuple(p.name for p in params[2:] if p.kind is not p.VAR_POSITIONAL)
        pos = [p for p in params if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
        if len(pos) < 2 and not any(p.kind is p.VAR_POSITIONAL for p in params):
            raise _fail(name, "the factory must take (motor, T_s, **options)")
    p = Plugin(name, factory, family, keywords)
    _PLUGINS[name] = p
    return p


def _unknown(name: str) -> UnknownEstimatorError:
    known = [*ESTIMATOR_NAMES, *entry_point_names()]
    return UnknownEstimatorError(
        f"unknown estimator {name!r}; known: {', '.join(known)}, "
        "or a plug-in as package.module:factory"
    )


def injection_family(name: str) -> str:
    """``"rotating"`` (Wen), ``"square"`` (Xue) or ``"none"`` (sensored, most plug-ins).

    Raises :class:`UnknownEstimatorError` for an unknown name and
    :class:`EstimatorPluginError` for a plug-in that cannot be loaded.
    """
    entry = _ESTIMATORS.get(name)
    if entry is not None:
        return entry[2]
    p = plugin(name)
    if p is None:
        raise _unknown(name)
    return p.family


def check_estimator(name: str) -> str:
    """Raise the one-line error of an unknown or broken estimator; its family otherwise."""
    return injection_family(name)


def missing_members(est: object) -> list[str]:
    """The members of the Estimator protocol ``est`` lacks (empty: it meets it)."""
    missing = [
        a
        for a in PROTOCOL_ATTRIBUTES
        if not isinstance(getattr(est, a, None), float | int) or isinstance(getattr(est, a), bool)
    ]
    missing += [f"{m}()" for m in PROTOCOL_METHODS if not callable(getattr(est, m, None))]
    return missing


def make_estimator(name: str, motor: MotorModel, T_s: float, **options: Any) -> Estimator:
    """Build the estimator called ``name`` for a controller sampling every ``T_s`` s.

    Parameters
    ----------
    name : str
        One of :data:`ESTIMATOR_NAMES`, ``package.module:factory`` or an
        entry-point name (module docstring).
    motor : MotorModel
        The controller's own (estimated) motor model.
    T_s : float
        Control period = PWM period (s).
    **options
        Estimator-specific settings (injection amplitude, frequency, filter
        corners, observer bandwidth); unknown keys of a built-in estimator
        raise ``TypeError``.
    """
    entry = _ESTIMATORS.get(name)
    if entry is not None:
        module_name, fixed, _ = entry
        module = importlib.import_module(module_name)
        est: Estimator = module.create(motor, T_s, **fixed, **options)
        return est
    p = plugin(name)
    if p is None:
        raise _unknown(name)
    kw = options if p.keywords is None else {k: v for k, v in options.items() if k in p.keywords}
    try:
        obj = p.factory(motor, T_s, **kw)
    except TypeError as e:
        raise TypeError(f"estimator plug-in {name!r}: {e}") from None
    missing = missing_members(obj)
    if missing:
        raise _fail(
            name,
            f"{type(obj).__name__} does not meet the Estimator protocol: "
            f"missing or not float: {', '.join(missing)}",
        )
    plug_in: Estimator = obj
    return plug_in
