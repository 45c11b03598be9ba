"""C headers of a designed controller: the core's design calls with the bench's own values.

``bench codegen --scenario FILE --estimator NAME`` writes ``bench_controller.h``
(:func:`generate_controller_header`) beside the core it ships (``core/``), so a drive
firmware (``firmware/``) initialises its ``cc_foc_t`` exactly as the bench's compiled
controller does. Nothing in it is written by hand: :func:`controller._compiled.build_core`
is run on the :class:`controller.Controller` the bench builds for the scenario, with a
recorder in place of the binding (``controller/_cctl.c``) that records each of the
binding's design calls and its arguments as the call of the core's ``cc_design_*``
function the binding calls for it (``controller/core/cc_design.h``, the one mapping onto
the core's ``_init`` calls), every double printed with ``%.17g`` (round-trip exact). The
header holds:

- ``bench_controller_init(cc_foc_t *c, cc_sup_t *sup)``: ``c`` and ``sup`` zeroed with
  the estimator's kind (``cc_design_init``), then the FOC constants, the three PIs, the
  speed filter, the polarity test, the estimator's blocks, the countermeasures and the
  supervision, in the order the binding receives them; returns 0, or -1 for a value the
  core refuses (the binding raises on the same value, and so does ``bench codegen``);
- ``BENCH_CTL_*`` macros: the estimator's name, the period ``T_s``, whether it needs plant
  truth, whether the supervision runs, and ``BENCH_CTL_RPM_PER_RAD_S``
  (:data:`bench.wire._protocol.RPM_PER_RAD_S`, how a node turns ``speed_ref`` into rad/s);
- ``BENCH_WIRE_<MESSAGE>_<SIGNAL>`` for every signal of ``PwmDuty`` and
  ``CtrlTelemetry``: ``{lo, hi, scale, offset, modulus}`` as the bench's codec encodes
  them, for ``bench_wire_raw()``.

Every ``bench codegen`` also writes ``bench_wire.h`` (:func:`generate_wire_header`):
``bench_wire_raw()``, the codec's encoding (clipped or wrapped, rounded half to even:
``nearbyint``), the one C home of that rule, which the firmware and the bench's native
controller node (``bench/nodes/native/bn_ctl.c``) both include, so the firmware's frames
are the bench node's bit for bit.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

from bench.wire._codec import Codec
from bench.wire._protocol import RPM_PER_RAD_S

__all__ = [
    "CONTROLLER_HEADER",
    "WIRE_HEADER",
    "WIRE_MESSAGES",
    "c_double",
    "design_signatures",
    "generate_controller_header",
    "generate_wire_header",
]

CONTROLLER_HEADER = "bench_controller.h"
"""The generated header's file name."""

WIRE_MESSAGES = ("PwmDuty", "CtrlTelemetry")
"""The messages whose signals' encodings the header carries (the controller's outputs)."""


def c_double(x: float) -> str:
    """``x`` as a C double literal that reads back to the same bits (``%.17g``; a
    literal always with a point or an exponent, so ``-0.0`` keeps its sign)."""
    x = float(x)
    if math.isnan(x):
        return "NAN"
    if math.isinf(x):
        return "INFINITY" if x > 0 else "(-INFINITY)"
    s = f"{x:.17g}"
    if not any(ch in s for ch in ".e"):
        s += ".0"
    return s


def _ll(x: Any) -> str:
    return f"{int(x)}LL"


def _flag(x: Any) -> str:
    return "1" if x else "0"


def _args(*xs: str) -> str:
    return ", ".join(xs)


def _d(*xs: Any) -> list[str]:
    return [c_double(x) for x in xs]


DESIGN_HEADER = "cc_design.h"
"""The core's header of the design functions (``controller/core/cc_design.h``): one
``cc_design_<method>`` per design method of the binding, the one mapping onto the core's
``_init`` calls."""

_PROTO = re.compile(r"^(void|int) cc_design_(\w+)\(([^;]*)\);", re.M)


def _ctype(param: str) -> str:
    """A prototype's parameter without its name: ``const double *pll`` -> ``const double *``."""
    m = re.fullmatch(r"(.+?)\s*(\w+)", " ".join(param.split()))
    if m is None:
        raise ValueError(f"{DESIGN_HEADER}: cannot read the parameter {param!r}")
    return " ".join(m.group(1).replace("*", " * ").split())


