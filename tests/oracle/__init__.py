"""The oracle: the controller's per-period step in Python, the reference the core is checked
against.

The controller has one engine, the portable C core ``controller/core/``
(:mod:`controller._engine`); ``"auto"``, ``"compiled"`` and ``"python"`` are
accepted names for it, kept for compatibility. The Python step that was the
``"python"`` engine lives here, in ``tests/``, as a readable reference model
(:class:`tests.oracle.controller.OracleController`), not as a second product.
The oracle tests (``tests/test_controller_engine.py``, ``tests/test_accel_ff.py``,
``tests/test_c_estimator.py``) run both on the same measurements and compare
at :data:`TOLERANCE`; ``tests/test_compensation.py``,
``tests/test_closed_form_flux_observer.py`` and
``tests/test_native_controller.py`` use the oracle where they read the
step's Python objects.

Inventory of the controller's per-period kernels and decisions
--------------------------------------------------------------

The controller's period (moved here, called by nothing else):

- ``Controller.step``, ``_polarity_step``, ``_advance_mode``, ``_restart``
  and the Python sides of ``set_enable``, ``set_speed_ref``,
  ``set_current_ref``, ``states``, ``injection``, and the supervision's
  ``Supervisor.wrap`` around the step: only the ``"python"`` engine called
  them. :class:`~tests.oracle.controller.OracleController` holds them; the
  :class:`controller.Controller` forwards each command to the core and reads
  its states from it.
- ``ReferenceModel.update``/``reset`` (the speed loop's designed response,
  ``accel_ref``; ``controller/core/cc_reference.c``): only the Python step
  and its own test called them. ``controller._controller.ReferenceModel``
  keeps the design (``alpha_s``, ``n_p``, ``a_max``, ``T_s``);
  :class:`tests.oracle.blocks.OracleReferenceModel` adds the step, the
  pattern for the blocks below.
- The engine choice: every name runs the core
  (:func:`controller.resolve_controller_engine`); ``Controller.engine`` is
  ``"compiled"`` and ``engine_note`` None (the node report keeps both keys).
- The one case outside the core, a CIC delay ``M > 64`` (square-wave,
  hybrid-square-wave), is now a typed option range, ``M`` in ``1 .. 64``
  (``controller._cctl.CIC_MAX``, the core's fixed delay line), declared on
  :class:`controller._square_wave.SquareWaveOptions`: the scenario schema
  refuses a longer one in one line. Why a range and not a longer line in the
  core: the core allocates nothing, so a longer line makes every instance's
  struct larger (four interpolators, on the firmware's RAM too), and it buys
  nothing: the observer pole the design derives falls with ``M``
  (4.45 rad/s at ``M = 64`` and 1 ms), already seven times slower than the
  speed loop it must follow.

The public blocks a user may call per period (``controller/__init__.py``; a
plug-in may compose them, ``docs/ESTIMATORS.md``) are bindings of the core:
``PIController`` (cc_pi), ``PositionObserver`` (cc_pll), ``FluxObserver``
(cc_flux_observer), ``PolarityTest`` (cc_startup), ``Supervisor``'s check,
release and windows (cc_supervision), ``TransitionBand.play``/``weights``
(cc_hybrid), ``svpwm`` and ``limit_magnitude`` (cc_svpwm), each a small type of
``controller/_cctl.c`` holding the core's struct or a function calling the core's;
so are the compensation's laws ``smooth_sign`` and ``cross_saturation_offset``
(cc_compensation), and ``DeadTimeCompensator.voltage``, which only the oracle's
duties called, moved here with them. Their Python steps moved
here (:mod:`tests.oracle.blocks`, ``Oracle*`` classes and the functions
``svpwm``, ``limit_magnitude``, ``smooth_sign``, ``cross_saturation_offset``), checked by ``tests/test_controller_blocks.py``;
``Supervisor.wrap`` stays in ``controller/`` (it orders a Python step, the
check and the release, as ``cc_sup_after`` does in the core). The hybrids'
trackers' ``sync`` stays too: its C twin is static in ``cc_hybrid.c`` and works
on the whole hybrid, and the Python one is a ``reset`` call of a bound block
(the PLL) or of a design (the Luenberger observer). The transforms
(``clarke``, ``park``, ``inv_park``, ``inv_clarke``, ``wrap_pi``,
``wrap_2pi``) stay Python by decision (docs/DEVELOPMENT.md, "The engines").

Moved here (:mod:`tests.oracle.estimators`, :mod:`tests.oracle.blocks`): the
shipped estimators' ``update``/``injection``/``hf_current_next`` (``_tt_dq``,
``_tt_ab``, ``_sfhf``, ``_self_demod``, ``_epf``, ``_rotating``,
``_square_wave``, ``_sensored``, ``_hybrid``) and their blocks' steps
(``_filters`` ``FirstOrder``/``FirstOrder2``/``Biquad2.update``, ``_cic``
``CicFilter``/``CicInterpolator.step`` and ``prime``, ``_luenberger.step``,
``_compensation`` ``DeadTimeCompensator.duties``/``OffsetCalibration.add``).
Each oracle class subclasses its design (gains, derivations, coefficients,
option dataclasses and the ``__init__`` that computes them stay in
``controller/``, with ``reset``, the state the core starts from) and adds the
step; :func:`tests.oracle.blocks.oracle` turns a built design into its oracle
in place. Whether the dead-time feed-forward adds a predicted HF current is a
fact of the design (``predicts_hf``: the rotating estimators and the hybrids),
no longer the presence of a method. A plug-in that returns a shipped
estimator unchanged runs in the core as that estimator's kind; one that
subclasses a shipped estimator is an external Python estimator calling its own
methods (:func:`controller._compiled.instance_kind`, docs/ESTIMATORS.md).
"""

from __future__ import annotations

from typing import Any

from bench.scenarios._setup import build_controller, controller_pars
from tests.oracle.controller import OracleController

__all__ = ["TOLERANCE", "OracleController", "build"]

#: The oracle tests' tolerance: 0, every output's bits (the core repeats the oracle's
#: operations in the same order, without fused multiply-adds, with the same libm).
TOLERANCE = 0.0


def build(scn: Any, estimator: str, engine: str | None = None) -> Any:
    """The scenario's controller for ``estimator``: the oracle for ``engine="oracle"``, else
    the bench's (:func:`bench.scenarios._setup.build_controller`, the core)."""
    if engine == "oracle":
        return OracleController(controller_pars(scn, estimator))
    return build_controller(scn, estimator, engine)
