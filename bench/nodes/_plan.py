"""The resolved plan of a run: made once from the scenario and the options, read by every node.

:func:`make_plan` turns an effective scenario (every override in place) and the
run's options into a :class:`RunPlan`: the PWM period and the number of periods
(the one place a run's ``duration`` becomes steps), the plant and the
controller as built (:class:`bench.scenarios._setup.PlantBuild`,
:class:`controller.ControllerPars`), the command schedule, the buses, the
latency link, the run's nonce, mode and pacing.  ``bench run`` writes it as
``plan.json`` in the run folder (:data:`PLAN_FILE`), and each node process
(``bench plant --plan``, ``bench controller --plan``, ``bench link --plan``)
reads that one file: a node neither parses the scenario again nor takes any
of the run's settings on its command line.  Run by hand, ``bench plant
SCENARIO ...`` and ``bench controller SCENARIO ...`` make the same plan from
their options (docs/PROTOCOL.md).

The file is JSON: every dataclass as an object of its fields, read back into
the same dataclasses by their type hints (:func:`read_plan`); a float is
written as Python's ``repr`` and read back bit for bit.
"""

from __future__ import annotations

import collections.abc
import json
import types
import typing
from dataclasses import dataclass, fields, is_dataclass
from pathlib import Path
from typing import Any, Literal, Union, get_args, get_origin, get_type_hints

from bench._errors import BenchError
from bench.scenarios._faults import Fault
from bench.scenarios._schema import Scenario
from bench.scenarios._setup import (
    PlannedCommand,
    PlantBuild,
    command_schedule,
    controller_pars,
    lockstep_delay,
    n_steps,
    needs_truth,
    plant_build,
    sample_period,
)
from bench.wire._bus import BusSpec
from controller import ControllerPars, DesignRecord

__all__ = ["PLAN_FILE", "PLAN_VERSION", "LinkPlan", "RunPlan", "make_plan", "read_plan"]

#: The plan's name in a run folder.
PLAN_FILE = "plan.json"
#: Version of the file's layout; a node refuses a plan of another version (one line).
PLAN_VERSION = 1
#: The node roles a plan names a bus for.
ROLES = ("plant", "controller")


@dataclass(frozen=True, slots=True)
class LinkPlan:
    """What the latency link (``bench link``) injects: the scenario's ``[latency]``."""

    seed: int
    duty_delay_steps: int
    sample_delay_steps: int
    duty_delay_us: float
    sample_delay_us: float
    duty_jitter_us: float
    sample_jitter_us: float
    jitter_dist: str
    duty_drop_prob: float
    sample_drop_prob: float


@dataclass(frozen=True, slots=True)
class RunPlan:
    """Everything a run's nodes need, resolved once (module docstring).

    ``estimator`` and ``controller`` are None when the plan has no controller
    of the bench's (a plant serving a controller under test, ``bench plant``
    alone).  ``buses`` names the bus of each role (:data:`ROLES`): with a
    latency link the controller's is the link's second bus.  ``dut_timeout_s``
    > 0: the plant serves a controller under test (``bench plant
    --dut-timeout``).  ``commands`` is the schedule the bench sends
    (:func:`bench.scenarios._setup.command_schedule`).  ``design`` is the
    controller's design as the process that wrote the plan made it
    (:meth:`controller.Controller.design_record`: its searches' results), so
    that the controller node builds the same controller without searching
    again; None: the node designs it (a plan made by ``bench controller
    SCENARIO``).  A design made for other settings than ``controller`` (a plan
    edited by hand) is not used: the node designs for ``controller`` itself and
    says so on one line.
    """

    scenario: str
    estimator: str | None
    mode: str
    T_s: float
    n_steps: int
    run_id: int
    pace_every: int
    dut_timeout_s: float
    lockstep_delay: int
    plant: PlantBuild
    controller: ControllerPars | None
    needs_truth: bool
    commands: tuple[PlannedCommand, ...]
    buses: dict[str, BusSpec]
    link: LinkPlan | None
    seed: int
    faults: tuple[Fault, ...] = ()
    design: DesignRecord | None = None
    version: int = PLAN_VERSION

    def bus(self, role: str) -> BusSpec:
        return self.buses[role]

    def write(self, path: Path) -> Path:
        """Write the plan as JSON to ``path``; returns ``path``."""
        path.write_text(json.dumps(_encode(self), indent=1) + "\n")
        return path


