"""A minimal estimator plug-in to copy: a flux observer with a PLL, no injection.

Run it with ``bench run docs/examples/flux-known-angle.toml --estimator
my_estimator:create`` from ``docs/examples`` (or with this folder on
``PYTHONPATH``); docs/ESTIMATORS.md explains every member.

The observer integrates the stator voltage equation in the stationary frame,
``d psi_s / dt = u_s - R_s i_s``, pulled towards the flux of the motor
model at the estimated angle, ``psi_m = e^{j theta} (L_d i_d + psi_f + j L_q i_q)``,
with the corner ``w_c``: a voltage model above ``w_c``, the current model
below it.  The active flux ``psi_s - L_q i_s`` points along the rotor's d
axis; a PLL (double pole at ``alpha_o``) tracks its angle and gives the speed.
Without injection it cannot find the angle at standstill: it needs a known
initial angle (``known_initial_angle = true``) and some speed to correct a
wrong model.

Gains from targets: the PLL leaves an angle error ``a / alpha_o^2`` at an
electrical acceleration ``a``; ``alpha_o = 2 pi 20`` rad/s keeps it within
1 deg up to 276 rad/s^2, three times the ramp of flux-known-angle.toml
(100 rpm in 0.5 s, 4 pole pairs: 84 rad/s^2).  Its speed estimate lags the
rotor (:meth:`FluxPLL.speed_response`), and the controller designs its
speed loop with that lag to its phase-margin target.  ``w_c`` = 20 rad/s
puts the hand-over from the current model to the voltage model below the
scenario's 42 rad/s electrical (100 rpm).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from controller import option_field

#: The controller runs no HF start-up for this estimator (no injection).
INJECTION_FAMILY = "none"


class FluxPLL:
    """Flux observer + PLL; the members are those of ``controller.Estimator``."""

    def __init__(self, motor: Any, T_s: float, alpha_o: float, w_c: float) -> None:
        self.T_s = T_s
        self.R_s, self.L_d, self.L_q, self.psi_f = motor.R_s, motor.L_d, motor.L_q, motor.psi_f
        # PLL: a double pole at alpha_o (k_p = 2 alpha_o, k_i = alpha_o^2)
        self.k_p = 2.0 * alpha_o
        self.k_i = alpha_o * alpha_o
        self.alpha_o = alpha_o
        self.w_c = w_c
        self.theta_hat = 0.0
        self.w_hat = 0.0
        self.err = 0.0
        self.i_alpha_f = 0.0
        self.i_beta_f = 0.0
        self.reset(0.0)

    def update(self, x: Any) -> None:
        """Sample ``k``: the currents and the voltage that drove them (``controller.EstimatorInput``)."""
        T, th = self.T_s, self.theta_hat
        c, s = math.cos(th), math.sin(th)
        i_d = c * x.i_alpha + s * x.i_beta
        i_q = -s * x.i_alpha + c * x.i_beta
        psi_d = self.L_d * i_d + self.psi_f
        psi_q = self.L_q * i_q
        m_a, m_b = c * psi_d - s * psi_q, s * psi_d + c * psi_q
        self.psi_a += T * (x.u_alpha - self.R_s * x.i_alpha + self.w_c * (m_a - self.psi_a))
        self.psi_b += T * (x.u_beta - self.R_s * x.i_beta + self.w_c * (m_b - self.psi_b))
        fa, fb = self.psi_a - self.L_q * x.i_alpha, self.psi_b - self.L_q * x.i_beta
        # angle error of the active flux in the estimated frame (rad for small errors)
        self.err = math.atan2(-s * fa + c * fb, c * fa + s * fb)
        self.w_hat += T * self.k_i * self.err
        self.theta_hat = (th + T * (self.w_hat + self.k_p * self.err)) % (2.0 * math.pi)
        self.i_alpha_f, self.i_beta_f = x.i_alpha, x.i_beta  # no HF to remove

    def injection(self) -> tuple[float, float]:
        """No injection."""
        return 0.0, 0.0

    def reset(self, theta0: float) -> None:
        """Start at ``theta0`` at standstill: the magnet's flux along ``theta0``."""
        self.theta_hat = theta0 % (2.0 * math.pi)
        self.w_hat = 0.0
        self.psi_a = self.psi_f * math.cos(theta0)
        self.psi_b = self.psi_f * math.sin(theta0)

    def speed_response(self, w: Any) -> Any:
        """``w_hat / w_e`` at the angular frequencies ``w`` (rad/s, an array): the speed
        estimate is the PLL's integral state, ``k_i / (s^2 + k_p s + k_i)``, a double pole
        at ``alpha_o``.  The controller designs its speed loop with it (docs/ESTIMATORS.md):
        without it the loop is designed for an exact speed, and this lag takes its phase
        margin (a growing oscillation at the speed loop's crossover)."""
        s = 1j * w
        return self.k_i / (s * s + self.k_p * s + self.k_i)

    def gains(self) -> dict[str, float]:
        """Recorded in ``meta.json``."""
        return {"alpha_o": self.alpha_o, "k_p": self.k_p, "k_i": self.k_i, "w_c": self.w_c}


@dataclass(frozen=True)
class Options:
    """The options, checked on load in a scenario that names this plug-in (docs/ESTIMATORS.md).

    Parameters
    ----------
    alpha_o : float
        PLL bandwidth, double pole (rad/s).
    w_c : float
        Corner between the current and the voltage model (rad/s).
    """

    alpha_o: float = option_field(2 * math.pi * 20, positive=True)
    w_c: float = option_field(20.0, minimum=0.0)


def create(motor: Any, T_s: float, **options: Any) -> FluxPLL:
    """The factory: ``bench run ... --estimator my_estimator:create``.

    It receives the options it declares (``create.options``) that the
    scenario's ``[estimator_options]`` sets; the others (``V_h``, ...) are left
    out with a note.
    """
    o = Options(**options)
    return FluxPLL(motor, T_s, o.alpha_o, o.w_c)


create.injection_family = INJECTION_FAMILY  # type: ignore[attr-defined]
create.options = Options  # type: ignore[attr-defined]
