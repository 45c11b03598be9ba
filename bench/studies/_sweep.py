"""Sweeps of the papers' claims: position error versus one parameter at a time.

Wen et al. claim (Table 3, Secs. 3.1 and 4.3) that the position error of the
triangular transform in the estimated d-q axes (``tt-dq``) depends neither on
the speed nor on the system delay, while that of the conventional SFHF
demodulation (``sfhf``) and of the triangular transform in alpha-beta
(``tt-ab``) does.  The sweeps below measure the position error of each
rotating-injection demodulator versus

- the speed (no load, steady state),
- the injected latency on the duty direction and on the sample direction
  (whole PWM periods, lockstep),
- the HF injection amplitude ``V_h`` (estimator option of
  :class:`controller._rotating.RotatingInjectionPars`),
- the white noise on the current measurements (``[noise] current_std_a``),
- on the ``drive`` plant (:mod:`bench.studies._plants`), the inverter's dead
  time (``[inverter] t_dead``, 0 to 3 us) with the drive's countermeasures on
  and off, and the ADC's resolution (``[sensors] adc_bits``, countermeasures
  on): what each hardware effect does to each method,

and fit a straight line to the mean error (``deg per 100 rpm``, ``deg per
period``), so a reader sees whether the bench agrees and where each method
breaks.

Every point is built from the shipped scenario ``wen-5.1`` (start-up with an
unknown initial angle, ramp to the speed, hold) with
:meth:`~bench.scenarios._schema.Scenario.with_overrides`; only the swept quantity
changes, and the same values hold for every method.  The points run
in-process (:func:`run_point`, through :func:`bench.runs._local.run_local`,
the route of ``bench.run``): the same DBC frames between the same node
objects as the two-process run, whose equality with the in-process trace is
tested in ``tests/test_bench_loop.py``.
"""

from __future__ import annotations

import math
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from bench.scenarios._schema import Latency, Noise, Profile, Scenario, load_scenario
from bench.studies._plants import plant_variant

#: The rotating-injection demodulators whose claims the sweeps check.
METHODS = ("sfhf", "tt-ab", "tt-dq")

#: A method's error counts as independent of the swept quantity when the
#: fitted line changes by less than this over the swept range (deg, electrical).
FLAT_DEG = 1.0


@dataclass(frozen=True, slots=True)
class SweepSpec:
    """One sweep: the quantity, its values and how a slope is reported.

    Parameters
    ----------
    name : str
        Key of the sweep (``speed``, ``duty_delay``, ...).
    label : str
        Axis label of the swept quantity, with its unit.
    values, quick_values : tuple of float
        Swept values (full run and ``--quick``).
    slope_per : float
        The slope is reported per this many units (100 for deg per 100 rpm).
    slope_unit : str
        Unit of the reported slope.
    fit : bool
        Whether a straight-line fit is meaningful (a claim is about it).
    """

    name: str
    label: str
    values: tuple[float, ...]
    quick_values: tuple[float, ...]
    slope_per: float
    slope_unit: str
    fit: bool = True


SWEEPS: dict[str, SweepSpec] = {
    s.name: s
    for s in (
        SweepSpec(
            "speed",
            "speed (rpm)",
            (25.0, 50.0, 100.0, 200.0, 300.0, 400.0),
            (50.0, 200.0, 400.0),
            100.0,
            "deg per 100 rpm",
        ),
        SweepSpec(
            "duty_delay",
            "injected delay, duty direction (PWM periods)",
            (0.0, 1.0, 2.0, 3.0, 4.0),
            (0.0, 2.0, 4.0),
            1.0,
            "deg per period",
        ),
        SweepSpec(
            "sample_delay",
            "injected delay, sample direction (PWM periods)",
            (0.0, 1.0, 2.0, 3.0, 4.0),
            (0.0, 2.0, 4.0),
            1.0,
            "deg per period",
        ),
        SweepSpec(
            "v_h",
            "HF injection amplitude V_h (V)",
            (10.0, 20.0, 35.0, 50.0, 75.0, 100.0),
            (20.0, 50.0),
            10.0,
            "deg per 10 V",
            fit=False,
        ),
        SweepSpec(
            "noise",
            "current noise (A rms per phase)",
            (0.0, 0.02, 0.05, 0.1, 0.2, 0.4),
            (0.0, 0.1),
            0.1,
            "deg per 0.1 A",
            fit=False,
        ),
        SweepSpec(
            "dead_time",
            "dead time (us), drive plant, countermeasures on",
            (0.0, 0.5, 1.0, 2.0, 3.0),
            (0.0, 3.0),
            1.0,
            "deg per us",
        ),
        SweepSpec(
            "dead_time_nocomp",
            "dead time (us), drive plant, countermeasures off",
            (0.0, 0.5, 1.0, 2.0, 3.0),
            (0.0, 3.0),
            1.0,
            "deg per us",
        ),
        SweepSpec(
            "adc_bits",
            "ADC resolution (bits), drive plant, countermeasures on",
            (8.0, 10.0, 12.0, 14.0, 16.0),
            (8.0, 12.0),
            1.0,
            "deg per bit",
            fit=False,
        ),
    )
}

