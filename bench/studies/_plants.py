"""The plants a study runs a scenario on: the papers' ideal plant, and a drive's with and
without its countermeasures (:func:`plant_variant`)."""

from __future__ import annotations

from dataclasses import replace

from bench._errors import BenchError
from bench.scenarios._schema import Scenario

#: The plants of the suite (:func:`plant_variant`), in report order.
PLANTS = ("ideal", "drive", "drive-nocomp")
#: How the report names each plant.
PLANT_LABELS = {
    "ideal": "ideal plant",
    "drive": "drive plant, countermeasures on",
    "drive-nocomp": "drive plant, countermeasures off",
}
#: The ``[controller]`` countermeasures ``drive`` switches on and ``drive-nocomp`` off.
COUNTERMEASURES = ("dead_time_compensation", "cross_saturation_compensation", "offset_calibration")


def plant_variant(scn: Scenario, plant: str) -> Scenario:
    """``scn`` on one of :data:`PLANTS`: as shipped (``ideal``), or on the ``drive``
    profile with every countermeasure of :data:`COUNTERMEASURES` on (``drive``) or off
    (``drive-nocomp``); the scenario's own ``[controller]`` values are kept otherwise."""
    if plant == "ideal":
        return scn
    if plant not in PLANTS:
        raise BenchError(f"unknown plant {plant!r} (known: {', '.join(PLANTS)})")
    on = plant == "drive"
    ctl = {**scn.controller, **dict.fromkeys(COUNTERMEASURES, on)}
    return replace(scn, plant_profile="drive", controller=ctl)


__all__ = ["COUNTERMEASURES", "PLANTS", "PLANT_LABELS", "plant_variant"]
