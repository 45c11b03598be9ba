"""``bench codegen OUT_DIR``: C code of the wire contract for controller firmware.

Writes into ``OUT_DIR``:

- ``bench_dbc.h``, ``bench_dbc.c``: cantools' pack/unpack code of the DBC
  (:func:`bench.wire._ccodec.generate_c`; one struct per message, ``*_pack``,
  ``*_unpack`` and ``*_<signal>_encode/_decode/_is_in_range`` per signal);
- ``bench_e2e.h``, ``bench_e2e.c``: the E2E protection of the DBC
  (:func:`bench.wire._cgen.generate_e2e`): CRC-8 SAE J1850 (poly 0x1D, init 0xFF, xorout
  0xFF) over the message's 16-bit ``E2EDataId`` (low byte first) and every
  payload byte except the crc byte, as :mod:`bench.wire._e2e` computes it, with
  the data ID and crc byte index of each protected message as macros;
- ``bench_wire.h`` (:func:`bench.wire._ctlgen.generate_wire_header`): ``bench_wire_raw()``,
  a signal's raw value as the bench's codec encodes it (the bench's native controller node
  and the firmware both encode with it);
- ``core/``: the controller core (``controller/core/``).

- with ``--scenario NAME``, ``bench_scenario.h`` (:func:`bench.wire._cgen.generate_scenario_header`):
  the scenario's motor (preset values with its ``[motor]`` in place), PWM
  rate and period, duration, start-up and command schedule as C macros
  (the schedule as constant/ramp/step segments; with ``--commands`` also
  every ``BenchCommand`` frame as a ``const`` table initializer), so a
  controller's firmware builds against the plant it meets.
- with ``--scenario NAME --estimator EST``, also ``bench_controller.h``
  (:func:`bench.wire._ctlgen.generate_controller_header`): the scenario's controller
  for the estimator as the bench builds it, as the core's ``cc_design_*`` calls with the
  Python design's values (``%.17g``), and the encodings of its output signals, so a
  firmware (``firmware/``, ``make ESTIMATOR=...``) runs the bench's controller.

The code is :mod:`bench.wire._cgen`'s and :mod:`bench.wire._ctlgen`'s; this module is the
command line.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from bench._errors import BenchError

__all__ = ["register"]


def _ship_core(out: Path) -> list[Path]:
    """The controller core (``controller/core/``) copied beside the codec, in ``core/``:
    the code a drive firmware builds its control law on (``firmware/``)."""
    from controller import core_sources

    (out / "core").mkdir(parents=True, exist_ok=True)
    paths = []
    for src in core_sources():
        dst = out / "core" / src.name
        dst.write_bytes(src.read_bytes())
        paths.append(dst)
    return paths


def _controller_header(out: Path, scenario: str, estimator: str, codec: Any) -> Path:
    """``bench_controller.h``: the scenario's controller for ``estimator``, as built."""
    from bench.scenarios._schema import load_scenario
    from bench.scenarios._setup import build_controller
    from bench.wire._ctlgen import generate_controller_header

    scn = load_scenario(scenario)
    try:
        ctrl = build_controller(scn, estimator, engine="compiled")
        return generate_controller_header(out, ctrl, codec, source=f"{estimator} of {scenario}")
    except ValueError as e:
        raise BenchError(f"--estimator {estimator}: {e}") from None


def cmd_codegen(args: argparse.Namespace) -> int:
    from bench.wire._ccodec import generate_c
    from bench.wire._cgen import generate_e2e, generate_scenario_header
    from bench.wire._codec import Codec
    from bench.wire._ctlgen import generate_wire_header

    out = Path(args.out_dir)
    if out.exists() and not out.is_dir():
        raise BenchError(f"OUT_DIR {out}: exists and is not a folder")
    codec = Codec(args.dbc) if args.dbc else Codec()
    if args.estimator and not args.scenario:
        raise BenchError("--estimator: needs --scenario (the controller is the scenario's)")
    try:
        files = [*generate_c(out, codec), *generate_e2e(out, codec), generate_wire_header(out)]
        files += _ship_core(out)
        if args.scenario:
            from bench.scenarios._describe import describe, schedule_lines
            from bench.scenarios._schema import load_scenario

            d = describe(load_scenario(args.scenario))
            text = schedule_lines(d["schedule"])
            files.append(
                generate_scenario_header(out, d, text, codec.version, commands=args.commands)
            )
        if args.estimator:
            files.append(_controller_header(out, args.scenario, args.estimator, codec))
    except OSError as e:
        raise BenchError(f"OUT_DIR {out}: cannot write ({e.strerror or e})") from None
    for f in files:
        print(f)
    print(f"codegen: C code of {codec.path.name} in {out}/", file=sys.stderr)
    return 0


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``bench codegen`` to the command line."""
    p = subparsers.add_parser(
        "codegen",
        help="write C pack/unpack code of the DBC and the E2E CRC helper (controller firmware)",
    )
    p.add_argument("out_dir", metavar="OUT_DIR", help="folder for the C files (created)")
    p.add_argument("--dbc", help="DBC file (default: the bench's dbc/bench.dbc)")
    p.add_argument(
        "--scenario",
        metavar="NAME",
        help="also write bench_scenario.h: the scenario's motor, PWM timing, start-up and "
        "command schedule (segments)",
    )
    p.add_argument(
        "--estimator",
        metavar="NAME",
        help="with --scenario: also write bench_controller.h, the scenario's controller for "
        "this estimator as the bench builds it (the core's init calls, exact values)",
    )
    p.add_argument(
        "--commands",
        action="store_true",
        help="with --scenario: also BENCH_SCN_COMMANDS, every BenchCommand frame as a table",
    )
    p.set_defaults(func=cmd_codegen)
