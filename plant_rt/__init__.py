"""Pure plant: IPMSM, inverter, mechanics, load and sensing, stepped per PWM period.

Never imports :mod:`controller`, never touches CAN.
"""

from plant_rt._engine import ENGINES, compiled_engine_missing, resolve_engine
from plant_rt._inverter import InverterPars, device_drop_error
from plant_rt._load import (
    ConstantLoad,
    LoadProfile,
    LoadSum,
    RampLoad,
    SpeedProportionalLoad,
    StepLoad,
)
from plant_rt._machine import (
    FLUX_RANGE,
    CrossSaturationPars,
    MotorPars,
    SaturationPars,
    cross_saturation_check,
    flux_d,
    flux_dq,
    magnetic_energy,
    torque,
)
from plant_rt._plant import EnergyMeter, Plant, Sample, Truth
from plant_rt._presets import PRESETS, Preset, UnknownPresetError, preset
from plant_rt._profiles import (
    PROFILE_NAMES,
    PlantProfile,
    UnknownProfileError,
    drive_profile,
    ideal_profile,
    plant_profile,
)
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
from plant_rt._sensors import SensorPars, encoder_angle

__all__ = [
    "ENGINES",
    "FAULT_NAMES",
    "FAULT_NONE",
    "FAULT_OVER_CURRENT",
    "FAULT_OVER_SPEED",
    "FAULT_OVER_VOLTAGE",
    "FAULT_WATCHDOG",
    "FLUX_RANGE",
    "PRESETS",
    "PROFILE_NAMES",
    "ConstantLoad",
    "CrossSaturationPars",
    "EnergyMeter",
    "InverterPars",
    "LoadProfile",
    "LoadSum",
    "MotorPars",
    "Plant",
    "PlantProfile",
    "Preset",
    "Protection",
    "ProtectionPars",
    "RampLoad",
    "Sample",
    "SaturationPars",
    "SensorPars",
    "SpeedProportionalLoad",
    "StepLoad",
    "Truth",
    "UnknownPresetError",
    "UnknownProfileError",
    "compiled_engine_missing",
    "cross_saturation_check",
    "device_drop_error",
    "drive_profile",
    "encoder_angle",
    "flux_d",
    "flux_dq",
    "ideal_profile",
    "magnetic_energy",
    "plant_profile",
    "preset",
    "resolve_engine",
    "torque",
]
