"""Estimators by name: one :class:`EstimatorSpec` per estimator, and the user's own as plug-ins.

An estimator is, for the bench, one :class:`EstimatorSpec`: its name, its
factory ``factory(motor, T_s, **options) -> Estimator``, its injection family,
the dataclass that declares its options (types, ranges, units, meanings),
whether it reads the plant's truth, and the kind of the compiled core that
runs it.  :data:`SPECS` holds the shipped ones; their names are part of the
command-line contract (DESIGN.md): ``sfhf``, ``tt-ab``, ``tt-dq``,
``self-demod`` and ``epf`` (Wen's references [27] and [25], reconstructed),
``square-wave``, ``square-wave-nocic``, ``sensored``, ``hybrid-tt-dq``,
``hybrid-square-wave`` (the injection family of a hybrid is its injection
estimator's: it injects below its transition band).  Everything else reads the
spec (:func:`spec`): the scenario schema, docs/SCENARIOS.md and ``bench list``
are generated from it, the nodes give the truth to an estimator whose spec
``needs_truth``, and nothing tests an estimator's name.

Plug-ins (docs/ESTIMATORS.md).  Wherever an estimator name is taken, a
user's estimator is named

- ``package.module:obj``: an :class:`EstimatorSpec` or a factory ``obj`` of
  an importable module, or
- the name an installed package registers in the entry-point group
  :data:`ENTRY_POINT_GROUP` (``can_hil_bench.estimators``), as python-can
  finds its interfaces; the entry point's object is the spec or the factory.

A plug-in's spec declares its family and options as a shipped one does; a
bare factory may say them as attributes (``injection_family``, ``options``: a
dataclass, or a mapping of names to :class:`~controller._api.Option`).  The
family tells the controller whether to run the HF start-up (alignment and
polarity test) before the speed loop: a plug-in that declares none takes its
estimator's (:func:`estimator_family`), so a plug-in that returns a shipped
estimator runs as that estimator does, start-up and designed gains included;
a declaration and an estimator that disagree are an error.  A plug-in never
receives the plant's truth and its spec names no compiled kind (a plug-in's
spec that asks for either is an error).  The shipped estimators' periods run
in the core alone (their Python is the tests' oracle): a plug-in that returns
one unchanged runs as its kind (:func:`shipped_kind`); one built on a shipped
class without a period of its own, or that returns the sensored baseline, is
refused with one line (docs/ESTIMATORS.md).

Options (:func:`declared_options`, :func:`hand_over`).  A declared estimator
(every shipped one, a plug-in with options) receives the scenario's options it
declares, checked as declared; a plug-in without a declaration receives them
all (``**options``) or the keywords it names.  A plug-in that cannot be
imported, whose declaration is malformed, or whose estimator lacks a member of
:class:`controller._api.Estimator`, raises :class:`EstimatorPluginError` with
one line naming it.
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

from controller import (
    _epf,
    _hybrid,
    _rotating,
    _self_demod,
    _sensored,
    _sfhf,
    _square_wave,
    _tt_ab,
    _tt_dq,
)
from controller._api import OPTION_KINDS, OPTION_LIMITS, Estimator, Option
from controller._params import MotorModel
from controller._rotating import RotatingInjectionPars

#: Entry-point group under which installed packages register estimators.
ENTRY_POINT_GROUP = "can_hil_bench.estimators"

#: The injection families the controller knows.
FAMILIES = ("rotating", "square", "none")

#: Float attributes and methods every estimator has (:class:`controller._api.Estimator`;
#: ``gains`` is optional).
PROTOCOL_ATTRIBUTES = ("theta_hat", "w_hat", "err", "i_alpha_f", "i_beta_f")
PROTOCOL_METHODS = ("update", "injection", "reset")


@dataclass(frozen=True, slots=True)
class EstimatorSpec:
    """Everything the bench knows of one estimator: its registry entry.

    Parameters
    ----------
    name : str
        The name ``--estimator`` and a scenario's ``estimator`` take.
    factory : callable
        ``factory(motor, T_s, **options) -> Estimator``; ``options`` are the
        scenario's values of the keys ``options`` declares.
    family : str
        Injection family (one of :data:`FAMILIES`): ``"rotating"`` (Wen),
        ``"square"`` (Xue) or ``"none"``; an HF family runs the start-up at
        standstill (alignment and polarity test) and needs a salient motor.
    options : type or None
        A dataclass whose fields are the options (a scenario's
        ``[estimator_options]`` keys): default and type from the field, unit
        and meaning from the class's numpydoc ``Parameters``, checks from
        :func:`controller.option_field`.  None: not declared (a plug-in that
        takes what its factory's signature names).
    needs_truth : bool
        It reads the plant's rotor angle and speed (``Measurement.theta_e``,
        ``w_e``): the sensored baseline only (DESIGN.md); the controller node
        then subscribes to the truth and the controller skips the start-up.
    compiled_kind : int or None
        The kind of the compiled core (``controller/_cctl.c``) that runs it;
        None: it runs in Python.
    summary : str
        One line for ``bench list``.
    speed_band : bool
        It hands over between an injection estimator and a flux observer
        through a speed band (:class:`controller.HybridEstimator`): its runs
        report per-band metrics.
    proposed_in : str
        The paper whose proposed method it is (``wen``, ``xue``; the prefix of
        that paper's scenarios), empty for the others: the report checks the
        paper's claims on it.
    """

    name: str
    factory: Callable[..., Any]
    family: str
    options: type | None = None
    needs_truth: bool = False
    compiled_kind: int | None = None
    summary: str = ""
    speed_band: bool = False
    proposed_in: str = ""

    def declared(self) -> dict[str, Option] | None:
        """The options it declares, by name (:func:`options_of_dataclass`); None without
        a declaration."""
        return None if self.options is None else dict(_declared(self.options))


_WEN = RotatingInjectionPars
_XUE = _square_wave.SquareWaveOptions

#: The shipped estimators, by name: their registry entries.
SPECS: dict[str, EstimatorSpec] = {
    s.name: s
    for s in (
        EstimatorSpec("sfhf", _sfhf.create, "rotating", _WEN, compiled_kind=3,
                      summary="synchronous-frame HPF demodulation, conventional (Wen 2.3)"),
        EstimatorSpec("tt-ab", _tt_ab.create, "rotating", _WEN, compiled_kind=2,
                      summary="TT self-demodulation in the alpha-beta axes (Wen 4.2)"),
        EstimatorSpec("tt-dq", _tt_dq.create, "rotating", _WEN, compiled_kind=1,
                      summary="TT self-demodulation in the estimated d-q axes (Wen 4.3)",
                      proposed_in="wen"),
        EstimatorSpec("self-demod", _self_demod.create, "rotating", _WEN, compiled_kind=8,
                      summary="HF response current self-demodulation, Wen's [27]"),
        EstimatorSpec("epf", _epf.create, "rotating", _WEN, compiled_kind=9,
                      summary="estimated position feedback demodulation, Wen's [25]"),
        EstimatorSpec("square-wave", _square_wave.create, "square", _XUE, compiled_kind=4,
                      summary="square-wave injection, CIC interpolation (Xue)",
                      proposed_in="xue"),
        EstimatorSpec("square-wave-nocic", functools.partial(_square_wave.create, cic=False),
                      "square", _XUE, compiled_kind=4,
                      summary="square-wave injection, envelope held (Xue, no CIC)"),
        EstimatorSpec("sensored", _sensored.create, "none", _sensored.SensoredOptions,
                      needs_truth=True, compiled_kind=5,
                      summary="the true angle and speed: the baseline"),
        EstimatorSpec("hybrid-tt-dq", _hybrid.create_tt_dq, "rotating",
                      _hybrid.HybridTtDqOptions, compiled_kind=6, speed_band=True,
                      summary="tt-dq handed over to a flux observer above a speed band"),
        EstimatorSpec("hybrid-square-wave", _hybrid.create_square_wave, "square",
                      _hybrid.HybridSquareWaveOptions, compiled_kind=7, speed_band=True,
                      summary="square-wave handed over to a flux observer above a speed band"),
    )
}  # fmt: skip

#: The built-in estimators.
ESTIMATOR_NAMES: tuple[str, ...] = tuple(SPECS)


class UnknownEstimatorError(ValueError):
    """Raised for an estimator name that is neither built in nor a plug-in."""


class EstimatorPluginError(UnknownEstimatorError):
    """A plug-in that cannot be imported or does not meet the Estimator protocol."""


@dataclass(frozen=True, slots=True)
class Plugin:
    """A user's estimator, resolved from its name.

    Parameters
    ----------
    name : str
        ``package.module:obj`` or an entry-point name.
    factory : callable
        ``factory(motor, T_s, **options) -> Estimator``.
    family : str
        Injection family (one of :data:`FAMILIES`).
    keywords : tuple of str or None
        The keywords the factory names, None when it takes ``**options``.
    family_declared : bool
        The plug-in declares ``injection_family`` (else ``family`` is ``"none"``
        until the estimator says otherwise, :func:`estimator_family`).
    options : dict or None
        The options it declares (name -> :class:`~controller._api.Option`), None
        without a declaration.
    spec : EstimatorSpec
        Its registry entry (``options`` as a dataclass).
    """

    name: str
    factory: Callable[..., Any]
    family: str
    keywords: tuple[str, ...] | None
    family_declared: bool = True
    options: dict[str, Option] | None = None
    spec: EstimatorSpec | None = None


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


def _load_factory(name: str) -> Any:
    """The object (a spec or a factory) named ``name``; None when no plug-in has that name."""
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
    obj = _load_factory(name)
    if obj is None:
        return None
    if isinstance(obj, EstimatorSpec):
        if obj.needs_truth:
            raise _fail(name, "needs_truth: only the built-in sensored baseline reads the truth")
        if obj.compiled_kind is not None:
            raise _fail(name, "compiled_kind: a plug-in runs in Python (leave it None)")
        factory: Any = obj.factory
        declared: Any = obj.family
        decl: Any = obj.options
    else:
        factory = obj
        declared = getattr(factory, "injection_family", None)
        decl = getattr(factory, "options", None)
    if not callable(factory):
        raise _fail(name, f"{type(factory).__name__} object is not callable")
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
    cls = None if decl is None else _declaration(name, decl)
    options = None if cls is None else dict(_declared(cls))
    if options is not None and keywords is not None:
        unnamed = [k for k in options if k not in keywords]
        if unnamed:
            raise _fail(
                name,
                f"declares options its factory does not take: {', '.join(unnamed)} "
                "(name them as keywords, or take **options)",
            )
    spec_ = EstimatorSpec(name, factory, family, cls)
    p = Plugin(name, factory, family, keywords, declared is not None, options, spec_)
    _PLUGINS[name] = p
    return p


def _declaration(name: str, decl: Any) -> type:
    """A plug-in's options as a dataclass (a mapping of names to :class:`Option` becomes
    one); one line when malformed."""
    if isinstance(decl, type) and dataclasses.is_dataclass(decl):
        try:
            _declared(decl)
        except (TypeError, ValueError) as e:
            raise _fail(name, f"options {decl.__name__}: {e}") from None
        return decl
    if not isinstance(decl, Mapping):
        raise _fail(
            name,
            "options must be a dataclass or a mapping of names to controller.Option, "
            f"got {type(decl).__name__}",
        )
    fields: list[tuple[str, Any, Any]] = []
    for k, v in decl.items():
        if not isinstance(k, str) or not k.isidentifier():
            raise _fail(name, f"option name {k!r} is not an identifier")
        if not isinstance(v, Option):
            raise _fail(name, f"option {k!r}: expected a controller.Option, got {type(v).__name__}")
        fields.append((k, Any, dataclasses.field(default=v.default, metadata={_AS_IS: v})))
    cls = dataclasses.make_dataclass("Options", fields, frozen=True)
    try:
        _declared(cls)
    except (TypeError, ValueError) as e:
        raise _fail(name, str(e)) from None
    return cls


#: The metadata key of a field declared by an :class:`Option` itself (a plug-in's mapping).
_AS_IS = "controller.Option"


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

    Default and type from the field; meaning and unit from the numpydoc
    ``Parameters`` of the class or of the base that defines the field (the unit
    in parentheses); the field's metadata (:func:`controller.option_field`) sets
    any :class:`Option` attribute (``unit``, ``positive``, ``minimum``,
    ``choices``, ``limit``...).  Raises ``ValueError`` for a field without a
    default or a check that is not one (kind, limit) and ``TypeError`` for an
    unknown attribute.
    """
    doc: dict[str, tuple[str, str]] = {}
    for base in reversed(cls.__mro__):
        doc.update(numpydoc_parameters(base.__doc__ or ""))
    out: dict[str, Option] = {}
    for f in dataclasses.fields(cls):
        if f.default is not dataclasses.MISSING:
            default = f.default
        elif f.default_factory is not dataclasses.MISSING:
            default = f.default_factory()
        else:
            raise ValueError(f"field {f.name!r} has no default")
        if _AS_IS in f.metadata:
            opt = f.metadata[_AS_IS]
        else:
            text = _plain(doc.get(f.name, ("", ""))[1])
            kw: dict[str, Any] = {"unit": unit_in(text), "doc": text}
            kw["kind"] = _kind_of(f.type, default)
            kw.update(f.metadata)
            opt = Option(default, **kw)
        if opt.kind and opt.kind not in OPTION_KINDS:
            raise ValueError(
                f"option {f.name!r}: kind {opt.kind!r} is not one of {', '.join(OPTION_KINDS)}"
            )
        if opt.limit and opt.limit not in OPTION_LIMITS:
            raise ValueError(
                f"option {f.name!r}: limit {opt.limit!r} is not one of {', '.join(OPTION_LIMITS)}"
            )
        out[f.name] = opt
    return out


