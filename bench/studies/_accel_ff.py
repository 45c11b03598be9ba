"""Wen Tables 6-8's maxima with tt-dq's acceleration feed-forward (``accel_ff``).

tt-dq misses its own maxima in Tables 6-8 within about 0.1 s of a speed step
or in a full-load ramp: its PLL, designed for 45 degrees of margin with the
BPF and LPF of eqs. (11)-(13) in its loop (``w_o`` = 58.5 rad/s), lags an
acceleration ``a`` by about ``a / w_o^2``.  The option ``accel_ff``
(:class:`controller._rotating.RotatingInjectionPars`) feeds the acceleration
the speed loop is designed to give from the speed reference into the PLL,
beside its loop, so the margin and the noise gain stay the design's.  This
study runs the three scenarios with it on the ideal and the drive plant
(in-process, the same route as the suite's runs); the report says where the
maxima are met and, where not, what the largest error follows: a load change
the drive does not know, which only a faster PLL, that is less margin, would
follow more closely.

Measured (in-process, ``tt-dq`` with ``accel_ff = true``; max |dtheta| in deg,
without the option in brackets; the suite's claims ``wen-5.x-max-accel-ff``
hold the same numbers):

- wen-5.2 (Table 6, <= 8): ideal 2.83 (9.18), drive 6.32 (9.30): met; the
  speed steps were the PLL's lag, and the reference explains them;
- wen-5.3 (Table 7, <= 5): ideal 7.97 (7.88), drive 8.31 (7.98): missed, at
  1.0 s, 0.1 s after the full-load ramp (0.6 to 0.9 s) that the drive does
  not know; the speed reversals no longer set the maximum;
- wen-5.4 (Table 8, <= 6): ideal 3.47 (3.50) met, drive 7.62 (7.89) missed,
  in the load ramp (3 to 4 s).

Why the load-change maxima are out of reach with eqs. (11)-(13) at the
design's margin: only a faster PLL follows an unknown load change more
closely, and its filters in the loop make every gain of bandwidth cost
margin and noise gain (``RotatingHFEstimator.phase_margin`` and the peak of
``|L / (1 + L)|``, tests/test_accel_ff.py). With ``accel_ff`` and ``w_o``
given (``[estimator_options] w_o``; the speed loop is designed anew for
each):

======== ============ ========== ================ ===================
 w_o      margin       noise      wen-5.3 ideal    wen-5.4 drive
 (rad/s)  (deg)        gain       (<= 5 deg)       (<= 6 deg, 20 rpm)
======== ============ ========== ================ ===================
 58.5     45.0         1.35       7.97             7.62, 19.7 rpm
 75       37.9         1.55       4.13             6.04, 23.0 rpm
 90       32.1         1.81       2.27             4.96, 20.1 rpm
======== ============ ========== ================ ===================

So Table 7's maximum needs about 38 degrees of margin and Table 8's on the
drive plant about 32, where its speed error (20.1 rpm) still misses the
paper's 20: not with the design's 45 degrees and noise gain 1.35.  Command
of a row: ``bench run wen-5.3 --estimator tt-dq`` with a scenario copy whose
``[estimator_options]`` sets ``accel_ff = true`` and ``w_o``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from bench.scenarios._schema import load_scenario
from bench.studies._plants import plant_variant

#: The scenarios of Tables 6-8.
SCENARIOS = ("wen-5.2", "wen-5.3", "wen-5.4")
#: The plants it runs on (the drive plant with its countermeasures).
PLANTS = ("ideal", "drive")
ESTIMATOR = "tt-dq"
OPTIONS = {"accel_ff": True}
#: Metrics kept in the summary.
KEEP = (
    "theta_err_abs_max_deg",
    "theta_err_max_deg",
    "theta_err_min_deg",
    "theta_err_abs_mean_deg",
    "speed_err_max_rpm",
    "lock_lost",
)


@dataclass(frozen=True, slots=True)
class AccelFfJob:
    """One scenario of Tables 6-8 with ``tt-dq`` and ``accel_ff`` on one plant (a suite job)."""

    scenario: str
    plant: str
    run_dir: Path

    @property
    def label(self) -> str:
        return f"{self.scenario}/{ESTIMATOR} accel_ff ({self.plant})"

    @property
    def cost(self) -> float:
        from bench.scenarios._setup import n_steps

        # the option runs the controller in Python: about twice a compiled run's steps
        # (the time-left estimate only)
        return 2.0 * n_steps(load_scenario(self.scenario))

    def __call__(self) -> dict[str, Any]:
        from bench.runs._local import run_local
        from bench.studies._extras import where_max

        try:
            scn = plant_variant(load_scenario(self.scenario), self.plant)
            scn = replace(scn, estimator_options={**scn.estimator_options, **OPTIONS})
            res = run_local(scn, ESTIMATOR, self.run_dir, plots=False)
        except Exception as e:  # one failing job must not end the suite
            return {"error": f"{type(e).__name__}: {e}"}
        from bench.runs._analysis import read_csv

        out: dict[str, Any] = {k: res.metrics.get(k) for k in KEEP}
        sig = self.run_dir / "signals.csv"
        if sig.exists():
            out["where_max"] = where_max(read_csv(str(sig)), scn)
        out["gains"] = {
            k: v
            for k, v in (res.meta.get("controller_gains") or {}).items()
            if k in ("estimator.w_o", "estimator.pm_deg", "alpha_s")
        }
        return out


def accel_ff_jobs(runs_dir: Path, plants: tuple[str, ...]) -> list[AccelFfJob]:
    """One job per scenario of Tables 6-8 and plant of :data:`PLANTS` the suite runs."""
    return [
        AccelFfJob(s, p, runs_dir / "accel-ff" / p / s)
        for p in plants
        if p in PLANTS
        for s in SCENARIOS
    ]
