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

With cross-saturation (:class:`CrossSaturationPars`) both flux linkages
depend on both currents, ``psi_d(i_d, i_q)`` and ``psi_q(i_d, i_q)``
(:func:`flux_dq`), derived from one magnetic co-energy so that the model
conserves energy and its incremental inductance matrix is symmetric.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from plant_rt._engine import _cplant


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
class CrossSaturationPars:
    """Cross-saturation: the d- and q-axis magnetic paths share saturable iron.

    Model. Both flux linkages derive from one magnetic co-energy
    ``W'(i_d, i_q)`` (``psi_d = dW'/di_d``, ``psi_q = dW'/di_q``), so the
    incremental inductance matrix is the Hessian of ``W'``: symmetric
    (``L_dq = d psi_d / d i_q = d psi_q / d i_d``, reciprocity), and the
    machine conserves energy with the torque ``1.5 n_p (psi_d i_q -
    psi_q i_d)`` (:func:`magnetic_energy`). The cross term added to the
    co-energy of the d-axis model (:class:`SaturationPars`) and of
    ``L_q i_q^2 / 2`` is::

        W'_x = -(c_dq / 4) (m_d^2 - i_0^2) i_q^2,   m_d = i_d + i_0,
        i_0 = psi_f / L_d

    ``m_d`` is the d-axis magnetising current, the stator current plus the
    magnet's equivalent current ``i_0`` (``L_d m_d`` is the d-axis flux of
    the linear machine). It is the cross-saturation term of the algebraic
    saturation model of motulator's ``SaturationModelSyRM`` (Hinkkanen et
    al., "Sensorless self-commissioning of synchronous reluctance motors at
    standstill without rotor locking", IEEE Trans. Ind. Appl., 2017;
    ``motulator/drive/utils/_sm_flux_maps.py``), ``a_dq / ((U + 2) (V +
    2)) |psi_d|^(U+2) |psi_q|^(V+2)`` with its lowest exponents
    ``U = V = 0``, moved from the energy in the flux linkages (motulator's
    current map) to the co-energy in the currents (a flux map, which is what
    this plant's current states need), and referred to the magnet-biased
    d-axis: by symmetry of the iron in the d-axis flux, the cross-coupling
    vanishes where that flux does (``m_d = 0``). The ``- i_0^2`` keeps the
    zero-current inductances at ``L_d`` and ``L_q``. Energy-based models
    with such a cross term: Jebai, Malrait, Martin, Rouchon, "Sensorless
    position estimation and control of permanent-magnet synchronous motors
    using a saturation model", Int. J. Control, 2016. The flux map::

        psi_d = psi_d(i_d) - (c_dq / 2) m_d i_q^2
        psi_q = L_q i_q    - (c_dq / 2) (m_d^2 - i_0^2) i_q
        L_dd  = L_dd(i_d)  - (c_dq / 2) i_q^2
        L_dq  = -c_dq m_d i_q
        L_qq  = L_q        - (c_dq / 2) (m_d^2 - i_0^2)

    Load current (``i_q``) lowers the d-axis flux (the torque constant
    falls) and tilts the incremental-inductance ellipse: an HF-injection
    estimator locks on its minimum-inductance axis, which lies at
    ``delta = -1/2 atan2(2 L_dq, L_qq - L_dd)`` from the d axis
    (Guglielmi, Pastorelli, Vagati, "Cross-saturation effects in IPM motors
    and related impact on sensorless control", IEEE Trans. Ind. Appl.,
    2006), positive (estimate leading) for motoring ``i_q > 0``.

    Parameters
    ----------
    c_dq : float
        Cross-saturation coefficient (H/A^2), >= 0; 0 disables the effect.
        :func:`cross_saturation_check` tells whether the model stays
        positive definite over the operating range.
    """

    c_dq: float = 0.0

    def __post_init__(self) -> None:
        if not (self.c_dq >= 0.0 and math.isfinite(self.c_dq)):
            raise ValueError(f"CrossSaturationPars.c_dq must be finite and >= 0, got {self.c_dq}")


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
    cross : CrossSaturationPars
        Cross-saturation, used only when the plant is built with
        ``cross_saturation=True``.
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
    cross: CrossSaturationPars = field(default_factory=CrossSaturationPars)

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
    out = _machine(motor, i_d, 0.0, saturation, False)
    return out[0], out[2]


def _machine(
    motor: MotorPars, i_d: float, i_q: float, saturation: bool, cross: bool
) -> tuple[float, float, float, float, float, float]:
    """The core's flux map and torque (``plant_rt/core/plant_machine.c``, its one home)."""
    return _cplant.machine(
        float(motor.n_p),
        float(motor.L_d),
        float(motor.L_q),
        float(motor.psi_f),
        float(motor.i_max),
        float(motor.sat.sigma),
        float(motor.sat.i_sat),
        float(motor.cross.c_dq),
        saturation,
        cross,
        float(i_d),
        float(i_q),
    )