def design_signatures() -> dict[str, tuple[bool, tuple[str, ...]]]:
    """``{method: (returns int, parameter types)}`` of every ``cc_design_*`` function of
    the core's :data:`DESIGN_HEADER` (``init`` included: the binding's constructor)."""
    from controller import core_sources

    (path,) = [p for p in core_sources() if p.name == DESIGN_HEADER]
    text = path.read_text(encoding="utf-8")
    return {
        m.group(2): (m.group(1) == "int", tuple(_ctype(q) for q in m.group(3).split(",")))
        for m in _PROTO.finditer(text)
    }


def _c_arg(ctype: str, x: Any) -> str:
    """A recorded Python value as the C argument of a parameter of type ``ctype`` (the
    binding's conversion: a tuple of doubles, flags 1.0/0.0; None -> NULL)."""
    if ctype == "double":
        return c_double(x)
    if ctype == "long long":
        return _ll(x)
    if ctype == "int":
        return str(int(x))
    if ctype in ("const double *", "const long long *") and x is None:
        return "NULL"
    if ctype == "const double *":
        return f"(const double[]){{{_args(*_d(*x))}}}"
    if ctype == "const long long *":
        return f"&(const long long){{{_ll(x)}}}"
    raise ValueError(f"{DESIGN_HEADER}: no C argument for a parameter of type {ctype!r}")


_TARGETS = {"cc_foc_t *": "c", "cc_sup_t *": "sup"}
"""The header's structs, by the parameter types that take them."""

_C_TYPES = (*_TARGETS, "double", "long long", "int", "const double *", "const long long *")
"""Every parameter type :func:`_c_arg` (or :data:`_TARGETS`) prints."""


class _Recorder:
    """Takes the calls :func:`controller._compiled.build_core` makes on ``_cctl.Core`` (and
    the supervision's) and records each as the call of its ``cc_design_*`` function, the
    arguments printed as the parameter types of :data:`DESIGN_HEADER` say: the recorder
    knows the calls and their arguments only, the core how they map onto its ``_init``
    calls (the binding, ``controller/_cctl.c``, calls the same functions).

    Each call is made on a real ``_cctl.Core`` too, so a value the binding refuses
    (a CIC delay, the offset periods) is refused here with the binding's own error."""

    def __init__(self, kind: int, *layout: Any) -> None:
        from controller._engine import _cctl

        if _cctl is None:
            raise ValueError("the compiled controller is not built")
        self._core = _cctl.Core(kind, *layout)
        self._sigs = design_signatures()
        self.lines: list[str] = []
        self.supervision_on = False
        self._record("init", int(kind))

    def _record(self, name: str, *args: Any) -> None:
        returns_int, ctypes = self._sigs[name]
        out: list[str] = []
        vals = list(args)
        for t in ctypes:
            if t in _TARGETS:
                out.append(_TARGETS[t])
            elif vals:
                out.append(_c_arg(t, vals.pop(0)))
            elif t.endswith("*"):  # an optional argument left out: None
                out.append("NULL")
            else:
                raise TypeError(f"cc_design_{name}: too few arguments ({len(args)})")
        if vals:
            raise TypeError(f"cc_design_{name}: too many arguments ({len(args)})")
        call = f"cc_design_{name}({_args(*out)})"
        self.lines.append(f"if ({call} < 0) return -1;" if returns_int else f"{call};")

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_") or name == "init" or name not in self._sigs:
            raise AttributeError(name)
        method = getattr(self._core, name)

        def record(*args: Any) -> None:
            method(*args)  # the binding's checks, and its errors
            if name == "supervision":
                self.supervision_on = True
            self._record(name, *args)

        return record

    def external(self, *_args: Any) -> None:
        raise ValueError(
            "the estimator is Python code (a plug-in): a firmware runs the core's estimators "
            "or an estimator in C"
        )

    def external_c(self, *_args: Any) -> None:
        raise ValueError(
            "an estimator in C of a plug-in is loaded at run time: a firmware links it itself"
        )


def _snake(name: str) -> str:
    from cantools.database.can.c_source import camel_to_snake_case

    return str(camel_to_snake_case(name))


def _wire_lines(codec: Codec) -> list[str]:
    out = []
    for msg in WIRE_MESSAGES:
        for s in codec._spec(msg).sigs:
            macro = f"BENCH_WIRE_{_snake(msg).upper()}_{s.name.upper()}"
            vals = _args(*_d(s.lo, s.hi, s.scale, s.offset), _ll(s.modulus))
            out.append(f"#define {macro} {{{vals}}}")
    return out


WIRE_HEADER = "bench_wire.h"
"""The encoding header's file name (written by every ``bench codegen``)."""