#: The sweeps on the ``drive`` plant, and whether the countermeasures are on.
DRIVE_SWEEPS = {"dead_time": True, "dead_time_nocomp": False, "adc_bits": True}

#: Base scenario of every sweep point, and the nominal speed of the
#: non-speed sweeps (rpm).
BASE_SCENARIO = "wen-5.1"
NOMINAL_RPM = 100.0
#: Simulated seconds per point and start of the scored window (s):
#: start-up and ramp end at 0.8 s.
DURATION_S = 3.0
SCORE_FROM_S = 1.5
QUICK_DURATION_S = 1.6
QUICK_SCORE_FROM_S = 1.1


@dataclass(frozen=True, slots=True)
class SlopeFit:
    """Least-squares straight line ``y = slope x + intercept``.

    ``span`` is the change of the fitted line over the fitted ``x`` range
    (same unit as ``y``); ``n`` the number of points used.
    """

    slope: float
    intercept: float
    span: float
    n: int


def fit_slope(x: Sequence[float] | np.ndarray, y: Sequence[float] | np.ndarray) -> SlopeFit:
    """Fit a straight line to the finite points of ``(x, y)``.

    Returns NaN fields when fewer than two distinct ``x`` values are finite.
    """
    xa = np.asarray(x, dtype=float)
    ya = np.asarray(y, dtype=float)
    ok = np.isfinite(xa) & np.isfinite(ya)
    xa, ya = xa[ok], ya[ok]
    if len(np.unique(xa)) < 2:
        return SlopeFit(math.nan, math.nan, math.nan, int(len(xa)))
    slope, intercept = np.polyfit(xa, ya, 1)
    span = float(slope) * float(xa.max() - xa.min())
    return SlopeFit(float(slope), float(intercept), span, int(len(xa)))


def is_flat(fit: SlopeFit, tol_deg: float = FLAT_DEG) -> bool:
    """True when the fitted error changes by less than ``tol_deg`` over the range."""
    return math.isfinite(fit.span) and abs(fit.span) < tol_deg


def sweep_scenario(base: Scenario, kind: str, x: float, *, quick: bool = False) -> Scenario:
    """The scenario of one sweep point: ``base`` with the swept quantity set to ``x``."""
    dur, score = (QUICK_DURATION_S, QUICK_SCORE_FROM_S) if quick else (DURATION_S, SCORE_FROM_S)
    rpm = x if kind == "speed" else NOMINAL_RPM
    scn = base.with_overrides(
        name=f"{base.name}-{kind}-{x:g}",
        duration=dur,
        score_from_s=score,
        speed_rpm=Profile(((0.0, 0.0), (0.3, 0.0), (0.8, rpm))),
        load_nm=Profile(((0.0, 0.0),)),
        thd_window_s=None,
        paper_result={},
    )
    if kind == "duty_delay":
        scn = replace(scn, latency=Latency(duty_delay_steps=int(x)))
    elif kind == "sample_delay":
        scn = replace(scn, latency=Latency(sample_delay_steps=int(x)))
    elif kind == "v_h":
        scn = replace(scn, estimator_options={**scn.estimator_options, "V_h": float(x)})
    elif kind == "noise":
        scn = replace(scn, noise=Noise(current_std_a=float(x)))
    elif kind in DRIVE_SWEEPS:
        scn = plant_variant(scn, "drive" if DRIVE_SWEEPS[kind] else "drive-nocomp")
        if kind == "adc_bits":
            scn = replace(scn, sensors={**scn.sensors, "adc_bits": int(x)})
        else:
            scn = replace(scn, inverter={**scn.inverter, "t_dead": float(x) * 1e-6})
    elif kind != "speed":
        raise ValueError(f"unknown sweep {kind!r} (known: {', '.join(SWEEPS)})")
    return scn


