"""A user's estimator written in C: a shared library against the core's estimator
interface (``controller/core/cc_estimator.h``), named through a plug-in's factory.

The library exports ``cc_estimator_size`` and ``cc_estimator_init``
(the header says how). :func:`c_estimator` makes the plug-in's factory;
the estimator it builds, :class:`CEstimator`, is a
:class:`controller.Estimator`:

- on the Python engine its methods call the library's functions through
  ``ctypes``;
- on the compiled engine the controller core calls the same functions
  directly (``controller/_compiled.py``), with no Python in the period, so
  the native controller node can run it too.

The two optional members of the interface are the protocol's optional members:
a library whose ``hf_current_next`` is not NULL has the method
``hf_current_next`` (the dead-time feed-forward adds the HF current it predicts),
and one whose ``set_saliency_offset`` is not NULL has the attribute
``saliency_offset`` (with cross-saturation compensation the controller hands it
the offset instead of correcting the angle itself, as for the hybrids); with a
NULL one the member is absent, as on a Python estimator without it.

Both engines give the same trace bit for bit (``tests/test_c_estimator.py``).
A function that returns nonzero is the one error
:data:`C_ESTIMATOR_FAILED` on both engines.
"""

from __future__ import annotations

import ctypes
import dataclasses
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from controller._api import EstimatorInput

#: The error of a C estimator's function that returned nonzero (both engines; the
#: binding controller/_cctl.c raises the same words).
C_ESTIMATOR_FAILED = "the estimator in C failed: a function of its cc_est_if_t returned nonzero"


class _In(ctypes.Structure):
    _fields_ = [
        ("k", ctypes.c_longlong),
        ("i_alpha", ctypes.c_double),
        ("i_beta", ctypes.c_double),
        ("torque", ctypes.c_double),
        ("u_alpha", ctypes.c_double),
        ("u_beta", ctypes.c_double),
        ("running", ctypes.c_int),
        ("accel_ref", ctypes.c_double),
    ]


class _Out(ctypes.Structure):
    _fields_ = [
        ("theta_hat", ctypes.c_double),
        ("w_hat", ctypes.c_double),
        ("err", ctypes.c_double),
        ("i_alpha_f", ctypes.c_double),
        ("i_beta_f", ctypes.c_double),
    ]


_P = ctypes.c_void_p
_D = ctypes.POINTER(ctypes.c_double)
_UPDATE = ctypes.CFUNCTYPE(ctypes.c_int, _P, ctypes.POINTER(_In), ctypes.POINTER(_Out))
_PAIR = ctypes.CFUNCTYPE(ctypes.c_int, _P, _D, _D)
_RESET = ctypes.CFUNCTYPE(ctypes.c_int, _P, ctypes.c_double, ctypes.POINTER(_Out))
_SET = ctypes.CFUNCTYPE(ctypes.c_int, _P, ctypes.c_double)


class _Iface(ctypes.Structure):
    """``cc_est_if_t``."""

    _fields_ = [
        ("ctx", _P),
        ("update", _UPDATE),
        ("injection", _PAIR),
        ("reset", _RESET),
        ("hf_current_next", _PAIR),
        ("set_saliency_offset", _SET),
    ]


class _Design(ctypes.Structure):
    """``cc_est_design_t``."""

    _fields_ = [
        ("n_p", ctypes.c_double),
        ("R_s", ctypes.c_double),
        ("L_d", ctypes.c_double),
        ("L_q", ctypes.c_double),
        ("psi_f", ctypes.c_double),
        ("J", ctypes.c_double),
        ("T_s", ctypes.c_double),
        ("options", _D),
        ("n_options", ctypes.c_int),
    ]


