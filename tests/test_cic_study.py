"""Xue's CIC claim as stated (Figs. 11-12): the quadrature signal's metrics, its recording
in a closed-loop run, the claim's verdict and the plot written from the summary."""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bench.studies._cic import (
    SCENARIO,
    WITH_CIC,
    WITHOUT_CIC,
    observer_design,
    quadrature_study,
    spectrum_metrics,
)
from bench.studies._report import NOT_REPRODUCED, NOT_RUN, REPRODUCED, evaluate_claims
from tests.oracle.blocks import OracleCicInterpolator

T_S = 1e-3  # Xue: 1 kHz PWM, 500 Hz injection
F_E = 20.0  # 300 rpm, 4 pole pairs
IMAGE_HZ = 1.0 / (2.0 * T_S) - F_E
HOLD_IMAGE = abs(math.cos(math.pi * IMAGE_HZ * T_S))  # a two-period hold's gain at the image


def _envelope(n: int, cic: bool) -> np.ndarray:
    """A 20 Hz sinusoid sampled every second period, held or held and CIC-interpolated."""
    ip = OracleCicInterpolator(2, 2)
    ip.prime(1.0)  # the first sample, as the estimator primes it: no start-up step
    out, held = [], 0.0
    for k in range(n):
        fresh = k % 2 == 0
        if fresh:
            held = math.cos(2.0 * math.pi * F_E * k * T_S)
        out.append(ip.step(held if fresh else None) if cic else held)
    return np.asarray(out)


def test_metrics_of_a_held_and_an_interpolated_sinusoid_are_the_closed_forms() -> None:
    zoh = spectrum_metrics(_envelope(4000, cic=False), T_S)
    cic = spectrum_metrics(_envelope(4000, cic=True), T_S)
    for m in (zoh, cic):
        assert m["f_e_hz"] == pytest.approx(F_E, abs=0.01)
        assert m["image_hz"] == pytest.approx(IMAGE_HZ, abs=0.01)
        assert m["amplitude"] == pytest.approx(1.0, abs=0.01)
    assert zoh["image_pct"] == pytest.approx(100 * HOLD_IMAGE, rel=0.02)
    assert cic["image_pct"] == pytest.approx(100 * HOLD_IMAGE**2, rel=0.02)
    # nothing but the image: the distortion is the image
    assert zoh["distortion_pct"] == pytest.approx(zoh["image_pct"], rel=0.02)
    # the held signal moves twice as far in one step as the interpolated one
    assert zoh["step_ratio"] == pytest.approx(2.0 * cic["step_ratio"], rel=0.02)
    assert cic["step_ratio"] == pytest.approx(1.0, abs=0.02)


@pytest.fixture(scope="module")
def recorded() -> dict[str, dict[str, Any]]:
    from bench.scenarios._schema import load_scenario

    scn = load_scenario(SCENARIO)
    return {est: quadrature_study(scn, est) for est in (WITH_CIC, WITHOUT_CIC)}


def test_the_runs_quadrature_signal_has_the_holds_image_and_the_cic_removes_it(
    recorded: dict[str, dict[str, Any]],
) -> None:
    a, b = recorded[WITH_CIC], recorded[WITHOUT_CIC]
    for r in (a, b):
        assert r["f_e_hz"] == pytest.approx(F_E, abs=0.05)  # 300 rpm held by the loop
        assert r["amplitude"] > 1.0  # the envelope of eq. (6), amperes
    # on the ideal plant the envelope is a clean sinusoid: the hold's image is the closed form
    assert b["image_pct"] == pytest.approx(100 * HOLD_IMAGE, rel=0.05)
    assert a["image_pct"] == pytest.approx(100 * HOLD_IMAGE**2, rel=0.05)
    assert a["distortion_pct"] < b["distortion_pct"] / 10
    assert a["step_ratio"] < 0.6 * b["step_ratio"]
    assert len(a["spectrum_hz"]) == len(a["spectrum_db"]) > 100


def test_observing_the_controller_changes_no_frame() -> None:
    """The recording hook reads the core's quadrature signal between periods (what the
    study records, ``Controller.quadrature``): the frames are the same, and it moves."""
    from bench.nodes._loops import run_inprocess
    from bench.scenarios._schema import load_scenario
    from bench.wire._codec import Codec

    scn = load_scenario(SCENARIO).with_overrides(duration=0.6)
    seen: list[float] = []
    plain = run_inprocess(scn, WITH_CIC, Codec())
    watched = run_inprocess(
        scn, WITH_CIC, Codec(), observe=lambda c: seen.append(c.quadrature()[0])
    )
    assert [(m.arbitration_id, bytes(m.data)) for m in plain] == [
        (m.arbitration_id, bytes(m.data)) for m in watched
    ]
    assert len(seen) >= 590 and any(seen)


def _summary(recorded: dict[str, dict[str, Any]]) -> dict[str, Any]:
    return {
        "suite": {
            "transport": "in-process",
            "mode": "lockstep",
            "workers": 1,
            "wall_s": 1.0,
            "quick": False,
            "runs_dir": "runs",
        },
        "runs": [],
        "sweeps": {},
        "cic": {
            "ideal": {
                "plant": "ideal",
                "scenario": SCENARIO,
                "design": observer_design(T_S),
                "signal": copy.deepcopy(recorded),
                "same_pole": {},
            }
        },
    }


def _verdict(s: dict[str, Any]) -> str:
    return {c["id"]: c["verdict"] for c in evaluate_claims(s)}["xue-cic-signal"]


def test_the_claim_follows_the_measurements(recorded: dict[str, dict[str, Any]]) -> None:
    s = _summary(recorded)
    assert _verdict(s) == REPRODUCED
    s["cic"]["ideal"]["signal"][WITH_CIC]["distortion_pct"] = 7.0  # CIC no smoother
    assert _verdict(s) == NOT_REPRODUCED
    s = _summary(recorded)
    s["cic"]["ideal"]["signal"][WITHOUT_CIC] = {"error": "no quadrature signal"}
    assert _verdict(s) == NOT_RUN


def test_the_plot_and_section_are_written_from_the_summary(
    tmp_path: Path, recorded: dict[str, dict[str, Any]]
) -> None:
    from bench.studies._report import write_report

    s = _summary(recorded)
    s["claims"] = evaluate_claims(s)
    write_report(s, tmp_path)
    md = (tmp_path / "report.md").read_text()
    assert "![cic](cic-spectrum.png)" in md
    png = tmp_path / "cic-spectrum.png"
    assert png.stat().st_size > 10_000
    d = s["cic"]["ideal"]["signal"]
    assert f"| ideal | {WITH_CIC} | 20.00 | {d[WITH_CIC]['distortion_pct']:.2f} |" in md
