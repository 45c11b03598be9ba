"""Pure drive controller: field-oriented control and sensorless estimators.

Never imports :mod:`plant_rt`, never touches CAN.
"""

from controller._api import (
    MODE_ALIGN,
    MODE_DISABLED,
    MODE_FAULT,
    MODE_POLARITY,
    MODE_RUN,
    ControlOutput,
    Estimator,
    EstimatorInput,
    Measurement,
    Option,
    option_field,
)
from controller._compensation import CompensationPars
from controller._controller import Controller, ControllerPars
from controller._cplugin import CEstimator, c_estimator
from controller._design import PM_TARGET_DEG, DesignRecord
from controller._engine import (
    ENGINES,
    compiled_controller_missing,
    core_sources,
    resolve_controller_engine,
)
from controller._filters import BPF_WEN, HPF_WEN, LPF_WEN, discretize
from controller._flux_observer import FluxObserver, pll_gains
from controller._hybrid import HybridDesign, HybridEstimator, TransitionBand, design
from controller._params import MotorModel
from controller._pi import PIController
from controller._pll import PositionObserver
from controller._registry import (
    ENTRY_POINT_GROUP,
    ESTIMATOR_NAMES,
    EstimatorPluginError,
    EstimatorSpec,
    UnknownEstimatorError,
    check_estimator,
    declared_options,
    make_estimator,
)
from controller._registry import spec as estimator_spec
from controller._rotating import RotatingInjectionPars, hf_amplitudes
from controller._startup import PolarityTest
from controller._supervision import DETECTION_MODES, SupervisionPars, Supervisor
from controller._svpwm import svpwm
from controller._transforms import clarke, inv_clarke, inv_park, park, wrap_2pi, wrap_pi

__all__ = [
    "BPF_WEN",
    "DETECTION_MODES",
    "ENGINES",
    "ENTRY_POINT_GROUP",
    "ESTIMATOR_NAMES",
    "HPF_WEN",
    "LPF_WEN",
    "MODE_ALIGN",
    "MODE_DISABLED",
    "MODE_FAULT",
    "MODE_POLARITY",
    "MODE_RUN",
    "PM_TARGET_DEG",
    "CEstimator",
    "CompensationPars",
    "ControlOutput",
    "Controller",
    "ControllerPars",
    "DesignRecord",
    "Estimator",
    "EstimatorInput",
    "EstimatorPluginError",
    "EstimatorSpec",
    "FluxObserver",
    "HybridDesign",
    "HybridEstimator",
    "Measurement",
    "MotorModel",
    "Option",
    "PIController",
    "PolarityTest",
    "PositionObserver",
    "RotatingInjectionPars",
    "SupervisionPars",
    "Supervisor",
    "TransitionBand",
    "UnknownEstimatorError",
    "c_estimator",
    "check_estimator",
    "clarke",
    "compiled_controller_missing",
    "core_sources",
    "declared_options",
    "design",
    "discretize",
    "estimator_spec",
    "hf_amplitudes",
    "inv_clarke",
    "inv_park",
    "make_estimator",
    "option_field",
    "park",
    "pll_gains",
    "resolve_controller_engine",
    "svpwm",
    "wrap_2pi",
    "wrap_pi",
]