class CEstimator:
    """An estimator in a shared library (module docstring). Subclass it to give the
    design-time members a C library has no place for (``speed_response``, ``gains``).

    Parameters
    ----------
    library : str or os.PathLike
        The shared library (``cc_estimator_size``, ``cc_estimator_init``).
    motor : MotorModel
        The controller's motor model.
    T_s : float
        Control period (s).
    *opts : float
        The plug-in's options, in their declared order.

    Raises
    ------
    ValueError
        The library cannot be loaded, lacks a function, or refuses the design.
    """

    theta_hat: float
    w_hat: float
    err: float
    i_alpha_f: float
    i_beta_f: float

    def __init__(self, library: str | os.PathLike[str], motor: Any, T_s: float, *opts: float):
        path = Path(library)
        try:
            lib = ctypes.CDLL(str(path.resolve()))
            size = lib.cc_estimator_size
            init = lib.cc_estimator_init
        except (OSError, AttributeError) as e:
            raise ValueError(f"estimator library {path}: {e}") from None
        size.restype = ctypes.c_size_t
        size.argtypes = []
        init.restype = ctypes.c_int
        init.argtypes = [_P, ctypes.POINTER(_Iface), ctypes.POINTER(_Design)]
        self.library = path
        self._lib = lib  # kept loaded while the estimator lives
        self._state = ctypes.create_string_buffer(max(1, int(size())))
        self.iface = _Iface()
        values = (ctypes.c_double * max(1, len(opts)))(*opts)
        m = motor
        design = _Design(float(m.n_p), m.R_s, m.L_d, m.L_q, m.psi_f, m.J, T_s, values, len(opts))
        if init(self._state, ctypes.byref(self.iface), ctypes.byref(design)) != 0:
            raise ValueError(f"estimator library {path}: cc_estimator_init refused the design")
        if not (self.iface.update and self.iface.injection and self.iface.reset):
            raise ValueError(f"estimator library {path}: update, injection or reset is NULL")
        self._in = _In()
        self._out = _Out()
        self._a = ctypes.c_double()
        self._b = ctypes.c_double()
        self._saliency_offset = 0.0
        self._publish()

    @property
    def interface_address(self) -> int:
        """The address of its ``cc_est_if_t`` (the compiled controller copies it)."""
        return ctypes.addressof(self.iface)

    def _publish(self) -> None:
        o = self._out
        self.theta_hat = o.theta_hat
        self.w_hat = o.w_hat
        self.err = o.err
        self.i_alpha_f = o.i_alpha_f
        self.i_beta_f = o.i_beta_f

    def update(self, x: EstimatorInput) -> None:
        """Sample ``k`` to the library's ``update``."""
        i = self._in
        i.k, i.i_alpha, i.i_beta, i.torque = x.k, x.i_alpha, x.i_beta, x.torque
        i.u_alpha, i.u_beta, i.running, i.accel_ref = x.u_alpha, x.u_beta, x.running, x.accel_ref
        if self.iface.update(self.iface.ctx, ctypes.byref(i), ctypes.byref(self._out)) != 0:
            raise RuntimeError(C_ESTIMATOR_FAILED)
        self._publish()

    def injection(self) -> tuple[float, float]:
        """The library's ``injection``."""
        a, b = self._a, self._b
        if self.iface.injection(self.iface.ctx, ctypes.byref(a), ctypes.byref(b)) != 0:
            raise RuntimeError(C_ESTIMATOR_FAILED)
        return a.value, b.value

    def reset(self, theta0: float) -> None:
        """The library's ``reset``."""
        if self.iface.reset(self.iface.ctx, float(theta0), ctypes.byref(self._out)) != 0:
            raise RuntimeError(C_ESTIMATOR_FAILED)
        self._publish()

    @property
    def hf_current_next(self) -> Callable[[], tuple[float, float]]:
        """The library's ``hf_current_next`` as the protocol's method; absent
        (``AttributeError``) when the library's is NULL."""
        if not self.iface.hf_current_next:
            raise AttributeError("hf_current_next: NULL in the library's cc_est_if_t")
        return self._hf_current_next

    def _hf_current_next(self) -> tuple[float, float]:
        a, b = self._a, self._b
        if self.iface.hf_current_next(self.iface.ctx, ctypes.byref(a), ctypes.byref(b)) != 0:
            raise RuntimeError(C_ESTIMATOR_FAILED)
        return a.value, b.value

    @property
    def saliency_offset(self) -> float:
        """The cross-saturation offset (rad) last handed to the library's
        ``set_saliency_offset``; absent (``AttributeError``) when that is NULL."""
        if not self.iface.set_saliency_offset:
            raise AttributeError("saliency_offset: set_saliency_offset is NULL in cc_est_if_t")
        return self._saliency_offset

    @saliency_offset.setter
    def saliency_offset(self, offset: float) -> None:
        if not self.iface.set_saliency_offset:
            raise AttributeError("saliency_offset: set_saliency_offset is NULL in cc_est_if_t")
        if self.iface.set_saliency_offset(self.iface.ctx, float(offset)) != 0:
            raise RuntimeError(C_ESTIMATOR_FAILED)
        self._saliency_offset = float(offset)


def c_estimator(
    library: str | os.PathLike[str],
    *,
    family: str = "none",
    options: Any = None,
    cls: type[CEstimator] = CEstimator,
) -> Callable[..., CEstimator]:
    """A plug-in's factory for the estimator in the shared library ``library``.

    ``family`` is its injection family (docs/ESTIMATORS.md); ``options`` its
    options dataclass, whose fields the library receives as numbers, in their
    order; ``cls`` a subclass of :class:`CEstimator` with the design-time
    members. The library is loaded when the factory is called.
    """

    def create(motor: Any, T_s: float, **opts: Any) -> CEstimator:
        values: tuple[float, ...] = ()
        if options is not None:
            o = options(**opts)
            values = tuple(float(getattr(o, f.name)) for f in dataclasses.fields(o))
        return cls(library, motor, T_s, *values)

    create.injection_family = family  # type: ignore[attr-defined]
    if options is not None:
        create.options = options  # type: ignore[attr-defined]
    return create
