"""Motor presets from the two papers, with every missing value chosen and explained.

All values the papers do not give live here and nowhere else.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from plant_rt._inverter import InverterPars
from plant_rt._machine import CrossSaturationPars, MotorPars, SaturationPars


class UnknownPresetError(KeyError):
    """Raised by :func:`preset` for a name that is not in :data:`PRESETS`."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else "unknown preset"


@dataclass(frozen=True, slots=True)
class Preset:
    """A motor, its inverter and its switching frequency.

    Parameters
    ----------
    name : str
        Preset name.
    motor : MotorPars
        Machine and mechanical parameters.
    inverter : InverterPars
        DC link and dead time.
    f_sw : float
        Default PWM (switching and sampling) frequency (Hz).
    doc : str
        Source of every value and the reasoning for the chosen ones.
    """

    name: str
    motor: MotorPars
    inverter: InverterPars
    f_sw: float
    doc: str

    @property
    def T_s(self) -> float:
        """Default PWM period (s)."""
        return 1.0 / self.f_sw


_RPM = 2.0 * math.pi / 60.0

_WEN_DOC = """Wen et al., Table 4: 1.2 kW, 1500 rpm, 4 pole pairs, R_s = 2.8 Ohm,
L_d = 57 mH, L_q = 82 mH, rated torque 7.5 N m, J = 0.003 kg m^2.

Chosen (not in the paper):
- psi_f = 0.30 Wb. With MTPA (i_d = -1.10 A, i_q = 3.82 A) the rated 7.5 N m
  needs 3.97 A peak, so i_rated = 4.0 A peak (2.8 A rms). At 1500 rpm
  (w_e = 628 rad/s) the back-EMF is 188 V peak and the stator voltage at the
  rated point 256 V peak, input power 1.25 kW (1.2 kW rated output).
- u_dc = 540 V (rectified 400 V three-phase mains): the rated point needs
  256 V, below both the sine-triangle limit u_dc/2 = 270 V and the
  space-vector limit u_dc/sqrt(3) = 312 V.
- f_sw = 10 kHz (not given; a common value for a 1.2 kW drive and the rate
  the 500 Hz injection of Section 3 needs for 20 samples per HF period).
- i_max = 8 A peak (2x rated, the usual short-time overload).
- b = 4.8e-4 N m s/rad: viscous friction of 1 % of rated torque at rated speed.
- t_dead = 0: the paper's RT-LAB model gives no dead time; the plant
  supports one (InverterPars.t_dead) for robustness studies.
- Saturation (used only with saturation=True): sigma = 0.15, i_sat = 2 A, so
  the incremental d-axis inductance is 0.87 L_d at +i_rated and 1.13 L_d
  at -i_rated, a contrast typical of the magnet-polarity test.
- Cross-saturation (used only with cross_saturation=True, as in the drive
  profile): c_dq = 1.1e-4 H/A^2 (CrossSaturationPars). The paper gives no
  flux map. Cross-saturation of IPM motors shifts the saliency axis that
  HF injection tracks by delta = -1/2 atan2(2 L_dq, L_qq - L_dd) (Guglielmi,
  Pastorelli, Vagati, IEEE TIA 2006), growing with load; c_dq is set so that
  delta is about 5 electrical degrees at rated current: 5.1 deg at
  i_d = 0, i_q = 4 A, 4.5 deg at the rated MTPA point, 0.66 deg at 1/8
  load. A moderate machine: the offset is larger than Wen Table 7's mean
  error bound (2.5 deg), so a drive must compensate it, but not so large
  that a compensation-free estimator loses lock. Side effects at rated
  q current: psi_d falls by 1.5 % (the torque constant's cross-saturation
  loss) and L_dd by 1.5 %; the flux map stays positive definite up to
  3 i_max (checked to 2 i_max when a plant is built)."""