def magnetic_energy(
    motor: MotorPars, i_d: float, i_q: float, saturation: bool, cross: bool = False
) -> float:
    """Magnetic field energy stored by the stator currents (J).

    ``W = 1.5 (int_0^{i_d} i L_dd(i) di + L_q i_q^2 / 2)``; the factor 1.5
    belongs to the amplitude-invariant d-q transformation. With saturation::

        int_0^{i_d} i L_dd(i) di
            = L_d i_d^2 / 2 - L_d sigma i_sat^2 (x sqrt(1 + x^2) - asinh x) / 2

    With cross-saturation the energy is ``W = i_d psi_d + i_q psi_q - W'``
    (Legendre transform of the co-energy of :class:`CrossSaturationPars`),
    which adds ``-c_dq i_q^2 (3/4 i_d^2 + i_0 i_d)`` inside the bracket (the
    integral of ``i . d psi`` along any path from zero current).

    Parameters
    ----------
    motor : MotorPars
        Machine parameters.
    i_d, i_q : float
        d- and q-axis currents (A).
    saturation : bool
        Whether the saturated flux model is used.
    cross : bool, optional
        Whether the cross-saturation model is used.

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
    if cross:
        i_0 = motor.psi_f / motor.L_d
        w_d -= motor.cross.c_dq * i_q * i_q * (0.75 * i_d * i_d + i_0 * i_d)
    return 1.5 * (w_d + 0.5 * motor.L_q * i_q * i_q)


def torque(
    motor: MotorPars, i_d: float, i_q: float, saturation: bool, cross: bool = False
) -> float:
    """Electromagnetic torque ``1.5 n_p (psi_d i_q - psi_q i_d)`` (N m).

    Linear case: ``1.5 n_p (psi_f i_q + (L_d - L_q) i_d i_q)``.
    """
    return _machine(motor, i_d, i_q, saturation, cross)[5]


def flux_dq(
    motor: MotorPars, i_d: float, i_q: float, saturation: bool, cross: bool
) -> tuple[float, float, float, float, float]:
    """Flux linkages and incremental inductances in the rotor frame.

    The d-axis model of :func:`flux_d` plus, with ``cross``, the
    cross-saturation of :class:`CrossSaturationPars`.

    Parameters
    ----------
    motor : MotorPars
        Machine parameters.
    i_d, i_q : float
        d- and q-axis currents (A).
    saturation : bool
        Use the saturated d-axis model.
    cross : bool
        Use the cross-saturation model.

    Returns
    -------
    psi_d, psi_q : float
        Flux linkages (Wb).
    L_dd, L_dq, L_qq : float
        Incremental inductances ``d psi_d / d i_d``, ``d psi_d / d i_q =
        d psi_q / d i_d`` and ``d psi_q / d i_q`` (H).
    """
    return _machine(motor, i_d, i_q, saturation, cross)[:5]


FLUX_RANGE: float = _cplant.FLUX_RANGE
"""The flux map's checked range in units of ``i_max``: ``|i_s| <= FLUX_RANGE i_max``
(``PLANT_FLUX_RANGE``, ``plant_rt/core/plant_machine.h``). The cross-saturated map is
checked positive definite there; beyond it the core continues the map (its cross
co-energy stops growing, ``plant_flux_cross_ext``) and a plant counts the periods spent
outside (:attr:`plant_rt.Plant.out_of_range_periods`)."""

FLUX_FADE: float = _cplant.FLUX_FADE
"""The width of the continuation's fade beyond the range, as a fraction of the range
(``PLANT_FLUX_FADE``; derived beside ``plant_flux_cross_ext``)."""

CHECK_REACH = 50.0
"""How far (in units of ``i_max``) :func:`cross_saturation_check` checks the continued
map: 50 i_max is past any current a drive's supply can push (a runaway of the xue2022
drive peaks near 2000 A, 100 i_max, only where the plant's integration has already
failed), and far beyond the fade of the continuation (2.5 i_max), where the matrix is
the d-axis model's diag(L_dd, L_q), positive by construction."""


def cross_saturation_check(motor: MotorPars, saturation: bool, i_max: float) -> None:
    """Raise ValueError unless the flux map is positive definite for ``|i_s| <= i_max``.

    The incremental inductance matrix must stay positive definite (a
    physical magnetic circuit stores energy for every current change); the
    quadratic cross term of :class:`CrossSaturationPars` does so only up to
    some current, checked here on a polar grid (24 radii by 72 angles). The
    map the core continues beyond that range (``plant_flux_cross_ext``) is
    checked too, on 48 radii spaced evenly in log from ``i_max`` to
    :data:`CHECK_REACH` ``motor.i_max``: a plant whose continued map is singular
    somewhere would turn NaN when a runaway reaches it.

    Parameters
    ----------
    motor : MotorPars
        Machine parameters.
    saturation : bool
        Whether the saturated d-axis model is used.
    i_max : float
        Radius of the current disc to check (A).
    """
    radii = [i_max * n / 24.0 for n in range(1, 25)]
    reach = CHECK_REACH * motor.i_max
    if reach > i_max:
        radii += [i_max * (reach / i_max) ** (n / 48.0) for n in range(1, 49)]
    for r in radii:
        for j in range(72):
            a = 2.0 * math.pi * j / 72.0
            i_d = r * math.cos(a)
            i_q = r * math.sin(a)
            _, _, L_dd, L_dq, L_qq = flux_dq(motor, i_d, i_q, saturation, True)
            if not (L_dd > 0.0 and L_dd * L_qq - L_dq * L_dq > 0.0):
                where = f"inside |i_s| <= {i_max:g} A" if r <= i_max else "its continuation"
                raise ValueError(
                    f"CrossSaturationPars.c_dq = {motor.cross.c_dq:g} H/A^2 makes the "
                    f"incremental inductance matrix singular at i_d = {i_d:.3g} A, "
                    f"i_q = {i_q:.3g} A ({where}): lower c_dq"
                )