@functools.cache
def _declared(cls: type) -> dict[str, Option]:
    return options_of_dataclass(cls)


def spec(name: str) -> EstimatorSpec:
    """The registry entry of estimator ``name``: a shipped one's, or a plug-in's.

    Raises :class:`UnknownEstimatorError` for an unknown name and
    :class:`EstimatorPluginError` for a plug-in that cannot be loaded.
    """
    s = SPECS.get(name)
    if s is not None:
        return s
    p = plugin(name)
    if p is None or p.spec is None:
        raise _unknown(name)
    return p.spec


def declared_options(name: str) -> dict[str, Option] | None:
    """The options estimator ``name`` declares, by name; None for a plug-in without a
    declaration (it takes what its factory's signature names, or everything)."""
    return spec(name).declared()


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
    p = plugin(name) if name not in SPECS else None
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
    s = SPECS.get(name)
    if s is not None:
        return s.family
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
    return spec(name).family


def check_estimator(name: str) -> str:
    """Raise the one-line error of an unknown or broken estimator; its family otherwise."""
    return injection_family(name)


#: The shipped estimators' design classes, each with the registry entry whose core kind
#: runs it (``square-wave-nocic`` is square-wave's class with ``cic`` False, the same kind).
_CLASS_SPEC: dict[type, str] = {
    _tt_dq.TTDQEstimator: "tt-dq",
    _tt_ab.TTABEstimator: "tt-ab",
    _sfhf.SFHFEstimator: "sfhf",
    _self_demod.SelfDemodEstimator: "self-demod",
    _epf.EPFEstimator: "epf",
    _square_wave.SquareWaveEstimator: "square-wave",
    _sensored.SensoredEstimator: "sensored",
}
#: A hybrid's entry, by the class of its injection estimator.
_HYBRID_SPEC: dict[type, str] = {
    _tt_dq.TTDQEstimator: "hybrid-tt-dq",
    _square_wave.SquareWaveEstimator: "hybrid-square-wave",
}
#: The classes whose period runs only in the core (their Python is the tests' oracle).
_SHIPPED_CLASSES: tuple[type, ...] = (
    _rotating.RotatingHFEstimator,
    _square_wave.SquareWaveEstimator,
    _sensored.SensoredEstimator,
    _hybrid.HybridEstimator,
)


