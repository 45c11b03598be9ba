"""The plants a study runs a scenario on: the papers' ideal plant, and a drive's with and
without its countermeasures (:func:`plant_variant`)."""

from __future__ import annotations

from dataclasses import replace

from bench._errors import BenchError
from bench.scenarios._schema import Scenario
from bench.scenarios._setup import COUNTERMEASURES

#: The plants of the suite (:func:`plant_variant`), in report order.
PLANTS = ("ideal", "drive", "drive-nocomp")
#: How the report names each plant.
PLANT_LABELS = {
    "ideal": "ideal plant",
    "drive": "drive plant, countermeasures on",
    "drive-nocomp": "drive plant, countermeasures off",
}


def plant_variant(scn: Scenario, plant: str) -> Scenario:
    """``scn`` on one of :data:`PLANTS`: the shipped scenario's plant with every
    countermeasure of :data:`~bench.scenarios._setup.COUNTERMEASURES` off (``ideal``), or
    the ``drive`` profile with all of them on (``drive``) or off (``drive-nocomp``: what
    the drive does to a firmware that does not compensate). Each plant sets the three
    switches itself rather than take the defaults
    (:func:`bench.scenarios._setup.countermeasures`), so a column means the same whatever
    the defaults; the scenario's other ``[controller]`` values are kept."""
    if plant not in PLANTS:
        raise BenchError(f"unknown plant {plant!r} (known: {', '.join(PLANTS)})")
    ctl = {**scn.controller, **dict.fromkeys(COUNTERMEASURES, plant == "drive")}
    if plant == "ideal":
        return replace(scn, controller=ctl)
    return replace(scn, plant_profile="drive", controller=ctl)


__all__ = ["COUNTERMEASURES", "PLANTS", "PLANT_LABELS", "plant_variant"]
