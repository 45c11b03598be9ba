"""``bench suite robustness``: where each paper's estimators keep lock and meet the paper's bound.

Each paper's estimators run from the paper's first scenario (Wen: ``wen-5.1``
with ``sfhf``, ``tt-ab``, ``tt-dq``; Xue: ``xue-fig13`` with ``square-wave``
and ``square-wave-nocic``: start-up at standstill with an unknown initial
angle, ramp to 100 rpm, hold) with one group of the scenario's keys changed
at a time (:data:`STUDIES`, on the :mod:`bench.studies._grid` engine):

- the controller's model against the plant (``[controller_model]``):
  ``L_d`` and ``L_q`` +-20 % (a heatmap), ``J`` x0.5 to x2 against
  ``psi_f`` +-10 % (a heatmap), ``R_s`` +-30 %;
- white noise on the phase currents (``sensors.current_noise_a``);
- the inverter's dead time (``inverter.t_dead``) with and without the
  controller's compensation (``controller.dead_time_compensation``);
- the current ADC's resolution (``sensors.adc_bits``, full scale
  ``2 i_max`` as in the ``drive`` profile).

A point *meets the bound* when the estimator kept lock
(:func:`bench.runs._metrics.lock_lost`), the run did not fail, and its
largest angle error in the scored window is within the paper's bound for
that scenario: Wen Table 5 (``wen-5.1``: -0.5 to 4 deg, so |dtheta| <= 4
deg) and Xue Fig. 13 (|dtheta| <= 0.1 rad).  The bound is the proposed
method's; the other methods of the paper are held to it as well, which is
the paper's own comparison.

Cost.  Every point is a short run (:data:`DURATION_S` simulated seconds,
scored from :data:`SCORE_FROM_S`: 0.3 s after the ramp ends), on coarse
grids (3 to 5 values per key); the report states both, so a reader knows
that a longer run could still drift out of the bound.
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bench.studies._grid import Plan, build_tasks, heatmap, line_plot, run_sweep

#: Simulated seconds of every point, and the start of its scored window (s).
DURATION_S = 1.6
SCORE_FROM_S = 1.1


@dataclass(frozen=True, slots=True)
class PaperSet:
    """One paper's scenario, estimators and angle bound (deg)."""

    name: str
    scenario: str
    estimators: tuple[str, ...]
    bound_deg: float
    bound_source: str


PAPERS: dict[str, PaperSet] = {
    "wen": PaperSet(
        "wen",
        "wen-5.1",
        ("sfhf", "tt-ab", "tt-dq"),
        4.0,
        "Wen et al. 2023, Table 5 (wen-5.1): dtheta from -0.5 to 4 deg",
    ),
    "xue": PaperSet(
        "xue",
        "xue-fig13",
        ("square-wave", "square-wave-nocic"),
        math.degrees(0.1),
        "Xue et al. 2022, Fig. 13 (xue-fig13): |dtheta| <= 0.1 rad",
    ),
}


@dataclass(frozen=True, slots=True)
class Study:
    """One group of keys varied together (a grid) and what it shows."""

    name: str
    title: str
    grid: dict[str, list[Any]]
    #: values set at every point (not swept); ``"adc_fs"`` is replaced by 2 i_max
    fixed: dict[str, Any]

    @property
    def nominal(self) -> dict[str, Any]:
        """The point with the scenario's own values: factor 1, no noise, no dead time, no ADC."""
        return {
            k: (1.0 if k.startswith("controller_model.") else v[0]) for k, v in self.grid.items()
        }


