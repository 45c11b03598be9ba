"""``bench plant``: the plant emulator as one node on a bus."""

from __future__ import annotations

import argparse
from typing import Any

from bench.cli._common import (
    NONNEG_INT,
    POS_FLOAT,
    POS_INT,
    STOP,
    add_bus,
    add_engine,
    add_plant_profile,
    add_rt,
    add_scenario_overrides,
    bus_spec,
    plant_engine,
    ready,
    run_id_arg,
    scenario_from_args,
    serve_node,
)


def cmd_plant(args: argparse.Namespace) -> int:
    import sys

    from bench.nodes._loops import make_plant_node, plant_loop
    from bench.scenarios._setup import with_position_sensor
    from bench.wire._codec import Codec
    from bench.wire._protocol import new_run_id

    scn = scenario_from_args(args)
    if args.dut_timeout:
        # a controller under test reads PositionSensor (docs/PROTOCOL.md)
        scn = with_position_sensor(scn)
    spec = bus_spec(args, announce=False)
    run_id = args.run_id or new_run_id()
    # a controller author needs to know where to listen (bench show SCENARIO says it too)
    print(
        f"plant: {scn.name}, {args.mode}, on {spec.describe()}, run {run_id:#06x}",
        file=sys.stderr,
        flush=True,
    )
    codec = Codec()
    node = make_plant_node(
        scn,
        codec,
        truth_every=args.truth_every,
        watchdog_s=None if args.watchdog_ms is None else args.watchdog_ms * 1e-3,
        watchdog_rounds=args.watchdog_rounds,
        engine=plant_engine(args),
    )
    node.run_id = run_id
    if args.mode == "lockstep":
        node.pace_every = args.pace_every
    return serve_node(
        args,
        spec,
        "plant",
        node,
        lambda bus: plant_loop(
            bus,
            node,
            realtime=args.mode == "realtime",
            on_ready=ready,
            stop=STOP.is_set,
            dut_timeout_s=args.dut_timeout or 0.0,
        ),
    )


def register(sub: Any) -> None:
    p = sub.add_parser("plant", help="serve the plant emulator on a bus (one node)")
    p.add_argument("scenario")
    add_scenario_overrides(p)
    add_plant_profile(p)
    add_bus(p)
    p.add_argument("--truth-every", type=POS_INT, default=1, help="send PlantTruth every N periods")
    p.add_argument(
        "--watchdog-ms",
        type=POS_FLOAT,
        help="real time: safe state after this long without a valid duty (default 10 periods, >= 20 ms)",
    )
    p.add_argument(
        "--watchdog-rounds",
        type=POS_INT,
        default=100,
        help="lockstep: safe state after this many 50 ms retransmission rounds without a duty",
    )
    p.add_argument("--report", help="write the node's counters to this JSON file at exit")
    p.add_argument(
        "--run-id",
        type=run_id_arg,
        metavar="N",
        help="the run's nonce sent in PlantTruth.run_id (1..65535; default: random; "
        "bench run gives its own)",
    )
    p.add_argument(
        "--pace-every",
        type=NONNEG_INT,
        default=0,
        metavar="N",
        help="lockstep: run period k only once a bench command for step k or later has come "
        "(the sender keeps one at least every N periods); 0: off (bench run sets it)",
    )
    p.add_argument(
        "--dut-timeout",
        type=POS_FLOAT,
        metavar="S",
        help="serve a controller under test: wait up to S seconds for its first PwmDuty "
        "(real time: the clock starts then); a lockstep watchdog trip ends the run; "
        "sends PositionSensor (the scenario's sensor, or a 16-bit one every period)",
    )
    add_engine(p)
    add_rt(p)
    p.set_defaults(func=cmd_plant)
