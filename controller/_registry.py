"""Estimators by name, imported lazily, and the user's own as plug-ins.

Each estimator module exposes ``create(motor, T_s, **options) -> Estimator``.
The names are part of the command-line contract (DESIGN.md): ``sfhf``,
``tt-ab``, ``tt-dq``, ``self-demod`` and ``epf`` (Wen's references [27] and
[25], reconstructed), ``square-wave``, ``square-wave-nocic``, ``sensored``,
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
or ``"none"``) tells the controller whether to run the HF start-up
(alignment and polarity test) before the speed loop.  An estimator may
say it itself (attribute ``injection_family``, as every shipped estimator's
class does): a factory that declares none takes its estimator's
(:func:`estimator_family`), so a plug-in that returns a shipped estimator
runs as that estimator does, start-up and designed gains included; a
factory and an estimator that disagree are an error.  A plug-in never
receives the plant's truth (only the built-in ``sensored`` baseline does).

Options (:func:`declared_options`, :func:`hand_over`).  Every estimator's
options are declared as :class:`controller._api.Option` values by name:
the shipped ones from their parameter dataclass or signature and
docstrings, a plug-in by its factory's attribute ``options`` (a mapping of
names to :class:`~controller._api.Option`, or a dataclass whose fields are
the options).  A declared plug-in receives the scenario's options it
declares, checked as declared; one without a declaration receives them all
(``**options``) or the keywords it names.  A plug-in that cannot be
imported, whose declaration is malformed, or whose estimator lacks a member
of :class:`controller._api.Estimator`, raises :class:`EstimatorPluginError`
with one line naming it.

What an estimator is, for the bench, is then four facts: its name, its
factory, its injection family and its declared options (:class:`Plugin`
holds them for a plug-in; ``_ESTIMATORS`` and :func:`_shipped_options` for
a built-in one); one registry entry per estimator can hold the four.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import inspect
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from controller._api import OPTION_KINDS, Estimator, Option
from controller._params import MotorModel

#: name -> (module, fixed keyword options, injection family)
_ESTIMATORS: dict[str, tuple[str, dict[str, Any], str]] = {
    "sfhf": ("controller._sfhf", {}, "rotating"),
    "tt-ab": ("controller._tt_ab", {}, "rotating"),
    "tt-dq": ("controller._tt_dq", {}, "rotating"),
    "self-demod": ("controller._self_demod", {}, "rotating"),
    "epf": ("controller._epf", {}, "rotating"),
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
    family_declared : bool
        The factory sets ``injection_family`` (else ``family`` is ``"none"``
        until the estimator says otherwise, :func:`estimator_family`).
    options : dict or None
        The options it declares (name -> :class:`~controller._api.Option`), None
        without a declaration.
    """

    name: str
    factory: Callable[..., Any]
    family: str
    keywords: tuple[str, ...] | None
    family_declared: bool = True
    options: dict[str, Option] | None = None


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
    declared = getattr(factory, "injection_family", None)
    family = "none" if declared is None else declared
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
    decl = getattr(factory, "options", None)
    options = None if decl is None else _declaration(name, decl)
    if options is not None and keywords is not None:
        unnamed = [k for k in options if k not in keywords]
        if unnamed:
            raise _fail(
                name,
                f"declares options its factory does not take: {', '.join(unnamed)} "
                "(name them as keywords, or take **options)",
            )
    p = Plugin(name, factory, family, keywords, declared is not None, options)
    _PLUGINS[name] = p
    return p


def _declaration(name: str, decl: Any) -> dict[str, Option]:
    """A plug-in's ``options`` attribute as name -> :class:`Option` (one line when malformed)."""
    if isinstance(decl, type) and dataclasses.is_dataclass(decl):
        try:
            return options_of_dataclass(decl)
        except (TypeError, ValueError) as e:
            raise _fail(name, f"options {decl.__name__}: {e}") from None
    if not isinstance(decl, Mapping):
        raise _fail(
            name,
            "options must be a dataclass or a mapping of names to controller.Option, "
            f"got {type(decl).__name__}",
        )
    out: dict[str, Option] = {}
    for k, v in decl.items():
        if not isinstance(k, str) or not k.isidentifier():
            raise _fail(name, f"option name {k!r} is not an identifier")
        if not isinstance(v, Option):
            raise _fail(name, f"option {k!r}: expected a controller.Option, got {type(v).__name__}")
        if v.kind and v.kind not in OPTION_KINDS:
            raise _fail(
                name, f"option {k!r}: kind {v.kind!r} is not one of {', '.join(OPTION_KINDS)}"
            )
        out[k] = v
    return out


