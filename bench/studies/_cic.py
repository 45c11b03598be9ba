"""Xue's CIC claim as Xue states it (Sec. 4, Figs. 11-12): the position quadrature signal.

Xue's evidence for the CIC interpolation is not the position error: Figs. 11-12
show the position quadrature signal without and with the CIC at 300 rpm, no
load, 500 Hz injection and 1 kHz switching, and their FFTs.  Without the CIC
the signal "has obvious discontinuity, and its harmonic content is richer";
with it "the waveform ... is smoother, the harmonic content is significantly
reduced".  This study records that signal (``e_alpha``, ``e_beta`` of
:class:`controller._square_wave.SquareWaveEstimator`, the envelope after the
hold or the CIC, before the normalisation) in the shipped scenario of that
operating point, :data:`SCENARIO`, for ``square-wave`` and
``square-wave-nocic`` on each plant, and measures on ``e_alpha`` over the
scored window (:func:`spectrum_metrics`, :func:`scipy.signal.periodogram`):

- ``distortion_pct``: the rms of everything but the fundamental (the
  electrical frequency ``f_e``, its Hann main lobe) and DC, in % of the
  fundamental's rms: the harmonic content of Figs. 11b-12b in one number;
- ``image_pct``: the largest line at the injection frequency's image
  ``1/T_h - f_e`` (480 Hz at 20 Hz), in % of the fundamental.  The envelope is
  sampled once per injection period ``T_h = 2 T_s``; a hold of two PWM periods
  passes that image with ``|cos(pi f T_s)|`` (6.3 % at 480 Hz), the hold and the
  CIC with its square (0.39 %): what the study should measure on the ideal plant;
- ``step_ratio``: the largest change between two successive PWM periods, over
  the largest change of a sinusoid of the same amplitude and frequency
  (``A w_e T_s``): the discontinuity of Figs. 11a-12a.  A held signal puts the
  change of two periods into one step and none into the next, so its ratio is
  twice that of the same signal interpolated.

Does the max |dtheta| follow?  The suite's claim ``xue-cic`` compares the
shipped estimators, whose observer poles are each designed for the same phase
margin (:func:`controller._square_wave.observer_pole`): the CIC adds half a PWM
period to the loop, so ``square-wave`` gets a lower pole (50.8 rad/s) than
``square-wave-nocic`` (60.9 rad/s), and the peak error after a load step
scales with ``1 / a^2`` (Xue eq. 12).  :func:`same_pole_runs` runs
``square-wave-nocic`` with the pole of ``square-wave`` in the load-step
scenarios, so the two differ only in the interpolation.  The image the CIC
removes lies far above the observer's crossover (about 26 Hz), where the
loop already attenuates it; so the interpolation itself moves the position
error little, and the shipped difference is the bandwidth each is allowed.
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from bench.scenarios._schema import Scenario, load_scenario
from bench.scenarios._setup import sample_period
from bench.studies._plants import plant_variant

#: The shipped scenario of Xue's Figs. 11-12 operating point (300 rpm, no load, 1 kHz, 500 Hz).
SCENARIO = "xue-fig14"
#: The estimators compared: with the CIC, and with the zero-order hold in its place.
WITH_CIC = "square-wave"
WITHOUT_CIC = "square-wave-nocic"
#: The load-step and speed-step scenarios where the max |dtheta| is compared at one pole.
SAME_POLE_SCENARIOS = ("xue-fig15", "xue-fig16", "xue-fig17", "xue-fig18")
#: Half-width of the fundamental's band (bins): the Hann window's main lobe is 2 bins each
#: side; one more keeps the leakage of a slightly drifting f_e in the fundamental.
FUND_BINS = 3
#: Spectrum points kept for the plot (Welch segments of this many PWM periods: 2 Hz at 1 kHz).
PLOT_SEGMENT = 500
#: Samples of the signal kept for the plot (PWM periods from the start of the scored window).
PLOT_SAMPLES = 40


def spectrum_metrics(x: np.ndarray, T_s: float) -> dict[str, float]:
    """The harmonic content of one component ``x`` of the quadrature signal (module docstring).

    ``x`` is sampled every ``T_s`` (s); the fundamental is the largest line above DC.
    """
    from scipy.signal import periodogram

    x = np.asarray(x, dtype=float)
    # density times the bin width: each line's power summed over its window lobe
    f, p = periodogram(x, fs=1.0 / T_s, window="hann", detrend="constant", scaling="density")
    p = p * (f[1] - f[0])
    k = 1 + int(np.argmax(p[1:]))
    lo, hi = max(1, k - FUND_BINS), k + FUND_BINS + 1
    fund = float(p[lo:hi].sum())
    rest = float(p[1:].sum()) - fund
    f_e = float(np.sum(f[lo:hi] * p[lo:hi]) / fund) if fund > 0 else math.nan
    amp = math.sqrt(2.0 * fund)
    f_img = 1.0 / (2.0 * T_s) - f_e
    j = int(np.argmin(np.abs(f - f_img)))
    img = float(p[max(1, j - FUND_BINS) : j + FUND_BINS + 1].sum())
    step = float(np.max(np.abs(np.diff(x))))
    return {
        "f_e_hz": f_e,
        "amplitude": amp,
        "distortion_pct": 100.0 * math.sqrt(max(rest, 0.0) / fund) if fund > 0 else math.nan,
        "image_hz": f_img,
        "image_pct": 100.0 * math.sqrt(img / fund) if fund > 0 else math.nan,
        "step_ratio": step / (amp * 2.0 * math.pi * f_e * T_s) if amp > 0 else math.nan,
    }


def record_quadrature(scn: Scenario, estimator: str) -> np.ndarray:
    """Run ``scn`` in-process and return ``e_alpha``, ``e_beta`` and the mode of every period."""
    from bench.nodes._loops import run_inprocess
    from bench.wire._codec import Codec

    rows: list[tuple[float, float, float]] = []

    def keep(ctrl: Any) -> None:
        e_a, e_b = ctrl.quadrature()  # the core's (controller.Controller.quadrature)
        rows.append((e_a, e_b, float(ctrl.mode)))

    run_inprocess(scn, estimator, Codec(), observe=keep)
    return np.asarray(rows, dtype=float)


def quadrature_study(scn: Scenario, estimator: str) -> dict[str, Any]:
    """The metrics, plotted spectrum and a stretch of ``e_alpha`` of one estimator in ``scn``."""
    from scipy.signal import welch

    from controller._api import MODE_RUN

    T_s = sample_period(scn)
    rec = record_quadrature(scn, estimator)
    k0 = int(round(scn.score_from_s / T_s))
    win = rec[k0:-1]  # the last period answers the run's stop (the PWM disabled)
    if len(win) < 4 * PLOT_SEGMENT or not np.all(win[:, 2] == MODE_RUN):
        return {"error": "the estimator did not run through the scored window (rotor lost?)"}
    x = win[:, 0]
    if not np.any(x):
        return {"error": "no quadrature signal in the scored window (no envelope: rotor lost)"}
    out: dict[str, Any] = spectrum_metrics(x, T_s)
    f, p = welch(x, fs=1.0 / T_s, window="hann", nperseg=PLOT_SEGMENT, scaling="spectrum")
    fund = float(np.max(p[1:]))
    out["spectrum_hz"] = [round(float(v), 6) for v in f]
    out["spectrum_db"] = [round(10.0 * math.log10(max(float(v) / fund, 1e-16)), 3) for v in p]
    out["signal"] = [round(float(v), 6) for v in x[:PLOT_SAMPLES]]
    out["T_s"] = T_s
    return out


def same_pole_runs(plant: str, scenarios: Sequence[str] = SAME_POLE_SCENARIOS) -> dict[str, Any]:
    """Max |dtheta| (rad) of ``square-wave-nocic`` with the observer pole of ``square-wave``.

    The pole is the one :func:`controller._square_wave.observer_pole` designs for
    ``square-wave`` at the scenario's PWM period (the shipped default options).
    """
    from bench.runs._local import run_local

    out: dict[str, Any] = {}
    for name in scenarios:
        scn = plant_variant(load_scenario(name), plant)
        a = observer_design(sample_period(scn))["a_cic"]
        s2 = replace(scn, estimator_options={**scn.estimator_options, "a": a})
        with tempfile.TemporaryDirectory() as d:
            res = run_local(s2, WITHOUT_CIC, Path(d), plots=False)
        m = res.metrics
        out[name] = {
            "a": a,
            "theta_err_abs_max_rad": m.get("theta_err_abs_max_rad"),
            "lock_lost": m.get("lock_lost"),
        }
    return out


def observer_design(T_s: float) -> dict[str, float]:
    """Both estimators' designed observer poles (rad/s) at the shipped options, and the
    crossover of the loop with CIC (Hz): what the report's explanation quotes."""
    from controller._design import PM_TARGET_DEG
    from controller._square_wave import DELAY_COMP_PERIODS, loop_margins, observer_pole

    a_cic = observer_pole(T_s, True, 2, DELAY_COMP_PERIODS, PM_TARGET_DEG)
    a_zoh = observer_pole(T_s, False, 2, DELAY_COMP_PERIODS, PM_TARGET_DEG)
    _, w_c = loop_margins(a_cic, T_s, True, 2, DELAY_COMP_PERIODS)
    return {
        "a_cic": a_cic,
        "a_zoh": a_zoh,
        "crossover_hz": w_c / (2.0 * math.pi),
        "pm_deg": PM_TARGET_DEG,
    }


