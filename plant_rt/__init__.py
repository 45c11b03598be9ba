"""Pure plant: IPMSM, inverter, mechanics, load and sensing, stepped per PWM period.

Never imports :mod:`controller`, never touches CAN.
"""

from plant_rt._clock import JitterStats, RealTimeClock
from plant_rt._inverter import InverterPars
from plant_rt._load import (
    ConstantLoad,
    LoadProfile,
    LoadSum,
    RampLoad,
    SpeedProportionalLoad,
    StepLoad,
)
from plant_rt._machine import MotorPars, SaturationPars, flux_d, magnetic_energy, torque
from plant_rt._plant import EnergyMeter, Plant, Sample, Truth
from plant_rt._presets import PRESETS, Preset, UnknownPresetError, preset
from plant_rt._protection import (
    FAULT_NAMES,
    FAULT_NONE,
    FAULT_OVER_CURRENT,
    FAULT_OVER_SPEED,
    FAULT_OVER_VOLTAGE,
    FAULT_WATCHDOG,
    Protection,
    ProtectionPars,
)
from plant_rt._sensors import SensorPars

__all__ = [
    "FAULT_NAMES",
    "FAULT_NONE",
    "FAULT_OVER_CURRENT",
    "FAULT_OVER_SPEED",
    "FAULT_OVER_VOLTAGE",
    "FAULT_WATCHDOG",
    "PRESETS",
    "ConstantLoad",
    "EnergyMeter",
    "InverterPars",
    "JitterStats",
    "LoadProfile",
    "LoadSum",
    "MotorPars",
    "Plant",
    "Preset",
    "Protection",
    "ProtectionPars",
    "RampLoad",
    "RealTimeClock",
    "Sample",
    "SaturationPars",
    "SensorPars",
    "SpeedProportionalLoad",
    "StepLoad",
    "Truth",
    "UnknownPresetError",
    "flux_d",
    "magnetic_energy",
    "preset",
    "torque",
]