def make_plan(
    scn: Scenario,
    estimator: str | None,
    *,
    mode: str,
    plant_bus: BusSpec,
    controller_bus: BusSpec | None = None,
    run_id: int,
    pace_every: int = 0,
    dut_timeout_s: float = 0.0,
    design: DesignRecord | None = None,
) -> RunPlan:
    """The plan of a run of ``scn`` (effective: every override in place) with ``estimator``.

    ``controller_bus``: the controller's bus when a latency link stands between
    (default: the plant's).  ``estimator`` None: no controller of the bench's.
    ``design``: the controller's design made beforehand (:attr:`RunPlan.design`).
    """
    lt = scn.latency
    link = None
    if lt.any:
        link = LinkPlan(
            seed=scn.seed,
            duty_delay_steps=lt.duty_delay_steps,
            sample_delay_steps=lt.sample_delay_steps,
            duty_delay_us=lt.duty_delay_us,
            sample_delay_us=lt.sample_delay_us,
            duty_jitter_us=lt.duty.jitter_us,
            sample_jitter_us=lt.sample.jitter_us,
            jitter_dist=lt.jitter_dist,
            duty_drop_prob=lt.duty.drop_prob,
            sample_drop_prob=lt.sample.drop_prob,
        )
    return RunPlan(
        scenario=scn.name,
        estimator=estimator,
        mode=mode,
        T_s=sample_period(scn),
        n_steps=n_steps(scn),
        run_id=run_id,
        pace_every=pace_every,
        dut_timeout_s=dut_timeout_s,
        lockstep_delay=lockstep_delay(scn),
        plant=plant_build(scn),
        controller=controller_pars(scn, estimator) if estimator else None,
        needs_truth=needs_truth(estimator) if estimator else False,
        commands=tuple(command_schedule(scn)),
        buses={"plant": plant_bus, "controller": controller_bus or plant_bus},
        link=link,
        seed=scn.seed,
        faults=tuple(scn.faults),
        design=design if estimator else None,
    )


def read_plan(path: str | Path) -> RunPlan:
    """The plan in ``path``; a missing, unreadable or foreign file is one line (BenchError)."""
    p = Path(path)
    try:
        data = json.loads(p.read_text())
    except (OSError, ValueError) as e:
        why = e.strerror if isinstance(e, OSError) and e.strerror else str(e)
        raise BenchError(f"--plan {p}: cannot read it ({why})") from None
    if not isinstance(data, dict) or data.get("version") != PLAN_VERSION:
        got = data.get("version") if isinstance(data, dict) else None
        raise BenchError(
            f"--plan {p}: not a run plan of version {PLAN_VERSION} (version {got!r}); "
            "bench run writes one into its run folder"
        )
    try:
        plan = _decode(RunPlan, data)
    except (KeyError, TypeError, ValueError) as e:
        raise BenchError(f"--plan {p}: field {e}: missing or of the wrong type") from None
    assert isinstance(plan, RunPlan)
    return plan


def _encode(v: Any) -> Any:
    if is_dataclass(v) and not isinstance(v, type):
        return {f.name: _encode(getattr(v, f.name)) for f in fields(v)}
    if isinstance(v, collections.abc.Mapping):
        return {str(k): _encode(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_encode(x) for x in v]
    return v


def _decode(tp: Any, v: Any) -> Any:
    """``v`` (parsed JSON) as type ``tp`` (a type hint: dataclasses, tuples, dicts, unions)."""
    origin, args = get_origin(tp), get_args(tp)
    if tp is Any or origin is Literal:
        return v
    if origin in (Union, types.UnionType):
        if v is None:
            return None
        kinds = [a for a in args if a is not type(None)]
        return _decode(kinds[0], v) if len(kinds) == 1 else v
    if isinstance(tp, type) and is_dataclass(tp):
        hints = get_type_hints(tp)
        return tp(**{f.name: _decode(hints[f.name], v[f.name]) for f in fields(tp) if f.init})
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_decode(args[0], x) for x in v)
        return tuple(_decode(a, x) for a, x in zip(args, v, strict=True))
    if origin in (list, collections.abc.Sequence):
        return [_decode(args[0] if args else Any, x) for x in v]
    if origin in (dict, collections.abc.Mapping, typing.Mapping):
        kind = args[1] if len(args) == 2 else Any
        return {k: _decode(kind, x) for k, x in v.items()}
    if tp is float:
        return float(v)
    if tp in (int, bool, str) and not isinstance(v, tp):
        raise TypeError(f"expected {tp.__name__}, got {v!r}")
    return v