def shipped_spec(est: object) -> EstimatorSpec | None:
    """The registry entry of ``est`` when it is a shipped estimator exactly as its factory
    builds it (its design class, not a subclass; a hybrid of a shipped injection
    estimator), else None."""
    t = type(est)
    if t is _hybrid.HybridEstimator:
        name = _HYBRID_SPEC.get(type(getattr(est, "hf", None)))
    else:
        name = _CLASS_SPEC.get(t)
    return None if name is None else SPECS[name]


def shipped_kind(est: object) -> int | None:
    """The core's kind of ``est`` when it is a shipped estimator exactly as its factory
    builds it (:func:`shipped_spec`), else None.

    A shipped estimator's period runs in the core alone (``controller/core/``; its Python
    step is the tests' oracle, ``tests/oracle/``), so its design object has no per-period
    methods: the core runs it as this kind, whoever built it (docs/ESTIMATORS.md).
    """
    s = shipped_spec(est)
    return None if s is None else s.compiled_kind


def _refuse_shipped(est: object, missing: list[str]) -> str | None:
    """Why a plug-in's shipped estimator cannot run (None: it can)."""
    s = shipped_spec(est)
    if s is not None and not s.needs_truth:
        return None  # runs as that kind
    if s is not None:
        return (
            f"it returns the {type(est).__name__}, which reads the plant's truth a plug-in "
            "never receives"
        )
    if not isinstance(est, _SHIPPED_CLASSES) or not missing:
        return None
    return (
        f"{type(est).__name__} is built on a shipped estimator, whose period runs only in the "
        f"core, and has no per-period methods of its own (missing: {', '.join(missing)}): "
        "return the shipped estimator unchanged (it runs as that estimator) or implement "
        "update, injection and reset"
    )


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
        One of :data:`ESTIMATOR_NAMES`, ``package.module:obj`` or an
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
    s = SPECS.get(name)
    if s is not None:
        est: Estimator = s.factory(motor, T_s, **options)
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
    why = _refuse_shipped(obj, missing)
    if why is not None:
        raise _fail(name, why)
    if missing and shipped_kind(obj) is None:
        raise _fail(
            name,
            f"{type(obj).__name__} does not meet the Estimator protocol: "
            f"missing or not float: {', '.join(missing)}",
        )
    plug_in: Estimator = obj
    return plug_in
