"""IPMSM parameters and the d-axis flux-linkage model.

The machine is modelled in the rotor d-q frame (amplitude-invariant
transformation, d axis on the magnet's north), as in Wen et al. eq. (1) and
Xue et al. eq. (1)::

    d psi_d / dt = u_d - R_s i_d + w_e psi_q
    d psi_q / dt = u_q - R_s i_q - w_e psi_d
    tau_e = 1.5 n_p (psi_d i_q - psi_q i_d)

with ``psi_q = L_q i_q`` and ``psi_d = psi_d(i_d)`` given by
:func:`flux_d`. With saturation off, ``psi_d = psi_f + L_d i_d`` and the
torque reduces to ``1.5 n_p (psi_f i_q + (L_d - L_q) i_d i_q)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field


@dataclass(frozen=True, slots=True)
class SaturationPars:
    """d-axis saturation of the magnetic circuit.

    The magnet biases the d-axis iron near the knee of its magnetisation
    curve: current that aids the magnet (``i_d > 0``) saturates the iron and
    lowers the incremental inductance, current that opposes it
    (``i_d < 0``) moves the iron back to the linear region. The model is
    built from the flux linkage (see :func:`flux_d`)::

        x = i_d / i_sat
        L_dd(i_d) = d psi_d / d i_d = L_d (1 - sigma x / sqrt(1 + x^2))

    so the incremental inductance runs smoothly from ``L_d (1 + sigma)``
    (large negative ``i_d``) through ``L_d`` (``i_d = 0``) to
    ``L_d (1 - sigma)`` (large positive ``i_d``).

    Parameters
    ----------
    sigma : float
        Relative half-range of the incremental d-axis inductance (-), in
        [0, 1).
    i_sat : float
        Current scale of the knee (A), > 0.
    """

    sigma: float = 0.15
    i_sat: float = 2.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.sigma < 1.0:
            raise ValueError(f"SaturationPars.sigma must be in [0, 1), got {self.sigma}")
        if not self.i_sat > 0.0:
            raise ValueError(f"SaturationPars.i_sat must be > 0, got {self.i_sat}")


@dataclass(frozen=True, slots=True)
class MotorPars:
    """IPMSM and mechanical parameters (SI units).

    Parameters
    ----------
    n_p : int
        Pole pairs.
    R_s : float
        Stator resistance (Ohm).
    L_d, L_q : float
        d- and q-axis inductances at zero current (H).
    psi_f : float
        Permanent-magnet flux linkage, peak per phase (Wb).
    J : float
        Total inertia of rotor and load (kg m^2).
    b : float
        Viscous friction coefficient (N m s/rad).
    i_rated : float
        Rated current, peak phase current (A).
    i_max : float
        Current limit, peak phase current (A).
    tau_rated : float
        Rated torque (N m).
    w_m_rated : float
        Rated mechanical speed (rad/s).
    sat : SaturationPars
        d-axis saturation, used only when the plant is built with
        ``saturation=True``.
    """

    n_p: int
    R_s: float
    L_d: float
    L_q: float
    psi_f: float
    J: float
    b: float
    i_rated: float
    i_max: float
    tau_rated: float
    w_m_rated: float
    sat: SaturationPars = field(default_factory=SaturationPars)

    def __post_init__(self) -> None:
        for name in ("R_s", "L_d", "L_q", "J", "i_rated", "i_max", "tau_rated", "w_m_rated"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"MotorPars.{name} must be > 0, got {getattr(self, name)}")
        if self.n_p < 1:
            raise ValueError(f"MotorPars.n_p must be >= 1, got {self.n_p}")
        if self.psi_f < 0.0 or self.b < 0.0:
            raise ValueError("MotorPars.psi_f and MotorPars.b must be >= 0")


def flux_d(motor: MotorPars, i_d: float, saturation: bool) -> tuple[float, float]:
    """d-axis flux linkage and incremental inductance.

    Integral of :class:`SaturationPars`' incremental inductance::

        psi_d(i_d) = psi_f + L_d (i_d - sigma i_sat (sqrt(1 + x^2) - 1))

    The apparent inductance ``(psi_d - psi_f) / i_d`` and the incremental
    inductance ``L_dd`` come from the same function, so the model is
    energy-consistent (see :func:`magnetic_energy`).

    Parameters
    ----------
    motor : MotorPars
        Machine parameters.
    i_d : float
        d-axis current (A).
    saturation : bool
        False gives the linear model ``psi_f + L_d i_d``.

    Returns
    -------
    psi_d : float
        d-axis flux linkage (Wb).
    L_dd : float
        Incremental d-axis inductance (H).
    """
    if not saturation:
        return motor.psi_f + motor.L_d * i_d, motor.L_d
    sat = motor.sat
    x = i_d / sat.i_sat
    r = math.sqrt(1.0 + x * x)
    psi_d = motor.psi_f + motor.L_d * (i_d - sat.sigma * sat.i_sat * (r - 1.0))
    return psi_d, motor.L_d * (1.0 - sat.sigma * x / r)


def magnetic_energy(motor: MotorPars, i_d: float, i_q: float, saturation: bool) -> float:
    """Magnetic field energy stored by the stator currents (J).

    ``W = 1.5 (int_0^{i_d} i L_dd(i) di + L_q i_q^2 / 2)``; the factor 1.5
    belongs to the amplitude-invariant d-q transformation. With saturation::

        int_0^{i_d} i L_dd(i) di
            = L_d i_d^2 / 2 - L_d sigma i_sat^2 (x sqrt(1 + x^2) - asinh x) / 2

    Parameters
    ----------
    motor : MotorPars
        Machine parameters.
    i_d, i_q : float
        d- and q-axis currents (A).
    saturation : bool
        Whether the saturated flux model is used.

    Returns
    -------
    float
        Field energy (J), zero at zero current.
    """
    w_d = 0.5 * motor.L_d * i_d * i_d
    if saturation:
        sat = motor.sat
        x = i_d / sat.i_sat
        w_d -= (
            0.5
            * motor.L_d
            * sat.sigma
            * sat.i_sat**2
            * (x * math.sqrt(1.0 + x * x) - math.asinh(x))
        )
    return 1.5 * (w_d + 0.5 * motor.L_q * i_q * i_q)


def torque(motor: MotorPars, i_d: float, i_q: float, saturation: bool) -> float:
    """Electromagnetic torque ``1.5 n_p (psi_d i_q - L_q i_q i_d)`` (N m).

    Linear case: ``1.5 n_p (psi_f i_q + (L_d - L_q) i_d i_q)``.
    """
    psi_d, _ = flux_d(motor, i_d, saturation)
    return 1.5 * motor.n_p * (psi_d - motor.L_q * i_d) * i_q