def numpydoc_parameters(doc: str) -> dict[str, tuple[str, str]]:
    """``name -> (type, description)`` from the numpydoc ``Parameters`` section of ``doc``."""
    out: dict[str, tuple[str, str]] = {}
    m = re.search(r"Parameters\n\s*-+\n(.*?)(\n\s*\n\s*\S+\n\s*-+\n|\Z)", doc, re.S)
    if not m:
        return out
    names: list[str] = []
    typ = ""
    text: list[str] = []

    def flush() -> None:
        for n in names:
            out[n] = (typ, " ".join(text).strip())

    for line in m.group(1).splitlines():
        head = re.match(r"^\s{0,4}([A-Za-z_][\w, ]*?)\s*:\s*(.*)$", line)
        if head and not line.startswith(" " * 8):
            flush()
            names = [n.strip() for n in head.group(1).split(",")]
            typ, text = head.group(2), []
        elif line.strip():
            text.append(line.strip())
    flush()
    return out


def unit_in(text: str) -> str:
    """The unit a description states in parentheses, ``(rad/s)``; empty without one."""
    m = re.search(r"\(((?:PWM )?periods|rad/s|rad|deg|Hz|V|A|s|-)\)", text)
    return m.group(1) if m else ""


def _plain(text: str) -> str:
    """A docstring's reST roles and literals as Markdown code."""
    return re.sub(r":\w+:`([^`]*)`", r"`\1`", text.replace("``", "`"))


def _kind_of(annotation: Any, default: Any) -> str:
    if default is not None:
        return ""
    a = annotation if isinstance(annotation, str) else getattr(annotation, "__name__", "")
    for kind in ("bool", "int", "str"):
        if re.search(rf"\b{kind}\b", a):
            return kind
    return "float"


def options_of_dataclass(cls: type) -> dict[str, Option]:
    """The options a dataclass declares: one :class:`Option` per field.

    Default and type from the field; meaning and unit from the class's numpydoc
    ``Parameters`` (the unit in parentheses); ``field(metadata=...)`` sets any
    :class:`Option` attribute (``unit``, ``positive``, ``minimum``, ``choices``...).
    """
    doc = numpydoc_parameters(cls.__doc__ or "")
    out: dict[str, Option] = {}
    for f in dataclasses.fields(cls):
        if f.default is not dataclasses.MISSING:
            default = f.default
        elif f.default_factory is not dataclasses.MISSING:
            default = f.default_factory()
        else:
            raise ValueError(f"field {f.name!r} has no default")
        text = _plain(doc.get(f.name, ("", ""))[1])
        kw: dict[str, Any] = {"unit": unit_in(text), "doc": text}
        kw["kind"] = _kind_of(f.type, default)
        kw.update(f.metadata)
        out[f.name] = Option(default, **kw)
    return out


def _options_of_signature(
    func: Callable[..., Any], skip: tuple[str, ...], doc: str
) -> dict[str, Option]:
    """The keyword parameters of ``func`` (less ``skip``) as options, described by ``doc``."""
    text = numpydoc_parameters(doc)
    out: dict[str, Option] = {}
    for k, p in inspect.signature(func).parameters.items():
        if k in skip or p.kind in (p.VAR_KEYWORD, p.VAR_POSITIONAL):
            continue
        d = None if p.default is inspect.Parameter.empty else p.default
        meaning = _plain(text.get(k, ("", ""))[1])
        out[k] = Option(d, unit_in(meaning), meaning, _kind_of(p.annotation, d))
    return out


@functools.cache
def _shipped_options(name: str) -> dict[str, Option]:
    """The declaration of a built-in estimator's options (:func:`declared_options`)."""
    family = _ESTIMATORS[name][2]
    out: dict[str, Option] = {}
    if name == "sensored":
        return out
    if family == "rotating":
        from controller._rotating import RotatingInjectionPars

        out = options_of_dataclass(RotatingInjectionPars)
    else:
        from controller._square_wave import SquareWaveEstimator

        out = _options_of_signature(
            SquareWaveEstimator.__init__,
            ("self", "motor", "T_s", "cic"),
            SquareWaveEstimator.__doc__ or "",
        )
    if name.startswith("hybrid-"):
        from controller._hybrid import _OWN_OPTIONS, design

        own = _options_of_signature(design, ("motor",), design.__doc__ or "")
        own.update(_HYBRID_GAINS)
        out.update({k: own[k] for k in _OWN_OPTIONS})
    return {
        k: dataclasses.replace(
            o, **_SHIPPED_CHECKS.get(k, {"positive": True} if o.value_kind == "float" else {})
        )
        for k, o in out.items()
    }


