"""Sensored baseline: the same FOC with the true rotor angle and speed."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from controller._params import MotorModel


@dataclass(frozen=True, slots=True)
class SensoredOptions:
    """The sensored baseline takes no options: its angle and speed are the plant's."""


class SensoredEstimator:
    """Passes the true angle and speed (``EstimatorInput.theta_e``/``w_e``) through.

    No injection; the current loop gets the measured current unchanged.
    Raises ``ValueError`` if the truth is missing.
    """

    #: No injection (``controller._registry.estimator_family``).
    injection_family: ClassVar[str] = "none"

    def __init__(self, T_s: float) -> None:
        self.T_s = T_s
        self.theta_hat = 0.0
        self.w_hat = 0.0
        self.err = 0.0
        self.i_alpha_f = 0.0
        self.i_beta_f = 0.0

    def gains(self) -> dict[str, float]:
        """No gains: the angle and speed come from the sensor."""
        return {}

    def reset(self, theta0: float) -> None:
        """Nothing to restart: the angle comes from the sensor."""
        self.theta_hat = theta0


def create(motor: MotorModel, T_s: float, **options: Any) -> SensoredEstimator:
    """Build the ``sensored`` estimator (takes no options)."""
    if options:
        raise TypeError(f"sensored estimator takes no options, got {sorted(options)}")
    return SensoredEstimator(T_s)
