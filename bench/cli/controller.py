"""``bench controller``: the project's drive controller as one node on a bus.

As ``bench plant`` (:mod:`bench.cli.plant`): ``--plan FILE`` serves a run's plan,
``SCENARIO [--estimator NAME] [options]`` makes one.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Callable
from typing import Any

from bench.cli._common import (
    POS_FLOAT,
    STOP,
    add_bus,
    add_controller_engine,
    add_plan,
    add_rt,
    add_scenario_overrides,
    choose_node_engine,
    node_rt,
    ready,
    run_id_arg,
    serve_node,
    stop_on_signals,
    write_report,
)


def cmd_controller(args: argparse.Namespace) -> int:
    from bench.cli.plant import node_plan
    from bench.nodes._loops import controller_loop, controller_node
    from bench.scenarios._setup import ENGINE_ENV
    from bench.wire._codec import Codec

    if args.engine is not None:
        os.environ[ENGINE_ENV] = args.engine
    plan = node_plan(args, "controller")
    codec = Codec()
    node = controller_node(plan, codec)
    node.run_id = plan.run_id
    spec = plan.bus("controller")
    # the same rule as the plant node's (choose_node_engine); without --engine, the
    # engine bench run's processes inherit, else auto
    asked = os.environ.get(ENGINE_ENV) or "auto"
    if choose_node_engine("controller", asked, lambda: _native_missing(node, spec)) == "native":
        return serve_native(
            args,
            spec,
            node,
            realtime=plan.mode == "realtime",
            on_ready=ready,
            stop=STOP.is_set,
            sample_timeout_s=args.sample_timeout_ms * 1e-3,
        )
    return serve_node(
        args,
        spec,
        "controller",
        node,
        lambda bus: controller_loop(
            bus,
            node,
            realtime=plan.mode == "realtime",
            on_ready=ready,
            stop=STOP.is_set,
            sample_timeout_s=args.sample_timeout_ms * 1e-3,
        ),
    )


def _native_missing(node: Any, spec: Any) -> str | None:
    from bench.nodes.native.controller_node import native_unavailable

    return native_unavailable(node, spec.interface)


def serve_native(
    args: argparse.Namespace,
    spec: Any,
    node: Any,
    *,
    realtime: bool,
    on_ready: Callable[[], None] | None,
    stop: Callable[[], bool],
    sample_timeout_s: float,
) -> int:
    """:func:`serve_node` for the native loop (bench/nodes/native/controller_node.py): the
    real-time settings, the loop until it ends or a signal stops it, the node's report
    whatever ends it."""
    from bench.nodes.native.controller_node import native_controller_loop

    stop_on_signals()
    rt = node_rt(args, "controller")
    try:
        native_controller_loop(
            spec,
            node,
            realtime=realtime,
            on_ready=on_ready,
            stop=stop,
            sample_timeout_s=sample_timeout_s,
        )
    finally:
        write_report(args.report, {**node.report(), "rt": rt})
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser("controller", help="serve the drive controller on a bus (one node)")
    p.add_argument(
        "scenario", nargs="?", help="scenario name or file (or --plan FILE: a run's plan.json)"
    )
    add_plan(p)
    p.add_argument("--estimator", "-e")
    add_scenario_overrides(p)
    add_bus(p)
    p.add_argument("--report", help="write the node's counters to this JSON file at exit")
    p.add_argument(
        "--run-id",
        type=run_id_arg,
        metavar="N",
        help="the run's nonce sent in CtrlTelemetry.run_id (bench run gives it; default 0: unknown)",
    )
    p.add_argument(
        "--sample-timeout-ms",
        type=POS_FLOAT,
        default=50.0,
        help="real time: disable the PWM after this long without a valid sample",
    )
    add_controller_engine(p)
    add_rt(p)
    p.set_defaults(func=cmd_controller, mode=None)
