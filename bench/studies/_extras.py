"""What the suite's report adds to a run's metrics, and the suite's JSON files.

:func:`run_extras` reads a run's signal table for the report (where the
largest error happened and what preceded it, the THD including the injection
current); :func:`refresh_extras` recomputes it when a report is rendered again
from its runs.  Both the suite (:mod:`bench.studies._suite`) and the report
(:mod:`bench.studies._report`) use them, so they live below both.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from bench.scenarios._schema import Scenario

#: Upper frequency of the THD that includes the HF injection current (Hz).
THD_HF_LIMIT_HZ = 1500.0


def run_extras(signals: Path, scn: Scenario) -> dict[str, Any]:
    """What the report adds to a run's metrics from its signal table.

    ``where_max``: see :func:`where_max`.  ``thd_phase_a_hf_pct``: the THD of
    phase-A current over the scenario's THD window with every harmonic up to
    :data:`THD_HF_LIMIT_HZ` (the metric ``thd_phase_a_pct`` stops at the
    40th, below the HF injection at 500 Hz), so the report can show how much
    of a THD the injection current makes.
    """
    import numpy as np

    from bench.runs._analysis import read_csv
    from bench.runs._metrics import thd_pct
    from bench.scenarios._setup import get_preset, sample_period

    out: dict[str, Any] = {}
    if not signals.exists():
        return out
    tab = read_csv(str(signals))
    where = where_max(tab, scn)
    if where:
        out["where_max"] = where
    if scn.thd_window_s is not None:
        t = tab["t"]
        win = (t >= scn.thd_window_s[0]) & (t < scn.thd_window_s[1])
        if np.count_nonzero(win) > 10:
            n_p = get_preset(scn).motor.n_p
            f1 = abs(float(np.mean(tab["w_m_rpm"][win]))) / 60.0 * n_p
            if f1 > 0:
                n_h = max(2, int(THD_HF_LIMIT_HZ / f1))
                out["thd_phase_a_hf_pct"] = thd_pct(
                    tab["i_a"][win], sample_period(scn), f1, n_harmonics=n_h
                )
    return out


def _same_run(metrics_path: Path, recorded: dict[str, Any]) -> bool:
    """Whether the run folder's ``metrics.json`` is the run a summary recorded: every
    number the summary kept of it is the folder's."""
    try:
        have = json.loads(metrics_path.read_text())
    except (OSError, ValueError):
        return False
    return bool(recorded) and all(have.get(k) == v for k, v in recorded.items())


def refresh_extras(summary: dict[str, Any]) -> None:
    """Recompute :func:`run_extras` of every run whose folder is still in ``runs_dir``
    and still holds that run (its metrics are the summary's)."""
    runs_dir = Path(summary.get("suite", {}).get("runs_dir", ""))
    for rec in summary.get("runs", []):
        if "error" in rec:
            continue
        sub = str(rec.get("files", "")).removeprefix("runs/") or (
            f"{rec['scenario']}/{rec['estimator']}"
        )
        sig = runs_dir / sub / "signals.csv"
        meta = sig.parent / "meta.json"
        if not (sig.exists() and meta.exists()):
            continue
        if not _same_run(sig.parent / "metrics.json", rec.get("metrics") or {}):
            continue  # another run in that folder (a later suite, or an older one)
        from bench.scenarios._schema import parse_scenario

        d = json.loads(meta.read_text())["scenario"]
        keep = {k: v for k, v in d.items() if k != "source" and v is not None}
        scn = parse_scenario(keep, d.get("source", rec["scenario"]))
        rec.update(run_extras(sig, scn))


def where_max(tab: dict[str, Any], scn: Scenario) -> dict[str, Any] | None:
    """When the largest |dtheta| of the scored window happens, and what happened just before.

    The context names the nearest change of the speed reference or of the
    load in the 0.5 s before, or says the run was steady there, so a report
    can say what limits a number.
    """
    import numpy as np

    t = tab["t"]
    sel = np.flatnonzero((t >= scn.score_from_s) & (tab["mode"] != 0))
    if len(sel) == 0:
        return None
    i = int(sel[np.argmax(np.abs(tab["theta_err_deg"][sel]))])
    ti = float(t[i])
    events = []
    for name, prof in (("speed reference", scn.speed_rpm), ("load", scn.load_nm)):
        for (t0, v0), (t1, v1) in zip(prof.points, prof.points[1:], strict=False):
            if v0 != v1 and t0 - 0.05 <= ti <= t1 + 0.5:
                if ti < t1:
                    what = f"during the {name} ramp to {v1:g} ({t0:g} to {t1:g} s)"
                else:
                    what = f"{ti - t1:.2f} s after the {name} change to {v1:g} at {t1:g} s"
                events.append((abs(ti - t1), what))
    if events:
        context = min(events)[1]
    else:
        context = f"steady, {float(tab['w_m_rpm'][i]):.0f} rpm, {float(tab['tau_L'][i]):.1f} N m"
    return {"t_s": ti, "theta_err_deg": float(tab["theta_err_deg"][i]), "context": context}


def path_name(estimator: str) -> str:
    """A folder name for ``estimator`` (a plug-in's ``package.module:factory`` has a colon)."""
    return estimator.replace(":", "-")


def write_json(path: Path, data: Any) -> None:
    path.write_text(json.dumps(data, indent=2, sort_keys=True, default=_json_default) + "\n")


def _json_default(o: Any) -> Any:
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