STUDIES: dict[str, Study] = {
    s.name: s
    for s in (
        Study(
            "model-inductances",
            "controller model: L_d and L_q +-20 %",
            {"controller_model.L_d": [0.8, 1.0, 1.2], "controller_model.L_q": [0.8, 1.0, 1.2]},
            {},
        ),
        Study(
            "model-inertia-flux",
            "controller model: J x0.5 to x2, psi_f +-10 %",
            {"controller_model.J": [0.5, 1.0, 2.0], "controller_model.psi_f": [0.9, 1.0, 1.1]},
            {},
        ),
        Study(
            "model-resistance",
            "controller model: R_s +-30 %",
            {"controller_model.R_s": [0.7, 1.0, 1.3]},
            {},
        ),
        Study(
            "current-noise",
            "white noise on the phase currents (A rms)",
            {"sensors.current_noise_a": [0.0, 0.01, 0.02, 0.05, 0.1, 0.2, 0.4]},
            {},
        ),
        Study(
            "dead-time",
            "inverter dead time, with and without the controller's compensation",
            {
                "inverter.t_dead": [0.0, 1e-6, 2e-6, 4e-6],
                "controller.dead_time_compensation": [False, True],
            },
            {},
        ),
        Study(
            "adc-bits",
            "current ADC resolution (bits; 0 = none), full scale 2 i_max",
            {"sensors.adc_bits": [0, 8, 10, 12]},
            {"sensors.current_full_scale_a": "adc_fs"},
        ),
    )
}


def study_plan(paper: PaperSet, study: Study, duration: float) -> Plan:
    """The sweep plan of one study for one paper."""
    from bench.scenarios._schema import load_scenario
    from bench.scenarios._setup import get_preset

    fixed: dict[str, Any] = {"score_from_s": min(SCORE_FROM_S, 0.7 * duration)}
    for k, v in study.fixed.items():
        if v == "adc_fs":
            v = 2.0 * get_preset(load_scenario(paper.scenario)).motor.i_max
        fixed[k] = v
    return Plan(
        paper.scenario,
        paper.estimators,
        grid={k: list(v) for k, v in study.grid.items()},
        duration=duration,
        fixed=fixed,
    )


def meets(m: dict[str, Any], bound_deg: float) -> bool:
    """Lock kept, no failure, and max |dtheta| within ``bound_deg``."""
    if "error" in m or m.get("lock_lost"):
        return False
    v = m.get("theta_err_abs_max_deg")
    return isinstance(v, int | float) and v <= bound_deg


def region(records: list[dict[str, Any]], est: str, bound_deg: float) -> dict[str, Any]:
    """Where ``est`` meets the bound: counts, and the points that do not (with why)."""
    recs = [r for r in records if r["estimator"] == est]
    bad = []
    for r in recs:
        m = r["metrics"]
        if meets(m, bound_deg):
            continue
        if "error" in m:
            why = "not run: " + short_error(str(m["error"]))
        elif m.get("lock_lost"):
            why = "lost lock"
        else:
            why = f"{m.get('theta_err_abs_max_deg', math.nan):.3g} deg"
        bad.append({"values": r["values"], "why": why})
    locked = sum(
        1 for r in recs if "error" not in r["metrics"] and not r["metrics"].get("lock_lost")
    )
    return {"points": len(recs), "ok": len(recs) - len(bad), "locked": locked, "not_ok": bad}


def short_error(e: str) -> str:
    """The reason of a point that did not run, in a few words."""
    if "without saliency" in e:
        return "the controller's model has no saliency (L_q <= L_d)"
    return e[:100]


def nominal_record(
    records: list[dict[str, Any]], est: str, nominal: dict[str, Any]
) -> dict[str, Any] | None:
    """The record of ``est`` at the scenario's own values (``nominal``), if the study ran it."""
    for r in records:
        if r["estimator"] == est and all(r["values"].get(k) == v for k, v in nominal.items()):
            return r
    return None


