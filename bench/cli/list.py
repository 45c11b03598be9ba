"""``bench list``: the shipped scenarios, the presets, the estimators and the plant profiles."""

from __future__ import annotations

import argparse
import json
from typing import Any


def cmd_list(args: argparse.Namespace) -> int:
    from bench.scenarios._describe import catalogue

    cat = catalogue()
    if args.json:
        print(json.dumps(cat, indent=2))
        return 0
    print("scenarios (bench run NAME, or a path to your own .toml):")
    for name, s in cat["scenarios"].items():
        print(f"  {name:16s} {s['preset']:8s} {s['duration_s']:5.1f} s  {s['description']}")
    print("presets (motor, inverter, PWM rate; bench show SCENARIO prints the motor):")
    for name, p in cat["presets"].items():
        print(f"  {name:16s} f_sw {p['f_sw_hz']:g} Hz, n_p {p['n_p']}, u_dc {p['u_dc']:g} V")
    print("estimators (--estimator; injection family; docs/SCENARIOS.md lists their options):")
    for name, s in cat["estimator_specs"].items():
        print(f"  {name:20s} {s['family']:9s} {s['summary']}")
    for name, fam in cat["estimator_plugins"].items():
        print(f"  {name:20s} {fam} (installed plug-in)")
    print("  package.module:factory  your own estimator (docs/ESTIMATORS.md)")
    print("plant profiles (--plant-profile, plant_profile): " + ", ".join(cat["plant_profiles"]))
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser("list", help="shipped scenarios, presets, estimators and plant profiles")
    p.add_argument("--json", action="store_true", help="as JSON")
    p.set_defaults(func=cmd_list)
