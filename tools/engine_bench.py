"""Plant engines side by side, in one process: ``.venv/bin/python tools/engine_bench.py``.

1. The plant alone, per period (``sample()`` and ``step()``): the average
   model (ideal profile) and the switching model (drive profile) of
   wen2023 at 10 kHz, fed the duties a tt-dq controller gave in a closed
   loop (recorded once, replayed into a fresh plant per run).
2. The in-process closed loop plant + tt-dq controller at 10 kHz
   (wen-5.1, the loop of ``bench perf``), with the scenario's plant and with
   the drive profile's switching plant.

Each figure is the median of ``--runs`` runs; the machine is shared, so the
ratios measured in the same run say more than the absolute times.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time
from typing import Any

from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import build_controller, build_plant
from controller import Controller, Measurement
from plant_rt import ConstantLoad, Plant, drive_profile, ideal_profile, preset

Duty = tuple[float, float, float, bool]


def _plant(model: str, engine: str) -> Plant:
    p = preset("wen2023")
    prof = drive_profile(p) if model == "switching" else ideal_profile(p)
    return Plant(
        p.motor,
        prof.inverter,
        p.T_s,
        sensors=prof.sensors,
        saturation=prof.saturation,
        cross_saturation=prof.cross_saturation,
        load=ConstantLoad(1.0),
        engine=engine,
    )


def _controller() -> Controller:
    ctrl = build_controller(load_scenario("wen-5.1"), "tt-dq")
    ctrl.set_enable(True)
    ctrl.set_speed_ref(300.0 * 2.0 * math.pi / 60.0)
    return ctrl


def _loop(plant: Plant, ctrl: Controller, n: int, record: list[Duty] | None = None) -> None:
    d: Duty = (0.5, 0.5, 0.5, False)
    for _ in range(n):
        s = plant.sample()
        o = ctrl.step(Measurement(s.k, s.i_a, s.i_b, s.i_c, s.u_dc, None, None))
        plant.step(*d)
        if record is not None:
            record.append(d)
        d = (o.d_a, o.d_b, o.d_c, o.enable)


def plant_alone(model: str, engine: str, duties: list[Duty], runs: int) -> float:
    """Median seconds per period of ``sample()`` + ``step()`` over the recorded duties."""
    times = []
    for _ in range(runs):
        plant = _plant(model, engine)
        t0 = time.perf_counter()
        for d in duties:
            plant.sample()
            plant.step(*d)
        times.append((time.perf_counter() - t0) / len(duties))
    return statistics.median(times)


def closed_loop(model: str | None, engine: str, n: int, runs: int) -> float:
    """Median seconds per step of plant + tt-dq controller; ``model`` None: wen-5.1's plant."""
    times = []
    for _ in range(runs):
        plant = (
            build_plant(load_scenario("wen-5.1"), engine)
            if model is None
            else _plant(model, engine)
        )
        ctrl = _controller()
        _loop(plant, ctrl, 2000)  # past the start-up (not timed)
        t0 = time.perf_counter()
        _loop(plant, ctrl, n)
        times.append((time.perf_counter() - t0) / n)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=7)
    ap.add_argument("--steps", type=int, default=10_000, help="periods per run")
    ap.add_argument("--json", help="also write the figures to this file")
    a = ap.parse_args()
    out: dict[str, Any] = {"plant_us_per_period": {}, "loop_10khz_tt_dq": {}}
    for model in ("average", "switching"):
        duties: list[Duty] = []
        _loop(_plant(model, "python"), _controller(), 2000 + a.steps, duties)
        duties = duties[2000:]
        row = {e: 1e6 * plant_alone(model, e, duties, a.runs) for e in ("python", "compiled")}
        row["speedup"] = row["python"] / row["compiled"]
        out["plant_us_per_period"][model] = row
        print(
            f"plant alone, {model:9s}: python {row['python']:7.2f} us  "
            f"compiled {row['compiled']:6.2f} us  ({row['speedup']:.1f}x)"
        )
    for label, model in (("wen-5.1 (average)", None), ("drive (switching)", "switching")):
        row = {}
        for e in ("python", "compiled"):
            us = 1e6 * closed_loop(model, e, a.steps, a.runs)
            row[e] = {"us_per_step": us, "steps_per_s": 1e6 / us, "rtf_10khz": 100.0 / us}
        speedup = row["python"]["us_per_step"] / row["compiled"]["us_per_step"]
        out["loop_10khz_tt_dq"][label] = {**row, "speedup": speedup}
        print(
            f"loop tt-dq 10 kHz, {label}: python {row['python']['steps_per_s']:7.0f} steps/s "
            f"({row['python']['rtf_10khz']:.1f}x real time), compiled "
            f"{row['compiled']['steps_per_s']:7.0f} steps/s "
            f"({row['compiled']['rtf_10khz']:.1f}x real time); {speedup:.2f}x"
        )
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f, indent=2)


if __name__ == "__main__":
    main()
