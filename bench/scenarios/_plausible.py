"""Plausibility of a scenario's motor from physics: a unit mistake is an error naming it.

A motor's parameters are not independent numbers: they describe one
machine driven by one inverter.  Three relations any IPMSM on a voltage
source inverter obeys, each with a wide band (a factor of ten or more
beyond the machines of the papers and of industry, see the bounds below),
so that only a mistake leaves them:

1. **Electrical time constant** ``tau = L / R_s`` of each axis.  Permanent-
   magnet machines from a few hundred watts to a few hundred kilowatts have
   ``tau`` between about 1 ms and 100 ms (Wen's motor 20 / 29 ms, Xue's
   19 / 39 ms); the band is ``[TAU_MIN_S, TAU_MAX_S]`` = 0.05 ms to 2 s.
2. **Back-EMF at rated speed against the DC link.**  The no-load phase
   voltage at rated speed is ``E = n_p w_m_rated psi_f`` (peak, as ``psi_f``
   is a peak flux linkage).  The inverter reaches at most ``u_dc / sqrt(3)``
   (peak phase, space-vector modulation); a drive runs above that only by
   field weakening, which rarely goes beyond three times base speed, so
   ``E <= EMF_MAX_RATIO u_dc / sqrt(3)``.  A magnet machine uses a sizeable
   part of its inverter's voltage (Wen 0.60, Xue 0.64): ``E`` below
   ``EMF_MIN_RATIO`` of it (1 %) is not such a machine (``psi_f = 0``, a
   reluctance machine, is exempt).
3. **Current for rated torque.**  The least peak current that makes
   ``tau_rated`` (maximum torque per ampere of ``tau = 1.5 n_p (psi_f i_q +
   (L_d - L_q) i_d i_q)``, searched over the current angle) must be within
   reach of the current limit (at most ``CURRENT_MAX_RATIO`` times
   ``i_max``: saturation lowers the torque, it does not multiply it) and
   not a small fraction of the rated current (at least ``i_rated /
   CURRENT_MIN_FRACTION``): Wen 4.2 A for 4 A rated, Xue 9.9 A for 10 A.
4. **Resistive drop at rated current** ``R_s i_rated``: the inverter must
   drive rated current through the winding at standstill, and the copper
   loss of a real machine keeps the drop at a few per cent of its voltage
   (Wen 3.6 %, Xue 0.6 % of ``u_dc / sqrt(3)``); above ``RS_DROP_MAX`` of
   it (half) the machine could not be driven at rated current.
5. **Mechanical time constant** ``tau_m = J w_m_rated / tau_rated``: the
   time rated torque takes to bring the inertia (rotor and load) from
   standstill to rated speed, friction and load aside.  A PM machine's own
   rotor gives from about 1 ms (low-inertia servo motors: 0.3e-4 kg m^2,
   314 rad/s, 1.3 N m: 7 ms; the fastest a few ms) to about 0.2 s (the
   high-inertia variants of the same frames); a drive's load adds its own
   inertia, up to the tens of times the rotor's that drive catalogues list
   as the matched range for fans, pumps and conveyors.  The papers' motors
   with their loads: Wen 0.063 s, Xue 0.053 s.  The band is
   ``[TAU_M_MIN_S, TAU_M_MAX_S]`` = 0.5 ms (below the fastest servo rotor
   by a factor of two) to 20 s (a load a hundred times the inertia of the
   highest-inertia rotor).  Inertia is often given in kg cm^2 (catalogues
   of servo motors) or g cm^2: ``J = 40`` meant as 40 kg cm^2 is 0.004
   kg m^2 and gives Wen's motor 840 s, a motor the controller's speed loop
   (its gains are designed from ``J``) never turns.

When a check fails and one value the scenario's ``[motor]`` (or
``[inverter]``) table sets brings every check back in band when read in
another unit (mH for H, mOhm for Ohm, mWb for Wb, rpm for rad/s, mA for A,
kg cm^2 or g cm^2 for kg m^2, or 1000 times the other way), the error names that field and that unit:
``L_d = 36 looks like mH; the schema wants H (0.036)``.  Values of the
preset are not suspected: they are the papers'.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: Electrical time constant band, s.
TAU_MIN_S = 5e-5
TAU_MAX_S = 2.0
#: Back-EMF at rated speed against the inverter's peak phase voltage u_dc / sqrt(3).
EMF_MAX_RATIO = 3.0
EMF_MIN_RATIO = 0.01
#: Resistive drop R_s i_rated at most this fraction of u_dc / sqrt(3).
RS_DROP_MAX = 0.5
#: Mechanical time constant band J w_m_rated / tau_rated, s (module docstring, check 5).
TAU_M_MIN_S = 5e-4
TAU_M_MAX_S = 20.0
#: Current for rated torque: at most this many times i_max ...
CURRENT_MAX_RATIO = 3.0
#: ... and at least i_rated over this.
CURRENT_MIN_FRACTION = 30.0

#: The unit each ``[motor]`` key is in, and the units a value may have been typed in
#: (factor to the schema's unit, name).
UNITS: dict[str, str] = {
    "R_s": "Ohm",
    "L_d": "H",
    "L_q": "H",
    "psi_f": "Wb",
    "i_rated": "A",
    "i_max": "A",
    "tau_rated": "N m",
    "w_m_rated": "rad/s (mechanical)",
    "u_dc": "V",
    "J": "kg m^2",
}
_PREFIXED = {"Ohm": "mOhm", "H": "mH", "Wb": "mWb", "A": "mA", "N m": "mN m", "V": "mV"}


def _alternatives(key: str) -> list[tuple[float, str]]:
    """(factor to the schema's unit, what the value then looks like) for one key."""
    unit = UNITS[key]
    if key == "w_m_rated":
        return [(math.pi / 30.0, "rpm")]
    if key == "J":  # catalogues give inertia in kg cm^2 (servo motors) or g cm^2
        return [(1e-4, "kg cm^2"), (1e-7, "g cm^2")]
    # typed in the milli unit, or in the schema's unit but scaled twice (mH -> H once too often)
    return [(1e-3, _PREFIXED[unit]), (1e3, f"a value in {unit} divided by 1000 once too often")]


@dataclass(frozen=True, slots=True)
class _Motor:
    n_p: float
    R_s: float
    L_d: float
    L_q: float
    psi_f: float
    i_rated: float
    i_max: float
    tau_rated: float
    w_m_rated: float
    u_dc: float
    J: float


def current_for_torque(m: _Motor, tau: float) -> float:
    """Least peak current that makes torque ``tau`` (N m), A (maximum torque per ampere).

    Torque at current amplitude ``i`` and angle ``beta`` (``i_d = -i sin beta``,
    ``i_q = i cos beta``) is ``1.5 n_p i cos beta (psi_f + (L_q - L_d) i sin beta)``;
    its maximum over ``beta`` grows with ``i``, so the least ``i`` is found by
    bisection on that maximum (searched on a 1 deg grid of ``beta``).
    """

    def t_max(i: float) -> float:
        best = 0.0
        for k in range(91):
            b = math.radians(k)
            t = 1.5 * m.n_p * i * math.cos(b) * (m.psi_f + (m.L_q - m.L_d) * i * math.sin(b))
            best = max(best, t)
        return best

    hi = 1.0
    while t_max(hi) < tau:
        hi *= 2.0
        if hi > 1e12:
            return math.inf
    lo = 0.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if t_max(mid) >= tau:
            hi = mid
        else:
            lo = mid
    return hi


def _checks(m: _Motor) -> list[tuple[str, tuple[str, ...], str]]:
    """The failed checks: (name, the keys it involves, what is wrong)."""
    bad: list[tuple[str, tuple[str, ...], str]] = []
    for ax in ("L_d", "L_q"):
        tau = getattr(m, ax) / m.R_s
        if not TAU_MIN_S <= tau <= TAU_MAX_S:
            bad.append(
                (
                    f"tau_{ax[-1]}",
                    (ax, "R_s"),
                    f"the electrical time constant {ax}/R_s = {tau:.3g} s is outside "
                    f"{TAU_MIN_S * 1e3:g} ms to {TAU_MAX_S:g} s, the band of any PM machine",
                )
            )
    u_lin = m.u_dc / math.sqrt(3.0)
    emf = m.n_p * m.w_m_rated * m.psi_f
    if emf > EMF_MAX_RATIO * u_lin or (m.psi_f > 0.0 and emf < EMF_MIN_RATIO * u_lin):
        bad.append(
            (
                "emf",
                ("psi_f", "w_m_rated", "u_dc"),
                f"the back-EMF at rated speed n_p w_m_rated psi_f = {emf:.4g} V (peak) is "
                f"{emf / u_lin:.3g} times the inverter's u_dc/sqrt(3) = {u_lin:.4g} V "
                f"(plausible: {EMF_MIN_RATIO:g} to {EMF_MAX_RATIO:g})",
            )
        )
    drop = m.R_s * m.i_rated
    if drop > RS_DROP_MAX * u_lin:
        bad.append(
            (
                "drop",
                ("R_s", "i_rated", "u_dc"),
                f"the resistive drop at rated current R_s i_rated = {drop:.4g} V is "
                f"{drop / u_lin:.3g} times the inverter's u_dc/sqrt(3) = {u_lin:.4g} V "
                f"(plausible: at most {RS_DROP_MAX:g})",
            )
        )
    tau_m = m.J * m.w_m_rated / m.tau_rated
    if not TAU_M_MIN_S <= tau_m <= TAU_M_MAX_S:
        bad.append(
            (
                "tau_m",
                ("J", "w_m_rated", "tau_rated"),
                f"the mechanical time constant J w_m_rated / tau_rated = {tau_m:.3g} s (rated "
                f"torque from standstill to rated speed) is outside {TAU_M_MIN_S * 1e3:g} ms "
                f"to {TAU_M_MAX_S:g} s, the band of a PM machine with its load",
            )
        )
    i_need = current_for_torque(m, m.tau_rated)
    if i_need > CURRENT_MAX_RATIO * m.i_max or i_need < m.i_rated / CURRENT_MIN_FRACTION:
        bad.append(
            (
                "current",
                ("tau_rated", "psi_f", "i_rated", "i_max", "L_d", "L_q"),
                f"rated torque {m.tau_rated:.4g} N m needs {i_need:.4g} A (peak, maximum "
                f"torque per ampere), against i_rated {m.i_rated:.4g} A and i_max "
                f"{m.i_max:.4g} A (plausible: i_rated/{CURRENT_MIN_FRACTION:g} to "
                f"{CURRENT_MAX_RATIO:g} i_max)",
            )
        )
    return bad


def motor_plausibility_error(
    values: dict[str, float], given: dict[str, str]
) -> tuple[str, str] | None:
    """The first implausibility of a motor as (field, reason), or None when plausible.

    ``values``: every parameter of :class:`_Motor` (the preset's, with the
    scenario's overrides).  ``given``: the keys the scenario set, with the
    field name to report (``motor.L_d``, ``inverter.u_dc``); only those are
    suspected of a unit mistake.
    """
    m = _Motor(**{k: float(v) for k, v in values.items()})
    bad = _checks(m)
    if not bad:
        return None
    name, keys, why = bad[0]
    before = {b[0] for b in bad}

    def failing_after(k: str, factor: float) -> set[str]:
        fixed = _Motor(**{**{x: getattr(m, x) for x in values}, k: getattr(m, k) * factor})
        return {b[0] for b in _checks(fixed)}

    suspects = [k for k in (*keys, *given) if k in given and k in UNITS]
    # a value whose other unit clears every check; else one that clears this check
    # and breaks no other (two values typed in the wrong unit, L_d and L_q in mH)
    for whole in (True, False):
        for k in dict.fromkeys(suspects):
            for factor, looks in _alternatives(k):
                after = failing_after(k, factor)
                if (not after) if whole else (name not in after and after <= before):
                    v = getattr(m, k)
                    return given[k], (
                        f"{k} = {v:g} looks like {looks}; the schema wants {UNITS[k]} "
                        f"({v * factor:.4g}): {why}"
                    )
    field = next((given[k] for k in keys if k in given), f"motor.{keys[0]}")
    involved = ", ".join(f"{k} ({UNITS[k]})" for k in keys if k in UNITS)
    return field, f"{why}; check {involved}"
