"""``bench plant``: the plant emulator as one node on a bus.

It serves a run's plan (:mod:`bench.nodes._plan`): ``bench plant --plan FILE``
reads one (``bench run`` starts its plant so, with the ``plan.json`` of its run
folder), and ``bench plant SCENARIO [options]`` makes one from the scenario and
the options, as ``bench run`` would.  The options of how this node serves the
plan (``--engine``, ``--truth-every``, the watchdogs, ``--report``, the real-time
ones) go with either; the run's own settings (:data:`PLAN_FIXES`) only with a
SCENARIO.
"""

from __future__ import annotations

import argparse
from typing import Any

from bench._errors import BenchError
from bench.cli._common import (
    NONNEG_INT,
    POS_FLOAT,
    POS_INT,
    STOP,
    add_bus,
    add_engine,
    add_plan,
    add_plant_profile,
    add_rt,
    add_scenario_overrides,
    bus_spec,
    choose_node_engine,
    plant_engine,
    ready,
    run_id_arg,
    scenario_from_args,
    serve_node,
)

#: The options of a run's settings: with ``--plan`` the plan fixes them (module docstring).
PLAN_FIXES = (
    ("scenario", "SCENARIO"),
    ("mode", "--mode"),
    ("duration", "--duration"),
    ("delay_steps", "--delay-steps"),
    ("sample_delay_steps", "--sample-delay-steps"),
    ("seed", "--seed"),
    ("plant_profile", "--plant-profile"),
    ("run_id", "--run-id"),
    ("pace_every", "--pace-every"),
    ("dut_timeout", "--dut-timeout"),
    ("estimator", "--estimator"),
    ("interface", "--interface"),
    ("channel", "--channel"),
    ("port", "--port"),
    ("bitrate", "--bitrate"),
    ("data_bitrate", "--data-bitrate"),
)


def node_plan(args: argparse.Namespace, role: str) -> Any:
    """The node's run plan: ``--plan FILE``, or made here from SCENARIO and the options.

    With ``--plan`` none of the run's settings (:data:`PLAN_FIXES`) may be given:
    the plan fixed them when it was made (one line naming them otherwise).
    """
    from bench.nodes._plan import make_plan, read_plan
    from bench.scenarios._setup import with_position_sensor
    from bench.wire._protocol import new_run_id

    if args.plan:
        given = [opt for dest, opt in PLAN_FIXES if getattr(args, dest, None) is not None]
        if given:
            raise BenchError(
                f"--plan {args.plan}: the plan fixes the run's settings; "
                f"{', '.join(given)} cannot change them (make a new plan, or run from SCENARIO)"
            )
        plan = read_plan(args.plan)
        if role == "controller" and plan.controller is None:
            raise BenchError(f"--plan {args.plan}: the plan has no controller of the bench's")
    else:
        if not args.scenario:
            raise BenchError(f"bench {role}: give a SCENARIO or --plan FILE")
        scn = scenario_from_args(args)
        est = None
        if role == "controller":
            est = args.estimator or scn.estimator
        elif args.dut_timeout:
            # a controller under test reads PositionSensor (docs/PROTOCOL.md)
            scn = with_position_sensor(scn)
        run_id = args.run_id if args.run_id is not None else new_run_id()
        if role == "controller":
            run_id = args.run_id or 0  # unknown unless given
        plan = make_plan(
            scn,
            est,
            mode=args.mode or "lockstep",
            plant_bus=bus_spec(args, announce=False),
            run_id=run_id,
            pace_every=getattr(args, "pace_every", None) or 0,
            dut_timeout_s=getattr(args, "dut_timeout", None) or 0.0,
        )
    args.mode = plan.mode  # the node's real-time settings follow it (serve_node)
    return plan


def _native_missing(node: Any, spec: Any) -> str | None:
    from bench.nodes.native._plant_native import native_missing

    return native_missing(node, spec.interface)


def cmd_plant(args: argparse.Namespace) -> int:
    import sys

    from bench.nodes._loops import plant_loop, plant_node
    from bench.wire._codec import Codec

    plan = node_plan(args, "plant")
    spec = plan.bus("plant")
    # a controller author needs to know where to listen (bench show SCENARIO says it too)
    print(
        f"plant: {plan.scenario}, {plan.mode}, on {spec.describe()}, run {plan.run_id:#06x}",
        file=sys.stderr,
        flush=True,
    )
    codec = Codec()
    node = plant_node(
        plan.plant.build(plant_engine(args)),
        plan.n_steps,
        plan.lockstep_delay,
        codec,
        truth_every=args.truth_every,
        watchdog_s=None if args.watchdog_ms is None else args.watchdog_ms * 1e-3,
        watchdog_rounds=args.watchdog_rounds,
        faults=plan.faults,
        seed=plan.seed,
    )
    node.run_id = plan.run_id
    if plan.mode == "lockstep":
        node.pace_every = plan.pace_every
    node.realtime = plan.mode == "realtime"  # what the native loop serves depends on it
    node.node_engine = choose_node_engine("plant", args.engine, lambda: _native_missing(node, spec))
    if node.node_engine == "native":
        from bench.nodes._loops import RETRANSMIT_S, STALL_S
        from bench.nodes.native._plant_native import open_native_bus, plant_loop_native
        from bench.wire._bus import quiet_receive

        nbus = open_native_bus(spec)  # where the Python node opens its bus: no frame missed

        def native_loop(bus: Any) -> None:
            quiet_receive(bus, spec.channel)  # serve_node's python-can bus is not read here
            plant_loop_native(
                spec,
                node,
                realtime=plan.mode == "realtime",
                on_ready=ready,
                stop=STOP.is_set,
                watchdog_s=STALL_S,
                dut_timeout_s=plan.dut_timeout_s,
                retransmit_s=RETRANSMIT_S,
                bus=nbus,
            )

        return serve_node(args, spec, "plant", node, native_loop)
    return serve_node(
        args,
        spec,
        "plant",
        node,
        lambda bus: plant_loop(
            bus,
            node,
            realtime=plan.mode == "realtime",
            on_ready=ready,
            stop=STOP.is_set,
            dut_timeout_s=plan.dut_timeout_s,
        ),
    )


def register(sub: Any) -> None:
    p = sub.add_parser("plant", help="serve the plant emulator on a bus (one node)")
    p.add_argument(
        "scenario", nargs="?", help="scenario name or file (or --plan FILE: a run's plan.json)"
    )
    add_plan(p)
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
    # None: not given (the plan's; the defaults are the plan's, lockstep and 0)
    p.set_defaults(func=cmd_plant, mode=None)