def run_point(scn: Scenario, estimator: str) -> dict[str, Any]:
    """Run one sweep point in-process; the metrics of ``metrics.json``, or the error as text.

    The run is :func:`bench.runs._local.run_local`'s, the route of ``bench
    run``'s in-process runs, the paper suite's and ``bench.run``: its files go
    to a temporary folder, without the plot.  The metrics are those of its
    ``metrics.json`` with the speed overshoot at every point, plus ``wall_s``,
    the seconds the point took (the run and its scoring).
    """
    from bench.runs._local import run_local

    t0 = time.perf_counter()
    try:
        with tempfile.TemporaryDirectory(prefix="bench-point-") as tmp:
            res = run_local(scn, estimator, Path(tmp), plots=False, overshoot=True)
    except Exception as e:  # a diverging or failing point is a result of the sweep
        return {"error": f"{type(e).__name__}: {e}", "wall_s": time.perf_counter() - t0}
    return {**res.metrics, "wall_s": time.perf_counter() - t0}


@dataclass(frozen=True, slots=True)
class SweepJob:
    """One point of one sweep for one method (picklable, for a process pool)."""

    kind: str
    x: float
    estimator: str
    scenario: Scenario

    @property
    def label(self) -> str:
        return f"sweep {self.kind}={self.x:g} {self.estimator}"

    @property
    def cost(self) -> float:
        """Relative cost (simulated steps), for ordering and time-left estimates."""
        from bench.scenarios._setup import n_steps

        return float(n_steps(self.scenario))

    def __call__(self) -> dict[str, Any]:
        return run_point(self.scenario, self.estimator)


def sweep_jobs(
    kinds: Sequence[str] = tuple(SWEEPS),
    *,
    methods: Sequence[str] = METHODS,
    quick: bool = False,
    base: Scenario | None = None,
) -> list[SweepJob]:
    """Every (sweep, value, method) point as a job."""
    base = base or load_scenario(BASE_SCENARIO)
    jobs = []
    for kind in kinds:
        if kind not in SWEEPS:
            raise ValueError(f"unknown sweep {kind!r} (known: {', '.join(SWEEPS)})")
        spec = SWEEPS[kind]
        for x in spec.quick_values if quick else spec.values:
            scn = sweep_scenario(base, kind, x, quick=quick)
            for est in methods:
                jobs.append(SweepJob(kind, x, est, scn))
    return jobs


def collect(
    jobs: Sequence[SweepJob], results: Sequence[dict[str, Any]], *, quick: bool
) -> dict[str, Any]:
    """Arrange point results per sweep and method, with the fitted slopes.

    Returns the ``sweeps`` part of ``summary.json``: per sweep its label,
    values and, per method, the lists of metrics (NaN for a failed point,
    with its error in ``errors``) and the fit of the mean error.
    """
    out: dict[str, Any] = {}
    for job, res in zip(jobs, results, strict=True):
        spec = SWEEPS[job.kind]
        sw = out.setdefault(
            job.kind,
            {
                "label": spec.label,
                "slope_unit": spec.slope_unit,
                "slope_per": spec.slope_per,
                "fit": spec.fit,
                "values": [],
                "methods": {},
                "base_scenario": BASE_SCENARIO,
                "duration_s": job.scenario.duration,
                "score_from_s": job.scenario.score_from_s,
                "quick": quick,
                "in_process": True,
            },
        )
        if job.x not in sw["values"]:
            sw["values"].append(job.x)
        meth = sw["methods"].setdefault(
            job.estimator,
            {
                "x": [],
                "theta_err_mean_deg": [],
                "theta_err_abs_mean_deg": [],
                "theta_err_abs_max_deg": [],
                "theta_err_rms_deg": [],
                "errors": {},
            },
        )
        meth["x"].append(job.x)
        for key in (
            "theta_err_mean_deg",
            "theta_err_abs_mean_deg",
            "theta_err_abs_max_deg",
            "theta_err_rms_deg",
        ):
            meth[key].append(float(res.get(key, math.nan)))
        meth.setdefault("lock_lost", []).append(bool(res.get("lock_lost")))
        if "error" in res:
            meth["errors"][f"{job.x:g}"] = res["error"]
    for sw in out.values():
        for meth in sw["methods"].values():
            f = fit_slope(meth["x"], meth["theta_err_mean_deg"])
            meth["slope"] = f.slope * sw["slope_per"]
            meth["intercept_deg"] = f.intercept
            meth["span_deg"] = f.span
            meth["flat"] = is_flat(f)
            meth["fit_points"] = f.n
    return out


