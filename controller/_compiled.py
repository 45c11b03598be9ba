"""The controller on the compiled engine: :class:`controller.Controller` with its step in C.

The compiled core (``controller/_cctl.c``, :mod:`controller._engine`) keeps
the states while it steps; the Python objects (the estimator, the PIs, the
speed filter and the controller's own state attributes) hold them whenever
Python reads or changes them. Each state attribute is a property here:

- reading one brings the Python objects up to date from the core (once per
  period at most);
- writing one, or taking one of the objects (``estimator``, ``pi_d``,
  ``pi_q``, ``pi_w``, ``lpf_w``, which the caller may change), hands the
  states over to Python: the next compiled period reads them all again.

So every command (:meth:`set_speed_ref`, :meth:`set_enable`, ...) and every
period the core leaves to Python (it returns None before it changes
anything) runs the Python code on the present states. An object taken
before a run and read after it is not kept up to date: take it again.
"""

from __future__ import annotations

from typing import Any

from controller._api import ControlOutput, Measurement
from controller._controller import Controller, ControllerPars
from controller._engine import _cctl, compiled_cover

#: The states the core keeps (read and written by Core.load and Core.store).
_STATE_VALUES = (
    "mode",
    "_n_mode",
    "_settled",
    "_i_ref",
    "w_m_ref",
    "i_d_ref",
    "i_q_ref",
    "tau_ref",
    "w_m_hat",
    "u_d",
    "u_q",
    "_u_a1",
    "_u_b1",
    "_u_a2",
    "_u_b2",
)
_STATE_OBJECTS = ("estimator", "pi_d", "pi_q", "pi_w", "lpf_w")
#: The module of the estimator class each kind of the core mirrors.
_MODULES = {
    1: "controller._tt_dq",
    2: "controller._tt_ab",
    3: "controller._sfhf",
    4: "controller._square_wave",
    5: "controller._sensored",
    6: "controller._hybrid",
    7: "controller._hybrid",
}
#: The module of a hybrid's injection estimator.
_HF_MODULES = {6: "controller._tt_dq", 7: "controller._square_wave"}


def _state(name: str, handed: bool) -> property:
    """Property of the state ``name``: read from the core when it has stepped since; a write
    (or, with ``handed``, a read) hands the states over to Python."""

    def get(self: CompiledController) -> Any:
        core = self._core
        if core is not None and core.holds:
            if core.dirty:
                core.store(self.__dict__)
            if handed:
                core.holds = False
        return self.__dict__[name]

    def put(self: CompiledController, value: Any) -> None:
        core = self._core
        if core is not None and core.holds:
            if core.dirty:
                core.store(self.__dict__)
            core.holds = False
        self.__dict__[name] = value

    return property(get, put, doc=f"``{name}`` (kept by the compiled core while it steps)")


class CompiledController(Controller):
    """A :class:`controller.Controller` whose periods run in C where the core covers them.

    Built by ``Controller(pars, engine)`` when the engine resolves to
    ``"compiled"``; the same trace as the Python engine, bit for bit.
    """

    _core: Any = None

    def __init__(self, pars: ControllerPars, engine: str = "auto") -> None:
        super().__init__(pars, engine)
        kind, why = compiled_cover(pars)
        est = self.__dict__["estimator"]
        est_mod = type(est).__module__
        if kind in _HF_MODULES and type(getattr(est, "hf", None)).__module__ != _HF_MODULES[kind]:
            est_mod = type(getattr(est, "hf", None)).__module__
        if _cctl is None or not kind or est_mod != _MODULES.get(kind):
            # not built, not covered, or an estimator registered under a compiled one's name
            self.engine_note = why or f"the estimator of {est_mod} is not compiled: Python"
            return
        core = _cctl.Core(kind, Measurement, ControlOutput)
        self._core = core
        self.engine = "compiled"
        self.engine_note = None
        # the step is the core's run(), called directly (no Python frame per period); it
        # hands the periods it leaves to the Python step on the same states
        core.bind(self.__dict__, super().step)
        self.__dict__["step"] = self._supervised(core.run)


for _name in _STATE_VALUES:
    setattr(CompiledController, _name, _state(_name, False))
for _name in _STATE_OBJECTS:
    setattr(CompiledController, _name, _state(_name, True))
