"""The controller's engine: the controller core (``controller/core/``) built from a designed
:class:`controller.Controller`.

Python designs every gain, filter and threshold (each with its derivation, in
:mod:`controller._controller` and the estimators' modules); :func:`build_core`
hands those values, by position, to the core's ``_init`` functions through the
binding ``controller/_cctl.c``. From then on the core runs every period, the
start-up (alignment, polarity test, settling) included, and keeps every state;
the controller forwards its commands to it. The Python objects stay the design
(:meth:`controller.Controller.gains` reads them); the states a caller may read
are :meth:`controller.Controller.states`.
"""

from __future__ import annotations

from dataclasses import fields
from typing import Any

from controller._api import ControlOutput, EstimatorInput, Measurement
from controller._cplugin import CEstimator
from controller._engine import KIND_EXTERNAL, _cctl
from controller._epf import EPFEstimator
from controller._filters import Biquad2, FirstOrder, FirstOrder2
from controller._hybrid import HybridEstimator
from controller._luenberger import LuenbergerObserver
from controller._pll import PositionObserver
from controller._registry import shipped_kind
from controller._rotating import RotatingHFEstimator
from controller._square_wave import SquareWaveEstimator


def _fo(f: FirstOrder | FirstOrder2) -> tuple[float, float, float]:
    return (f.b0, f.b1, f.a1)


def _bq(f: Biquad2) -> tuple[float, float, float, float, float]:
    return (f.b0, f.b1, f.b2, f.a1, f.a2)


def _rotating(core: Any, est: RotatingHFEstimator, tracking: bool) -> None:
    pll: Any = est.pll
    mech = isinstance(pll, LuenbergerObserver)  # observer = "mechanical"
    assert mech or isinstance(pll, PositionObserver)
    e: Any = est
    hpf = getattr(e, "_hpf", None)
    quad = getattr(e, "_quad", None)
    # the LPF of eq. (13); epf's two sequences each have one, with the same coefficients
    lpf = e._lpf_p if isinstance(est, EPFEstimator) else e._lpf
    core.rotating(
        est.V_h,
        est.wT,
        e._inv_norm,
        (0.0, 0.0, pll.T_s) if mech else (pll.k_p, pll.k_i, pll.T_s),
        _bq(e._bpf),
        _fo(lpf),
        None if hpf is None else _fo(hpf),
        (est.w_h, est.T_s, est.bpf_B, e._w0_min) if tracking and est.bpf_tracking else None,
        None if quad is None else _bq(quad),
    )
    if mech:
        core.mechanical(pll.T_s, pll._g1, pll._g2, pll._g3, pll._gt, e._l3)
    if est.measured:  # normalise = "measured"
        core.measured(e._floor)


def _square_wave(core: Any, est: SquareWaveEstimator) -> None:
    o: Any = est.observer
    e: Any = est
    core.square_wave(
        est.cic, est.M, est.U_h, e._t_comp, e._k_err, (o.T_s, o._g1, o._g2, o._g3, o._gt)
    )


def instance_kind(est: object) -> int:
    """The core's kind that runs ``est``: a shipped estimator's, exactly as its factory
    builds it (:func:`controller._registry.shipped_kind`), else :data:`KIND_EXTERNAL` (a
    plug-in's Python estimator, a subclass of a shipped one that brings its own period)."""
    kind = shipped_kind(est)
    return KIND_EXTERNAL if kind is None else kind


def _slots(cls: type) -> tuple[Any, ...]:
    """The slot descriptors of a slotted dataclass, in the order of its fields (the layout
    the binding reads and fills, as a struct's)."""
    return tuple(vars(cls)[f.name] for f in fields(cls))