#: A sweep point whose largest |position error| is above this (deg) lost the rotor
#: angle when the summary has no ``lock_lost`` of its own (an older summary).
LOST_ABS_MAX_DEG = 90.0


def lost_points(meth: dict[str, Any]) -> Any:
    """Per point of one method's sweep: whether the estimator lost the rotor angle
    (the run's ``lock_lost``; an older summary: max |dtheta| above :data:`LOST_ABS_MAX_DEG`)."""
    if "lock_lost" in meth and len(meth["lock_lost"]) == len(meth["x"]):
        return np.asarray(meth["lock_lost"], dtype=bool)
    peak = np.asarray(meth["theta_err_abs_max_deg"], dtype=float)
    return np.nan_to_num(peak, nan=0.0) > LOST_ABS_MAX_DEG


def plot_sweeps(sweeps: dict[str, Any], out_dir: Any) -> list[str]:
    """One PNG per sweep: mean error (with fitted line) and max |error| per method."""
    import matplotlib

    matplotlib.use("Agg")
    from pathlib import Path

    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    names = []
    for kind, sw in sweeps.items():
        fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
        lost_any = False
        for est, meth in sw["methods"].items():
            x = np.asarray(meth["x"], dtype=float)
            mean = np.asarray(meth["theta_err_mean_deg"], dtype=float)
            peak = np.asarray(meth["theta_err_abs_max_deg"], dtype=float)
            lost = lost_points(meth)
            lost_any |= bool(lost.any())
            (ln,) = ax[0].plot(x, mean, "o-", ms=4, lw=1, label=est)
            if sw["fit"] and math.isfinite(meth["slope"]):
                xs = np.array([x.min(), x.max()])
                ax[0].plot(
                    xs,
                    meth["intercept_deg"] + meth["slope"] / sw["slope_per"] * xs,
                    ls=":",
                    color=ln.get_color(),
                    lw=1,
                    label=f"{est} fit: {meth['slope']:+.2f} {sw['slope_unit']}",
                )
            ax[1].plot(x, peak, "o-", ms=4, lw=1, label=est, color=ln.get_color())
            for a, y in ((ax[0], mean), (ax[1], peak)):
                if lost.any():
                    a.plot(x[lost], y[lost], "x", ms=10, mew=2, color="tab:red")
        ax[0].set_ylabel(r"mean $\Delta\theta$ (deg)")
        ax[1].set_ylabel(r"max $|\Delta\theta|$ (deg)")
        for a in ax:
            a.set_xlabel(sw["label"])
            a.grid(alpha=0.3)
            if lost_any:  # one legend entry for the lost-lock marks
                a.plot([], [], "x", ms=10, mew=2, color="tab:red",
                       label="lost lock (mean meaningless)")  # fmt: skip
            a.legend(fontsize=7)
        ax[1].set_yscale("log")
        fig.suptitle(f"position error vs {sw['label']} (in-process, {BASE_SCENARIO} base)")
        fig.tight_layout()
        name = f"sweep-{kind}.png"
        fig.savefig(out / name, dpi=80)
        plt.close(fig)
        names.append(name)
    return names
