"""Our drive's rotor-position estimator, as a plug-in of the bench (docs/ESTIMATORS.md).

The factory below is what the bench calls: ``create(motor, T_s, **options)``
returns an object with the members of ``controller.Estimator`` (``update``,
``theta_hat``, ``w_hat``, ``injection``, ...).  This one starts from Wen's
tt-dq demodulator as the bench ships it: its HF injection, filters and PLL,
and its options declared as this estimator's own (a scenario's
``[estimator_options]`` are checked against them).  Replace the body of
``create`` with your estimator and keep the tests.

Name it ``my_drive.estimator:create`` (with this project importable), or,
after ``pip install -e .``, by the name this project's pyproject.toml
registers in the entry-point group ``can_hil_bench.estimators``:
``bench run wen-5.1 --estimator my-drive``.
"""

from __future__ import annotations

from typing import Any

from controller import declared_options, make_estimator


def create(motor: Any, T_s: float, **options: Any) -> Any:
    """The estimator for the controller's motor model ``motor`` at the period ``T_s`` (s)."""
    return make_estimator("tt-dq", motor, T_s, **options)


#: The controller runs the HF start-up (alignment, magnet polarity) before the speed loop.
create.injection_family = "rotating"  # type: ignore[attr-defined]
#: The scenario's [estimator_options] this estimator takes, with units and checks.
create.options = declared_options("tt-dq")  # type: ignore[attr-defined]