_XUE_DOC = """Xue et al., Table 1: 3 kW, 540 V DC, 1200 rpm, R_s = 0.19 Ohm,
L_d = 3.53 mH, L_q = 7.48 mH, 4 pole pairs. Switching frequency 1 kHz
(Section 4).

Chosen (not in the paper):
- tau_rated = 3 kW / 125.7 rad/s = 23.9 N m (from rated power and speed).
- psi_f = 0.40 Wb. With MTPA (i_d = -1.04 A, i_q = 9.85 A) the rated torque
  needs 9.90 A peak, so i_rated = 10 A peak (7.1 A rms). At 1200 rpm
  (w_e = 503 rad/s) the back-EMF is 201 V peak and the stator voltage at the
  rated point 205 V peak, below u_dc/2 = 270 V, input power 3.03 kW.
- J = 0.01 kg m^2: the same ratio of inertia to rated torque as the Wen
  motor (0.003 / 7.5 * 23.9 = 0.0096), i.e. the same acceleration at rated
  torque.
- b = 1.9e-3 N m s/rad: friction of 1 % of rated torque at rated speed.
- i_max = 20 A peak (2x rated).
- t_dead = 0: the paper's simulation gives no dead time.
- Saturation (used only with saturation=True): sigma = 0.15, i_sat = 5 A
  (half the rated current, as for the Wen motor).
- Cross-saturation (used only with cross_saturation=True): c_dq =
  3.1e-7 H/A^2, chosen by the same rule as for the Wen motor: a saliency-axis
  offset of about 5 electrical degrees at rated current (5.0 deg at
  i_d = 0, i_q = 10 A, and at the rated MTPA point). Xue's load steps
  (3 N m, 1/8 of rated torque, i_q = 1.25 A) see 0.64 deg, well inside the
  0.26 rad bound of Figs. 15, 16 and 18. The coefficient is small in H/A^2
  because the magnet's equivalent current psi_f / L_d = 113 A is large; at
  rated q current psi_d falls by 0.44 % and L_dd by 0.44 %; positive
  definite up to 4 i_max."""

_WEN = Preset(
    name="wen2023",
    motor=MotorPars(
        n_p=4,
        R_s=2.8,
        L_d=57e-3,
        L_q=82e-3,
        psi_f=0.30,
        J=0.003,
        b=4.8e-4,
        i_rated=4.0,
        i_max=8.0,
        tau_rated=7.5,
        w_m_rated=1500.0 * _RPM,
        sat=SaturationPars(sigma=0.15, i_sat=2.0),
        cross=CrossSaturationPars(c_dq=1.1e-4),
    ),
    inverter=InverterPars(u_dc=540.0, t_dead=0.0),
    f_sw=10e3,
    doc=_WEN_DOC,
)

_XUE = Preset(
    name="xue2022",
    motor=MotorPars(
        n_p=4,
        R_s=0.19,
        L_d=3.53e-3,
        L_q=7.48e-3,
        psi_f=0.40,
        J=0.01,
        b=1.9e-3,
        i_rated=10.0,
        i_max=20.0,
        tau_rated=3000.0 / (1200.0 * _RPM),
        w_m_rated=1200.0 * _RPM,
        sat=SaturationPars(sigma=0.15, i_sat=5.0),
        cross=CrossSaturationPars(c_dq=3.1e-7),
    ),
    inverter=InverterPars(u_dc=540.0, t_dead=0.0),
    f_sw=1e3,
    doc=_XUE_DOC,
)

PRESETS: dict[str, Preset] = {p.name: p for p in (_WEN, _XUE)}
"""The shipped presets by name."""


def preset(name: str) -> Preset:
    """Look up a preset by name.

    Raises
    ------
    UnknownPresetError
        If ``name`` is not a preset; the message lists the known names.
    """
    try:
        return PRESETS[name]
    except KeyError:
        known = ", ".join(sorted(PRESETS))
        raise UnknownPresetError(f"unknown preset {name!r}; known presets: {known}") from None
