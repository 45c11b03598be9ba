"""C header of a designed controller: the core's ``_init`` calls with the bench's own values.

``bench codegen --scenario FILE --estimator NAME`` writes ``bench_controller.h``
(:func:`generate_controller_header`) beside the core it ships (``core/``), so a drive
firmware (``firmware/``) initialises its ``cc_foc_t`` exactly as the bench's compiled
controller does. Nothing in it is written by hand: :func:`controller._compiled.build_core`
is run on the :class:`controller.Controller` the bench builds for the scenario, with a
recorder in place of the binding (``controller/_cctl.c``) that prints each of the
binding's calls as the C calls the binding makes, every double printed with ``%.17g``
(round-trip exact). The header holds:

- ``bench_controller_init(cc_foc_t *c, cc_sup_t *sup)``: ``c`` and ``sup`` zeroed, then
  the estimator's kind, the FOC constants, the three PIs, the speed filter, the polarity
  test, the estimator's blocks, the countermeasures and the supervision, in the order the
  binding receives them; returns 0, or -1 for a CIC delay the core refuses (as the
  binding raises);
- ``BENCH_CTL_*`` macros: the estimator's name, the period ``T_s``, whether it needs plant
  truth, whether the supervision runs, and ``BENCH_CTL_RPM_PER_RAD_S``
  (:data:`bench.wire._protocol.RPM_PER_RAD_S`, how a node turns ``speed_ref`` into rad/s);
- ``BENCH_WIRE_<MESSAGE>_<SIGNAL>`` for every signal of ``PwmDuty`` and
  ``CtrlTelemetry``: ``{lo, hi, scale, offset, modulus}`` as the bench's codec encodes
  them, and ``bench_wire_raw()``, its encoding (clipped or wrapped, rounded half to even:
  ``nearbyint``), so the firmware's frames are the bench node's bit for bit.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from bench.wire._codec import Codec
from bench.wire._protocol import RPM_PER_RAD_S

__all__ = ["CONTROLLER_HEADER", "WIRE_MESSAGES", "c_double", "generate_controller_header"]

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


class _Recorder:
    """Takes the calls :func:`controller._compiled.build_core` makes on ``_cctl.Core`` and
    keeps, for each, the C calls ``controller/_cctl.c`` makes for it (same order, same
    argument conversions: ``d`` -> double, ``L`` -> long long, ``p`` -> truth).

    The binding's mapping written a second time, as C text: tests/test_ctlgen_mapping.py
    fails when the two could disagree (a design method of the binding without its twin
    here, or a design whose header-initialised structs are not the binding's byte for
    byte, over designs that run every method here)."""

    def __init__(self, kind: int, *_layout: Any) -> None:
        self.kind = int(kind)
        self.lines: list[str] = [f"if (cc_estim_init(&c->est, {self.kind}) < 0) return -1;"]
        self.supervision_on = False

    def _call(self, fn: str, *args: str) -> None:
        self.lines.append(f"{fn}({_args(*args)});")

    def foc(self, n_p: Any, L_d: Any, L_q: Any, psi_f: Any, i_max: Any, tau_max: Any,
            t_delay: Any, n_align: Any, n_settle: Any, theta0: Any, raw: Any,
            align: Any) -> None:  # fmt: skip
        self._call(
            "cc_foc_init",
            "c",
            *_d(n_p, L_d, L_q, psi_f, i_max, tau_max, t_delay),
            _ll(n_align),
            _ll(n_settle),
            c_double(theta0),
            _flag(raw),
            _flag(align),
        )

    def pi(self, which: int, k_p: Any, k_i: Any, T_s: Any, k_t: Any) -> None:
        target = ("&c->pi_d", "&c->pi_q", "&c->pi_w")[min(int(which), 2)]
        self._call("cc_pi_init", target, *_d(k_p, k_i, T_s, k_t))

    def speed_filter(self, b0: Any, b1: Any, a1: Any) -> None:
        self._call("cc_fo_init", "&c->lpf_w", *_d(b0, b1, a1))

    def polarity(self, L_d: Any, T_s: Any, i_pulse: Any, u_frac: Any) -> None:
        self._call("cc_polarity_init", "&c->polarity", *_d(L_d, T_s, i_pulse, u_frac))

    def reference_model(self, alpha_s: Any, n_p: Any, a_max: Any, T_s: Any) -> None:
        self._call("cc_ref_init", "&c->ref", *_d(alpha_s, n_p, a_max, T_s))

    def mechanical(self, T_s: Any, g1: Any, g2: Any, g3: Any, gt: Any, l3: Any) -> None:
        self._call("cc_rot_mechanical", "&c->est.rot", *_d(T_s, g1, g2, g3, gt, l3))

    def measured(self, floor: Any) -> None:
        self._call("cc_rot_measured", "&c->est.rot", *_d(floor))

    def accel_ff(self) -> None:
        self.lines.append("c->est.rot.accel_ff = 1;")

    def external(self, *_args: Any) -> None:
        raise ValueError(
            "the estimator is Python code (a plug-in): a firmware runs the core's estimators "
            "or an estimator in C"
        )

    def external_c(self, *_args: Any) -> None:
        raise ValueError(
            "an estimator in C of a plug-in is loaded at run time: a firmware links it itself"
        )

    def rotating(self, V_h: Any, wT: Any, inv_norm: Any, pll: Any, bpf: Any, lpf: Any,
                 hpf: Any, track: Any, quad: Any = None) -> None:  # fmt: skip
        r = "&c->est.rot"
        self._call("cc_rot_init", r, *_d(V_h, wT, inv_norm))
        self._call("cc_pll_init", "&c->est.rot.pll", *_d(*pll))
        self._call("cc_bq2_init", "&c->est.rot.bpf", *_d(*bpf))
        for f in ("lpf", "lpf_ab", "lpf_n"):
            fn = "cc_fo_init" if f == "lpf" else "cc_fo2_init"
            self._call(fn, f"&c->est.rot.{f}", *_d(*lpf))
        self._call("cc_bq2_init", "&c->est.rot.quad", *_d(*(quad or (0.0,) * 5)))
        self._call("cc_fo2_init", "&c->est.rot.hpf", *_d(*(hpf or (0.0,) * 3)))
        if track is not None:
            self._call("cc_rot_tracking", r, *_d(*track))

    def square_wave(self, cic: Any, M: Any, U_h: Any, t_comp: Any, k_err: Any,
                    obs: Any) -> None:  # fmt: skip
        self.lines.append(
            "if (cc_sqw_init(c->est.kind == CC_EST_SQUARE_WAVE ? &c->est.out : &c->est.hyb.hf, "
            f"&c->est.sqw, {_flag(cic)}, {_ll(M)}, {_args(*_d(U_h, t_comp, k_err))}) < 0) "
            "return -1;"
        )
        self._call("cc_luen_init", "&c->est.sqw.obs", *_d(*obs))

    def hybrid(self, obs: Any, band: Any, T_s: Any, n_p: Any, J: Any) -> None:
        self._call(
            "cc_hyb_init",
            "&c->est.out",
            "&c->est.hyb",
            "c->est.kind == CC_EST_HYBRID_SQUARE_WAVE",
            "&c->est.rot",
            "&c->est.sqw",
            *_d(T_s, n_p, J),
        )
        self._call("cc_flux_init", "&c->est.hyb.obs", *_d(*obs))
        self._call("cc_band_init", "&c->est.hyb.band", *_d(*band))

    def compensation(self, dt: Any, cross: Any, cal: Any, hf: Any) -> None:
        if dt is not None:
            T_s, t_dead, v_ce, v_f, i_band, sine, hf_next = dt
            self._call(
                "cc_foc_dead_time",
                "c",
                *_d(T_s, t_dead, v_ce, v_f, i_band),
                _flag(sine),
                _flag(hf_next),
            )
        if cross is not None:
            self._call("cc_foc_cross_saturation", "c", c_double(cross[0]), _flag(cross[1]))
        if cal is not None:
            if int(cal) < 1:
                raise ValueError(f"compiled controller: {int(cal)} offset periods")
            self._call("cc_foc_offset_calibration", "c", _ll(cal))
        if hf is not None:
            self._call("cc_rot_hf_model", "&c->est.rot", *_d(*hf))

    def supervision(self, T_s: Any, i_rail: Any, n_range: Any, i_res: Any, du_stuck: Any,
                    n_stuck: Any, i_min: Any, rho_open: Any, n_open_min: Any,
                    n_open_max: Any, u_uv: Any, u_ov: Any, u_hyst: Any,
                    n_dc: Any) -> None:  # fmt: skip
        self.supervision_on = True
        self._call(
            "cc_sup_init",
            "sup",
            *_d(T_s, i_rail),
            _ll(n_range),
            *_d(i_res, du_stuck),
            _ll(n_stuck),
            *_d(i_min, rho_open),
            _ll(n_open_min),
            _ll(n_open_max),
            *_d(u_uv, u_ov, u_hyst),
            _ll(n_dc),
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
 * The controller {source or ctrl.pars.estimator} as the bench builds it: the calls its
 * compiled engine makes to the core's _init functions (controller/_cctl.c), with the
 * values the Python design gives them (doubles printed %.17g, exact).  A firmware that
 * calls bench_controller_init() runs the bench's controller bit for bit.
 */
#ifndef BENCH_CONTROLLER_H
#define BENCH_CONTROLLER_H

#include <math.h>
#include <string.h>

#include "cc_foc.h"
#include "cc_supervision.h"

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
    memset(c, 0, sizeof *c);
    memset(sup, 0, sizeof *sup);
{body}
    (void)sup;
    return 0;
}}

/* One output signal's encoding as the bench's codec applies it (bench/wire/_codec.py):
 * the value clipped to [lo, hi], or with modulus > 0 its raw value taken modulo modulus;
 * raw = (value - offset) / scale rounded half to even. */
typedef struct {{
    double lo, hi, scale, offset;
    long long modulus;
}} bench_wire_sig_t;

{chr(10).join(_wire_lines(codec))}

static inline long long bench_wire_raw(const bench_wire_sig_t *s, double v)
{{
    if (s->modulus > 0) {{
        long long r = (long long)nearbyint((v - s->offset) / s->scale) % s->modulus;
        return r < 0 ? r + s->modulus : r;
    }}
    v = v < s->lo ? s->lo : (v > s->hi ? s->hi : v);
    return (long long)nearbyint((v - s->offset) / s->scale);
}}

#endif /* BENCH_CONTROLLER_H */
"""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / CONTROLLER_HEADER
    path.write_text(text, encoding="utf-8")
    return path
