"""Plant profiles: the ideal plant of the papers and a drive with its hardware effects.

A profile is everything about the plant that is not the motor: the inverter
model and DC link, the sensors, and which magnetic effects are on. The
motor's own values (including the cross-saturation coefficient) stay in its
preset (:mod:`plant_rt._presets`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

from plant_rt._inverter import InverterPars
from plant_rt._presets import Preset
from plant_rt._sensors import SensorPars

ProfileName = Literal["ideal", "drive"]
PROFILE_NAMES: tuple[str, ...] = ("ideal", "drive")
"""The plant profiles by name."""


class UnknownProfileError(KeyError):
    """Raised by :func:`plant_profile` for a name that is not in :data:`PROFILE_NAMES`."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else "unknown plant profile"


@dataclass(frozen=True, slots=True)
class PlantProfile:
    """The non-motor part of a plant.

    Build a plant with ``Plant(preset.motor, prof.inverter, T_s,
    sensors=prof.sensors, saturation=prof.saturation,
    cross_saturation=prof.cross_saturation)``.

    Parameters
    ----------
    name : str
        Profile name.
    inverter : InverterPars
        Inverter model, dead time, device drops and DC link.
    sensors : SensorPars
        Current and DC-link voltage sensing.
    saturation : bool
        d-axis saturation of the motor (:class:`SaturationPars`).
    cross_saturation : bool
        Cross-saturation of the motor (:class:`CrossSaturationPars`).
    doc : str
        The reasoning for every value.
    """

    name: str
    inverter: InverterPars
    sensors: SensorPars
    saturation: bool
    cross_saturation: bool
    doc: str


_IDEAL_DOC = """The papers' plant: the preset's inverter as an average model (its
u_dc, no dead time, no device drops, stiff DC link), exact sensors, d-axis
saturation on (the magnet-polarity test needs it), no cross-saturation."""

_DRIVE_DOC = """A drive as built, each value with its reason:
- Switching inverter (model = "switching", carrier peak on the sample
  instant): the current ripple, the dead-time distortion around each current
  zero and the switching harmonics exist only edge by edge.
- t_dead = 2 us: the usual order for 1.2 kV IGBTs in a 540 V link (turn-off
  delay plus tail current, a few hundred ns each, with margin for the gate
  drivers' spread); 2 % of the 10 kHz period (10.8 V of mean pole-voltage
  error), 0.2 % at 1 kHz.
- v_ce = v_f = 1.5 V: on-state voltage of a 1.2 kV IGBT and forward voltage
  of its freewheeling diode near their rated current, the order of the
  datasheets of this power class; equal drops make the drop error
  -sign(i_x) 1.5 V in every leg whatever the duty, the same shape as the
  dead-time error (0.14 of it at 10 kHz, 1.4 times it at 1 kHz).
- DC link stiff (r_dc = c_dc = 0): the papers' u_dc is a regulated supply;
  a user sets r_dc and c_dc to study the link.
- Current ADC: 12 bits (the converters of common motor-control MCUs), full
  scale +-2 i_max (+-16 A for wen2023, +-40 A for xue2022): the protection
  trips at 1.5 i_max and the ADC must still read the current there, with
  room for the ripple on top; one LSB is 4 i_max / 4096 (7.8 mA, 19.5 mA).
- Gain errors (+0, +0.5 %, -0.5 %) on phases a, b, c: a 0.5 % mismatch
  between the two currents the controller receives (a and b; c is
  reconstructed), the accuracy class of closed-loop Hall sensors.
- Offsets (+10, -10, +10) mA: 10 mA each, of alternating sign so that they
  do not cancel in alpha-beta (a stationary current vector of 11.5 mA from
  a and b, the order an uncalibrated sensor leaves after its zero drift).
- DC-link voltage read with the same 12-bit ADC over 0..1000 V (0.24 V LSB).
- No added noise and no sensor delay: the brief's drive has neither; a
  user sets current_noise_a and sample_delay_s.
- Saturation and the preset's cross-saturation on (CrossSaturationPars in
  the preset; about 5 electrical degrees of saliency-axis offset at rated
  current)."""


def ideal_profile(p: Preset) -> PlantProfile:
    """The papers' plant for preset ``p``; the reasoning is in the profile's ``doc``."""
    return PlantProfile(
        name="ideal",
        inverter=replace(p.inverter, model="average", t_dead=0.0, v_ce=0.0, v_f=0.0),
        sensors=SensorPars(),
        saturation=True,
        cross_saturation=False,
        doc=_IDEAL_DOC,
    )


def drive_profile(p: Preset, seed: int = 0) -> PlantProfile:
    """A real drive for preset ``p``: switching inverter, dead time, drops, ADC, cross-saturation.

    The reason for every value is in the profile's ``doc``.

    Parameters
    ----------
    p : Preset
        Motor preset; the ADC full scale follows its ``i_max``.
    seed : int
        Seed of the sensors' noise generator (no noise by default; kept
        for a user who adds some).
    """
    i_fs = 2.0 * p.motor.i_max
    return PlantProfile(
        name="drive",
        inverter=replace(
            p.inverter,
            model="switching",
            t_dead=2e-6,
            v_ce=1.5,
            v_f=1.5,
            r_dc=0.0,
            c_dc=0.0,
            sample_at="peak",
        ),
        sensors=SensorPars(
            bits=12,
            i_fs=i_fs,
            u_fs=1000.0,
            gain_abc=(1.0, 1.005, 0.995),
            offset_abc=(0.010, -0.010, 0.010),
            seed=seed,
        ),
        saturation=True,
        cross_saturation=True,
        doc=_DRIVE_DOC,
    )


def plant_profile(name: str, p: Preset, seed: int = 0) -> PlantProfile:
    """Look up a plant profile by name for preset ``p``.

    Raises
    ------
    UnknownProfileError
        If ``name`` is not in :data:`PROFILE_NAMES`; the message lists them.
    """
    if name == "ideal":
        return ideal_profile(p)
    if name == "drive":
        return drive_profile(p, seed)
    known = ", ".join(PROFILE_NAMES)
    raise UnknownProfileError(f"unknown plant profile {name!r}; known profiles: {known}")