def run_robustness(
    out: Path,
    *,
    papers: tuple[str, ...] = tuple(PAPERS),
    studies: tuple[str, ...] = tuple(STUDIES),
    duration: float = DURATION_S,
    executor: str = "local",
    workers: int = 2,
    scheduler: str | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Run every study for every paper (resumable), write ``report.md``, ``summary.json``, plots.

    Stopped by SIGINT/SIGTERM (:func:`bench.studies._executors.catch_signals`),
    as the paper suite and ``bench sweep`` are: no further study starts, the
    summary and the report hold the studies that finished and the finished
    points of the one under way (no plot of it), ``interrupted`` is set and
    ``finished`` counts the points; the points not run are missing from the
    studies' ``points.jsonl`` and run when the command is given again.
    """
    from bench.studies._executors import interrupted

    t0 = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    plots = out / "plots"
    plots.mkdir(exist_ok=True)
    summary: dict[str, Any] = {
        "duration_s": duration,
        "score_from_s": min(SCORE_FROM_S, 0.7 * duration),
        "executor": executor,
        "workers": workers,
        "papers": {},
        "throughput": [],
    }
    planned = sum(
        len(build_tasks(study_plan(PAPERS[p], STUDIES[st], duration)))
        for p in papers
        for st in studies
    )
    stopped = False
    for pname in papers:
        if stopped:
            break
        paper = PAPERS[pname]
        psum: dict[str, Any] = {
            "scenario": paper.scenario,
            "estimators": list(paper.estimators),
            "bound_deg": paper.bound_deg,
            "bound_source": paper.bound_source,
            "studies": {},
        }
        for sname in studies:
            if interrupted():
                stopped = True
                break
            study = STUDIES[sname]
            plan = study_plan(paper, study, duration)
            if progress:
                print(f"robustness: {pname} {sname}", file=sys.stderr)
            res = run_sweep(
                plan,
                out / pname / sname,
                executor=executor,
                workers=workers,
                scheduler=scheduler,
                progress=progress,
                plots=False,
            )
            if "throughput" in res.summary:
                summary["throughput"].append(
                    {"study": f"{pname}/{sname}", **res.summary["throughput"]}
                )
            stopped = bool(res.summary.get("interrupted"))
            keys = list(study.grid)
            figs: list[str] = []
            if stopped:  # seconds of matplotlib: not within the time a signal allows
                pass
            elif len(keys) == 2:
                for est in paper.estimators:
                    name = f"{pname}-{sname}-{est}.png"
                    heatmap(
                        [r for r in res.records if r["estimator"] == est],
                        keys[0],
                        keys[1],
                        plots / name,
                        f"{paper.scenario} {est}: {sname}",
                        bound=paper.bound_deg,
                    )
                    figs.append(f"plots/{name}")
            else:
                name = f"{pname}-{sname}.png"
                line_plot(
                    res.records,
                    keys[0],
                    paper.estimators,
                    plots / name,
                    f"{paper.scenario}: {study.title}",
                    paper.bound_deg,
                )
                figs.append(f"plots/{name}")
            psum["studies"][sname] = {
                "title": study.title,
                "grid": study.grid,
                "fixed": plan.fixed,
                "missing": res.summary["missing"],
                "figures": figs,
                "regions": {e: region(res.records, e, paper.bound_deg) for e in paper.estimators},
                "points": len(res.records),
                "compute_s": sum(float(r["metrics"].get("wall_s") or 0.0) for r in res.records),
                "nominal": {
                    e: (
                        (nominal_record(res.records, e, study.nominal) or {}).get("metrics") or {}
                    ).get("theta_err_abs_max_deg")
                    for e in paper.estimators
                },
            }
            if stopped:
                psum["studies"][sname]["interrupted"] = True
                break
        if psum["studies"] or not stopped:  # a paper the signal came before is not in it
            summary["papers"][pname] = psum
    summary["wall_s"] = time.perf_counter() - t0
    studies_run = [st for p in summary["papers"].values() for st in p["studies"].values()]
    summary["points"] = sum(st["points"] for st in studies_run)
    summary["compute_s"] = sum(st["compute_s"] for st in studies_run)
    if stopped or interrupted():
        summary["interrupted"] = True
        summary["finished"] = {"points": summary["points"], "points_planned": planned}
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=str) + "\n")
    (out / "report.md").write_text(render_report(summary))
    return summary


def _vals(v: dict[str, Any]) -> str:
    return ", ".join(f"{k.split('.')[-1]}={x}" for k, x in v.items())


def render_report(summary: dict[str, Any]) -> str:
    """``report.md`` from ``summary.json``."""
    d, sf = summary["duration_s"], summary["score_from_s"]
    lines = [
        "# Robustness of the papers' estimators",
        "",
    ]
    fin = summary.get("finished")
    if summary.get("interrupted") and fin:
        lines += [
            f"**Interrupted: {fin['points']} of {fin['points_planned']} points finished.** "
            "This report holds the studies that finished and the finished points of the one "
            "under way (no figure of it); the same command again runs the missing points "
            "and rewrites it.",
            "",
        ]
    lines += [
        "Generated by `bench suite robustness` (bench/studies/_robustness.py); every point is "
        "an in-process run (the frames of a run over CAN, between the same node objects).",
        "",
        f"**Cost and limits.** Every point runs {d:g} simulated seconds (start-up at "
        f"standstill with an unknown initial angle, ramp to 100 rpm by 0.8 s), scored from "
        f"{sf:g} s; the grids are coarse (3 to 5 values per key). A point that meets the bound "
        "here could still drift out of it in a longer run; a lost lock is final. One group of "
        "keys changes at a time, the others keep the paper scenario's values.",
        "",
        "A point **meets the bound** when the estimator kept lock, the run did not fail and "
        "max |dtheta| over the scored window is within the paper's bound (the proposed "
        "method's; the paper's other methods are held to it too). In the heatmaps a red x "
        "marks lost lock, an orange ring a point above the bound; the number is max |dtheta| "
        "in degrees.",
        "",
    ]
    for pname, p in summary["papers"].items():
        lines += [
            f"## {pname.capitalize()}: {p['scenario']} ({', '.join(p['estimators'])})",
            "",
            f"Bound: {p['bound_deg']:.3g} deg, from {p['bound_source']}.",
            "",
        ]
        nom: dict[str, Any] = next(
            (
                s["nominal"]
                for s in p["studies"].values()
                if any(v is not None for v in s["nominal"].values())
            ),
            {},
        )
        if nom:
            at = ", ".join(f"{e} {v:.3g} deg" for e, v in nom.items() if v is not None)
            lines += [f"Max |dtheta| at the scenario's own values: {at}."]
            over = [e for e, v in nom.items() if v is not None and v > p["bound_deg"]]
            if over:
                lines.append(
                    f"{', '.join(over)} {'is' if len(over) == 1 else 'are'} above the bound "
                    "already there, so outside it at every point; the middle figure of each "
                    "cell (points in lock) says where they still work."
                )
            lines.append("")
        lines += [
            "| study | " + " | ".join(p["estimators"]) + " |",
            "|---" * (1 + len(p["estimators"])) + "|",
        ]
        for s in p["studies"].values():
            cells = []
            for e in p["estimators"]:
                r = s["regions"][e]
                cells.append(f"{r['ok']} / {r.get('locked', '?')} / {r['points']}")
            lines.append(f"| {s['title']} | " + " | ".join(cells) + " |")
        lines += [
            "",
            "Each cell: points within the bound / points where the method kept lock / points "
            "run. Where each method leaves the bound:",
            "",
        ]
        for s in p["studies"].values():
            lines.append(f"### {s['title']}")
            lines.append("")
            grid = "; ".join(f"`{k}` = {', '.join(map(str, v))}" for k, v in s["grid"].items())
            lines.append(f"Grid: {grid}.")
            if s["missing"]:
                lines.append(f"**{s['missing']} points did not finish** (resume to run them).")
            lines.append("")
            for e in p["estimators"]:
                r = s["regions"][e]
                if not r["not_ok"]:
                    lines.append(f"- {e}: within the bound at every point ({r['points']}).")
                else:
                    bad = "; ".join(f"{_vals(b['values'])} ({b['why']})" for b in r["not_ok"])
                    lines.append(f"- {e}: {r['ok']}/{r['points']} within; outside at {bad}.")
            lines.append("")
            lines += [f"![{f}]({f})" for f in s["figures"]]
            lines.append("")
    total = summary.get("points", 0)
    compute = summary.get("compute_s", 0.0)
    lines += [
        "## Run",
        "",
        f"{total} points; their own run times add up to {compute:.0f} s (each point's "
        "wall time in its worker, on a machine shared with other work).",
    ]
    if summary.get("throughput"):
        tps = summary["throughput"]
        n = sum(t["points"] for t in tps)
        wall = sum(t["wall_s"] for t in tps)
        lines.append(
            f"The last invocation ran {n} of them in {wall:.0f} s ({n / wall:.2f} points/s) on "
            f"{tps[0]['workers']} {tps[0]['executor']} worker(s), {tps[0].get('cpus')} CPUs; "
            "the others were finished already (points.jsonl) and were not run again."
        )
    lines.append("")
    return "\n".join(lines)