def build_core(ctrl: Any, core_type: Any = None) -> tuple[Any, str | None]:
    """``(core, None)``: the core for the designed controller ``ctrl`` (a
    :class:`controller.Controller`); the pair's second item, once the reason a controller
    ran in Python, is kept for :mod:`bench.wire._ctlgen` and is always None.

    A shipped estimator runs as its kind whoever built it (the registry by name, or a
    plug-in that returns it unchanged); any other estimator, a subclass of a shipped one
    among them, is the core's external estimator: the core calls its Python methods
    (:func:`instance_kind`).
    ``core_type`` takes the binding's calls instead of ``_cctl.Core`` (same constructor and
    methods): ``bench codegen`` records them as C for a firmware (:mod:`bench.wire._ctlgen`).
    """
    pars = ctrl.pars
    est = ctrl.estimator
    kind = instance_kind(est)
    if core_type is None:
        core_type = _cctl.Core
    core = core_type(kind, Measurement, _slots(Measurement), ControlOutput, _slots(ControlOutput))
    m = ctrl.motor
    core.foc(
        float(m.n_p),
        m.L_d,
        m.L_q,
        m.psi_f,
        ctrl.i_max,
        ctrl.tau_max,
        ctrl.t_delay,
        ctrl.n_align,
        ctrl.n_settle,
        pars.theta0,
        ctrl.raw_feedback,
        ctrl.family != "none" and pars.startup,
    )
    for which, pi in enumerate((ctrl.pi_d, ctrl.pi_q, ctrl.pi_w)):
        core.pi(which, pi.k_p, pi.k_i, pi.T_s, pi.k_t)
    core.speed_filter(*_fo(ctrl.lpf_w))
    ref = ctrl.ref_model
    core.reference_model(ref.alpha_s, float(ref.n_p), ref.a_max, ref.T_s)
    pt = ctrl.polarity
    core.polarity(pt.L_d, pt.T_s, pt.i_pulse, pt.u_frac)
    if kind == KIND_EXTERNAL and isinstance(est, CEstimator):
        core.external_c(est.interface_address)  # a user's estimator in C: no Python
    elif kind == KIND_EXTERNAL:
        core.external(est, EstimatorInput, _slots(EstimatorInput))
    elif kind in (1, 2, 3, 8, 9):
        _rotating(core, est, kind == 1)
    elif kind == 4:
        _square_wave(core, est)
    elif kind in (6, 7):
        hf = est.hf
        if kind == 6:
            _rotating(core, hf, True)
            if hf.accel_ff:
                core.accel_ff()
            tr_T_s = est.tracker.T_s
            # observer = "mechanical": the Luenberger tracker's model, -n_p / J
            mech = hf.mechanical
            n_p, J = (float(hf.pll.n_p), hf.pll.J) if mech else (0.0, 1.0)
        else:
            _square_wave(core, hf)
            tr_T_s = hf.T_s
            n_p, J = float(hf.observer.n_p), hf.observer.J
        o = est.observer
        b = est.band
        core.hybrid(
            (o.R_s, o.L_d, o.L_q, o.psi_f, o.T_s, o.zeta_f, o.w_min, o.k_p, o.k_i),
            (b.w_lo, b.w_mid, b.w_hi, b.h),
            tr_T_s,
            n_p,
            J,
        )
    if kind == 1 and est.accel_ff:
        core.accel_ff()
    _compensation(core, ctrl, est, kind == KIND_EXTERNAL)
    return core, None


def _compensation(core: Any, ctrl: Any, est: Any, external: bool) -> None:
    """The countermeasures the controller designed (:mod:`controller._compensation`),
    switched on in the core as in the Python step (an external estimator predicts its HF
    current itself)."""
    dt = ctrl.dead_time
    cal = ctrl.calibration
    hf: Any = est.hf if isinstance(est, HybridEstimator) else est
    rot = isinstance(hf, RotatingHFEstimator) and not external
    core.compensation(
        None
        if dt is None
        else (dt.T_s, dt.t_dead, dt.v_ce, dt.v_f, dt.i_band, dt.sine, ctrl._predicts_hf),
        (ctrl.motor.k_dq, ctrl._sal_own) if ctrl.cross_sat else None,
        None if cal is None else cal.n,
        (hf.I_p, hf.I_n) if rot else None,
    )