#: What the shipped estimators' options accept beyond their type, by key; every other
#: number is > 0.  The scenario also holds an injection amplitude (``V_h``, ``U_h``)
#: within the inverter's linear range and ``f_h`` below the Nyquist frequency, which
#: depend on the scenario (``bench/scenarios/_schema.py``).
_SHIPPED_CHECKS: dict[str, dict[str, Any]] = {
    "w_o": {"minimum": 0.0},  # 0 freezes the PLL
    "delay_comp": {"minimum": 0.0},  # periods; 0 disables it
    "u_err": {"minimum": 0.0},  # V
    "M": {"kind": "int", "minimum": 1},  # CIC differential delay, PWM periods
    "normalise": {"choices": ("model", "measured")},
    "observer": {"choices": ("pll", "mechanical")},
}


#: The hybrids' options that override a designed gain (controller._hybrid.create).
_HYBRID_GAINS = {
    "alpha_o": Option(
        None,
        "rad/s",
        "Bandwidth of the hybrids' flux observer's speed tracker; default: designed from theta_acc.",
        positive=True,
    ),
    "zeta_f": Option(
        None,
        "-",
        "Damping of the flux observer's correction; default: the design's.",
        positive=True,
    ),
}


def declared_options(name: str) -> dict[str, Option] | None:
    """The options estimator ``name`` declares, by name; None for a plug-in without a
    declaration (it takes what its factory's signature names, or everything)."""
    if name in _ESTIMATORS:
        return dict(_shipped_options(name))
    p = plugin(name)
    if p is None:
        raise _unknown(name)
    return None if p.options is None else dict(p.options)


def hand_over(name: str, options: Mapping[str, Any]) -> tuple[dict[str, Any], list[str]]:
    """A scenario's options for estimator ``name``: (those it receives, the keys it does not).

    A declared estimator (every shipped one, a plug-in with ``options``)
    receives the keys it declares; a plug-in without a declaration the
    keywords its factory names, or every key when it takes ``**options``.
    """
    decl = declared_options(name)
    if decl is None:
        p = plugin(name)
        kw = None if p is None else p.keywords
        keys: Any = options if kw is None else kw
    else:
        keys = decl
    return {k: v for k, v in options.items() if k in keys}, [k for k in options if k not in keys]


def check_options(name: str, options: Mapping[str, Any]) -> dict[str, Any]:
    """``options`` checked against the plug-in ``name``'s declaration (values in their type).

    Raises :class:`EstimatorPluginError` with one line for a key it does not
    declare or a value its declaration refuses; a plug-in without a
    declaration gets ``options`` unchecked.  The built-in estimators' values are
    checked by the scenario schema (``bench/scenarios/_schema.py``).
    """
    p = plugin(name) if name not in _ESTIMATORS else None
    if p is None or p.options is None:
        return dict(options)
    out: dict[str, Any] = {}
    for k, v in options.items():
        opt = p.options.get(k)
        if opt is None:
            raise _fail(
                name, f"unknown option {k!r} (it declares: {', '.join(p.options) or 'none'})"
            )
        val, why = opt.check(v)
        if why is not None:
            raise _fail(name, f"option {k!r}: {why}")
        out[k] = val
    return out


def estimator_family(name: str, est: object) -> str:
    """The injection family the controller runs ``est`` (built for ``name``) with.

    A built-in name's; a plug-in's declared one, else the estimator's own
    ``injection_family`` (every shipped estimator has one), else ``"none"``.
    A plug-in that declares a family other than its estimator's own is an
    :class:`EstimatorPluginError`.
    """
    entry = _ESTIMATORS.get(name)
    if entry is not None:
        return entry[2]
    own = getattr(est, "injection_family", None)
    p = plugin(name)
    if p is None:
        raise _unknown(name)
    if own is not None and own not in FAMILIES:
        raise _fail(
            name, f"its estimator's injection_family {own!r} is not one of {', '.join(FAMILIES)}"
        )
    if not p.family_declared:
        return own if own is not None else "none"
    if own is not None and own != p.family:
        raise _fail(
            name,
            f"the factory declares injection_family {p.family!r}, its {type(est).__name__} "
            f"is a {own!r} estimator (leave the factory's out, or make them agree)",
        )
    return p.family


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
    kw = check_options(name, options) if p.options is not None else hand_over(name, options)[0]
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
