"""The controller's own view of the motor: estimated parameters, which may differ from the plant's."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class MotorModel:
    """Motor parameters as the controller believes them to be.

    Kept separate from the plant's parameters so that parameter-error
    studies need no code change: the bench builds this from a preset and may
    scale any field.

    Parameters
    ----------
    n_p : int
        Pole pairs.
    R_s : float
        Stator resistance (Ohm).
    L_d, L_q : float
        d- and q-axis inductances (H).
    psi_f : float
        Permanent-magnet flux linkage (Wb).
    J : float
        Total inertia (kg m^2).
    b : float
        Viscous friction coefficient (N m s/rad).
    i_max : float
        Current limit, peak phase current (A).
    tau_max : float
        Torque limit (N m).
    k_dq : float
        Cross-saturation coefficient (H/A): incremental cross inductance
        ``L_dq = k_dq i_q`` (:mod:`controller._compensation`); usually
        negative, 0 without cross-saturation.
    """

    n_p: int
    R_s: float
    L_d: float
    L_q: float
    psi_f: float
    J: float
    b: float
    i_max: float
    tau_max: float
    k_dq: float = 0.0