_WIRE_H = """/* Generated by `bench codegen` (bench/wire/_ctlgen.py): do not edit.
 *
 * A signal's raw value as the bench's codec encodes it (bench/wire/_codec.py
 * Codec.encode): the value clipped to [lo, hi], or with modulus > 0 its raw value taken
 * modulo modulus; raw = (value - offset) / scale rounded half to even (nearbyint, the
 * default rounding mode).  The one C home of that rule: the drive firmware's frames
 * (bench_controller.h) and the bench's native controller node
 * (bench/nodes/native/bn_ctl.c) both encode with it.
 */
#ifndef BENCH_WIRE_H
#define BENCH_WIRE_H

#include <math.h>

/* one signal's encoding: {lo, hi, scale, offset, modulus} */
typedef struct {
    double lo, hi, scale, offset;
    long long modulus;
} bench_wire_sig_t;

static inline long long bench_wire_raw(const bench_wire_sig_t *s, double v)
{
    if (s->modulus > 0) {
        long long r = (long long)nearbyint((v - s->offset) / s->scale) % s->modulus;
        return r < 0 ? r + s->modulus : r;
    }
    v = v < s->lo ? s->lo : (v > s->hi ? s->hi : v);
    return (long long)nearbyint((v - s->offset) / s->scale);
}

#endif /* BENCH_WIRE_H */
"""


def generate_wire_header(out_dir: str | Path) -> Path:
    """Write ``bench_wire.h``: ``bench_wire_sig_t`` and ``bench_wire_raw()``, the codec's
    encoding of one signal in C (see the header's comment); returns its path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / WIRE_HEADER
    path.write_text(_WIRE_H, encoding="utf-8")
    return path


def generate_controller_header(
    out_dir: str | Path, ctrl: Any, codec: Codec, *, source: str = ""
) -> Path:
    """Write ``bench_controller.h`` for the designed controller ``ctrl``.

    Parameters
    ----------
    out_dir : str or Path
        Folder (created if missing).
    ctrl : controller.Controller
        The controller as the bench builds it (its estimator must be one the compiled
        core covers: ``ctrl.engine == "compiled"``).
    codec : bench.wire._codec.Codec
        The DBC's codec (the output signals' encodings).
    source : str
        Where the design came from (scenario and estimator), for the header's comment.

    Returns
    -------
    Path
        The header written.

    Raises
    ------
    ValueError
        When the compiled core does not cover ``ctrl`` (the reason in one line).
    """
    from controller._compiled import build_core

    rec, why = build_core(ctrl, _Recorder)
    if rec is None:
        raise ValueError(why or "the controller is not compiled")
    sup = getattr(ctrl, "supervisor", None)
    if sup is not None:
        rec.supervision(*sup.args())
    from controller import estimator_spec

    spec = estimator_spec(ctrl.pars.estimator)
    body = "\n".join(f"    {ln}" for ln in rec.lines)
    text = f"""/* Generated by `bench codegen` (bench/wire/_ctlgen.py): do not edit.
 *
 * The controller {source or ctrl.pars.estimator} as the bench builds it: the design calls
 * its compiled engine makes (controller/_cctl.c), as the calls of the core's cc_design_*
 * functions (cc_design.h) the binding makes, with the values the Python design gives
 * them (doubles printed %.17g, exact).  A firmware that
 * calls bench_controller_init() runs the bench's controller bit for bit.
 */
#ifndef BENCH_CONTROLLER_H
#define BENCH_CONTROLLER_H

#include "bench_wire.h"
#include "cc_design.h"

/* the estimator (its registry name) and the control period [s] */
#define BENCH_CTL_ESTIMATOR "{ctrl.pars.estimator}"
#define BENCH_CTL_T_S {c_double(ctrl.pars.T_s)}
/* 1: the estimator reads the plant's true angle (PlantTruth): not for a drive */
#define BENCH_CTL_NEEDS_TRUTH {_flag(spec.needs_truth)}
/* 1: cc_sup_after() follows every cc_foc_step() (the scenario's supervision) */
#define BENCH_CTL_SUPERVISION {_flag(rec.supervision_on)}
/* BenchCommand.speed_ref [rpm] / this = the speed reference [rad/s] */
#define BENCH_CTL_RPM_PER_RAD_S {c_double(RPM_PER_RAD_S)}

/* c and sup zeroed, then initialised as the bench's compiled controller; 0, or -1 */
static inline int bench_controller_init(cc_foc_t *c, cc_sup_t *sup)
{{
{body}
    return 0;
}}

/* the encodings of the output signals (bench_wire_sig_t, bench_wire_raw(): bench_wire.h) */
{chr(10).join(_wire_lines(codec))}

#endif /* BENCH_CONTROLLER_H */
"""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / CONTROLLER_HEADER
    path.write_text(text, encoding="utf-8")
    return path
