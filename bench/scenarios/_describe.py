"""What a controller author needs to know about a scenario, as plain data.

``bench show`` prints it; ``bench list`` lists what exists.  The motor is
the preset with the scenario's ``[motor]`` values in place, the plant the
profile as built, and the commands are the frames the bench sends:
``BenchCommand`` with the step it applies at, the command code, the speed
reference (rpm, mechanical) and the load torque (N m).
"""

from __future__ import annotations

from dataclasses import asdict
from typing import Any

from bench.scenarios._schema import SHIPPED, Scenario, load_scenario
from bench.scenarios._setup import command_schedule, n_steps, plant_setup, sample_period


def cmd_names() -> dict[int, str]:
    """``BenchCommand.cmd`` names, from the DBC's value table (``none``: new references only)."""
    from bench.wire._codec import default_codec

    sig = default_codec().message("BenchCommand").get_signal_by_name("cmd")
    return {int(k): str(v) for k, v in (sig.choices or {}).items()}


def describe(scn: Scenario) -> dict[str, Any]:
    """The effective scenario, its motor, PWM rate, plant and command schedule."""
    p, prof = plant_setup(scn)
    T_s = sample_period(scn)
    names = cmd_names()
    return {
        "scenario": scn.to_dict(),
        "pwm": {"f_sw_hz": 1.0 / T_s, "T_s": T_s, "periods": n_steps(scn)},
        "motor": {"preset": p.name, **asdict(p.motor), "replaced": sorted(scn.motor)},
        "plant": {
            "profile": prof.name,
            "inverter": asdict(prof.inverter),
            "sensors": asdict(prof.sensors),
            "saturation": prof.saturation,
            "cross_saturation": prof.cross_saturation,
        },
        "commands": [
            {
                "step": c.apply_step,
                "cmd": c.cmd,
                "cmd_name": names.get(c.cmd, "?"),
                "speed_ref_rpm": c.speed_ref_rpm,
                "load_nm": c.load_nm,
            }
            for c in command_schedule(scn)
        ],
    }


def catalogue() -> dict[str, Any]:
    """The shipped scenarios, presets, estimators and plant profiles."""
    from controller._registry import (
        ESTIMATOR_NAMES,
        UnknownEstimatorError,
        entry_point_names,
        injection_family,
    )
    from plant_rt import PRESETS, PROFILE_NAMES

    scenarios = {}
    for name in SHIPPED:
        s = load_scenario(name)
        scenarios[name] = {
            "description": s.description,
            "paper": s.paper,
            "preset": s.preset,
            "estimators": list(s.estimators),
            "duration_s": s.duration,
        }
    presets = {
        name: {"f_sw_hz": p.f_sw, "n_p": p.motor.n_p, "u_dc": p.inverter.u_dc}
        for name, p in PRESETS.items()
    }
    plugins: dict[str, str] = {}
    for e in entry_point_names():
        try:
            plugins[e] = injection_family(e)
        except UnknownEstimatorError as err:  # an installed plug-in that does not load
            plugins[e] = f"error: {err}"
    return {
        "scenarios": scenarios,
        "presets": presets,
        "estimators": {e: injection_family(e) for e in ESTIMATOR_NAMES},
        "estimator_plugins": plugins,
        "plant_profiles": list(PROFILE_NAMES),
    }