@dataclass(frozen=True, slots=True)
class CicJob:
    """The quadrature signal with and without CIC on one plant, and the same-pole runs
    (a suite job: picklable, :func:`bench.studies._suite.run_jobs`)."""

    plant: str = "ideal"

    @property
    def label(self) -> str:
        return f"cic quadrature signal ({self.plant})"

    @property
    def cost(self) -> float:
        from bench.scenarios._setup import n_steps

        steps = 2 * n_steps(load_scenario(SCENARIO))
        steps += sum(n_steps(load_scenario(s)) for s in SAME_POLE_SCENARIOS)
        return float(steps)

    def __call__(self) -> dict[str, Any]:
        try:
            scn = plant_variant(load_scenario(SCENARIO), self.plant)
            return {
                "plant": self.plant,
                "scenario": SCENARIO,
                "design": observer_design(sample_period(scn)),
                "signal": {est: quadrature_study(scn, est) for est in (WITH_CIC, WITHOUT_CIC)},
                "same_pole": same_pole_runs(self.plant),
            }
        except Exception as e:  # one failing job must not end the suite
            return {"plant": self.plant, "error": f"{type(e).__name__}: {e}"}


def plot_cic(cic: dict[str, Any], out_dir: Path) -> str | None:
    """``cic-spectrum.png`` from the summary's ``cic`` entry: per plant, a stretch of the
    quadrature signal and its spectrum, with and without CIC (Xue Figs. 11-12)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plants = [
        p for p, r in cic.items() if "error" not in r and "error" not in r["signal"][WITH_CIC]
    ]
    if not plants:
        return None
    fig, ax = plt.subplots(len(plants), 2, figsize=(10, 3.2 * len(plants)), squeeze=False)
    for row, plant in enumerate(plants):
        sig = cic[plant]["signal"]
        for est, style in ((WITHOUT_CIC, "o-"), (WITH_CIC, "s-")):
            r = sig[est]
            if "error" in r:
                continue
            t = np.arange(len(r["signal"])) * r["T_s"] * 1e3
            ax[row][0].plot(t, r["signal"], style, ms=3, lw=1, drawstyle="steps-post", label=est)
            ax[row][1].plot(r["spectrum_hz"], r["spectrum_db"], lw=1, label=est)
        ax[row][0].set_xlabel("time from the scored window's start (ms)")
        ax[row][0].set_ylabel(r"$E_\alpha$ (A)")
        ax[row][0].set_title(f"{SCENARIO} ({plant}): position quadrature signal")
        ax[row][1].set_xlabel("frequency (Hz)")
        ax[row][1].set_ylabel("dB re the fundamental")
        ax[row][1].set_ylim(-100, 5)
        ax[row][1].set_title("its spectrum (Welch, Hann)")
        for a in ax[row]:
            a.grid(alpha=0.3)
            a.legend(fontsize=8)
    fig.tight_layout()
    out_dir.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_dir / "cic-spectrum.png", dpi=80)
    plt.close(fig)
    return "cic-spectrum.png"
