"""From a CAN capture to the per-step signal table.

Live runs and ``bench analyze`` share this code: a run records the raw frames
first and derives its table, metrics and plots from the capture, so a
capture analysed later gives exactly what the live run wrote.

Tolerated: captures that start mid-run (steps are counted from the first one
seen), gaps, other traffic (IDs not in the DBC are counted and skipped),
frames that fail their CRC or length (counted per reason), duplicated frames
(first copy wins) and out-of-order counters (counted).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field

import can
import numpy as np
import numpy.typing as npt

from bench._codec import Codec

Array = npt.NDArray[np.float64]

#: Columns of the per-step table, in CSV order, with units.
COLUMNS: tuple[tuple[str, str], ...] = (
    ("step", "PWM period index k (sample instant t = k T_s)"),
    ("t", "s"),
    ("theta_e", "true electrical angle, rad"),
    ("theta_hat", "estimated electrical angle, rad"),
    ("theta_err_deg", "wrap(theta_e - theta_hat), electrical degrees"),
    ("w_m_rpm", "true mechanical speed, rpm"),
    ("w_hat_rpm", "estimated mechanical speed, rpm"),
    ("w_ref_rpm", "speed reference in force, rpm"),
    ("load_ref_nm", "load torque commanded, N m"),
    ("tau_e", "electromagnetic torque, N m"),
    ("tau_L", "load torque, N m"),
    ("i_a", "phase-A current sample, A"),
    ("i_b", "phase-B current sample, A"),
    ("i_c", "phase-C current (-i_a - i_b), A"),
    ("i_d", "d current in the true rotor frame, A"),
    ("i_q", "q current in the true rotor frame, A"),
    ("u_dc", "DC-link voltage sample, V"),
    ("d_a", "duty computed from this sample (applies from period k+1), 0..1"),
    ("d_b", "duty, 0..1"),
    ("d_c", "duty, 0..1"),
    ("enable", "PWM enabled by the controller, 0/1"),
    ("est_err", "estimator error signal, rad"),
    ("mode", "controller mode"),
)


@dataclass(slots=True)
class Capture:
    """Decoded content of a capture."""

    table: dict[str, Array]
    frames: int = 0
    unknown_ids: int = 0
    rejected: dict[str, int] = field(default_factory=dict)
    duplicates: int = 0
    out_of_order: int = 0
    incomplete_steps: int = 0
    first_step: int = 0

    @property
    def frames_rejected(self) -> int:
        return sum(self.rejected.values())


class _Unwrapper:
    def __init__(self, modulus: int) -> None:
        self.m = modulus
        self.last: int | None = None
        self.base = 0

    def __call__(self, raw: int) -> tuple[int, bool]:
        """Full step for ``raw``, and whether it went backwards."""
        if self.last is None:
            self.last = raw
            return raw, False
        half = self.m // 2
        d = (raw - self.last + half) % self.m - half
        full = self.last + d
        back = d < 0
        if not back:
            self.last = full
        return full, back


def analyze_frames(
    frames: Iterable[can.Message],
    codec: Codec,
    *,
    T_s: float,
    n_p: int,
) -> Capture:
    """Decode frames into the per-step table (steps with samples, truth and telemetry)."""
    samples: dict[int, tuple[float, float, float]] = {}
    truth: dict[int, tuple[float, float, float, float]] = {}
    tele: dict[int, tuple[float, float, float, float]] = {}
    duty: dict[int, tuple[float, float, float, float]] = {}
    cmds: dict[int, tuple[float, float]] = {}
    unwrappers: dict[str, _Unwrapper] = {}
    for name, _sig in (
        ("PhaseSamples", "step"),
        ("PlantTruth", "step"),
        ("CtrlTelemetry", "step"),
        ("PwmDuty", "step"),
        ("BenchCommand", "step"),
    ):
        unwrappers[name] = _Unwrapper(1 << codec.step_bits(name))
    cap = Capture(table={})
    for msg in frames:
        cap.frames += 1
        if msg.is_error_frame or msg.is_remote_frame:
            continue
        d = codec.decode(msg)
        if d is None:
            cap.unknown_ids += 1
            continue
        if d.reason is not None:
            cap.rejected[d.reason] = cap.rejected.get(d.reason, 0) + 1
            continue
        s = d.signals
        if d.name == "PhaseSamples":
            k, back = unwrappers[d.name](int(s["step"]))
            store: dict = samples
            val: tuple = (float(s["i_a"]), float(s["i_b"]), float(s["u_dc"]))
        elif d.name == "PlantTruth":
            k, back = unwrappers[d.name](int(s["step"]))
            store = truth
            val = (float(s["theta_e"]), float(s["w_m"]), float(s["tau_e"]), float(s["tau_L"]))
        elif d.name == "CtrlTelemetry":
            k, back = unwrappers[d.name](int(s["step"]))
            store = tele
            val = (float(s["theta_hat"]), float(s["w_hat"]), float(s["err"]), float(s["mode"]))
        elif d.name == "PwmDuty":
            k, back = unwrappers[d.name](int(s["step"]))
            k -= 1  # the duty tagged k+1 answers sample k
            store = duty
            val = (float(s["duty_a"]), float(s["duty_b"]), float(s["duty_c"]), float(s["enable"]))
        elif d.name == "BenchCommand":
            k, back = unwrappers[d.name](int(s["step"]))
            store = cmds
            val = (float(s["speed_ref"]), float(s["load_torque"]))
        else:
            continue
        if k in store:
            cap.duplicates += 1
            continue
        if back:
            cap.out_of_order += 1
        store[k] = val
    steps_all = sorted(set(samples) & set(truth) & set(tele))
    if not steps_all:
        raise ValueError("no step has samples, truth and telemetry together")
    cap.incomplete_steps = len(set(samples) | set(truth) | set(tele)) - len(steps_all)
    k0 = steps_all[0]
    cap.first_step = k0
    steps = np.array(steps_all, dtype=np.int64)
    n = len(steps)
    cols = {name: np.full(n, math.nan) for name, _ in COLUMNS}
    cols["step"] = steps.astype(float)
    cols["t"] = steps * T_s
    cols["i_a"], cols["i_b"], cols["u_dc"] = (
        np.array([samples[k][j] for k in steps_all]) for j in range(3)
    )
    cols["i_c"] = -cols["i_a"] - cols["i_b"]
    cols["theta_e"], cols["w_m_rpm"], cols["tau_e"], cols["tau_L"] = (
        np.array([truth[k][j] for k in steps_all]) for j in range(4)
    )
    cols["theta_hat"], cols["w_hat_rpm"], cols["est_err"], cols["mode"] = (
        np.array([tele[k][j] for k in steps_all]) for j in range(4)
    )
    # wire units: w_m mechanical rad/s, w_hat electrical rad/s
    rpm = 60.0 / (2.0 * math.pi)
    cols["w_m_rpm"] = cols["w_m_rpm"] * rpm
    cols["w_hat_rpm"] = cols["w_hat_rpm"] * (rpm / n_p)
    nan4 = (math.nan,) * 4
    cols["d_a"], cols["d_b"], cols["d_c"], cols["enable"] = (
        np.array([duty.get(k, nan4)[j] for k in steps_all]) for j in range(4)
    )
    # references in force: forward fill of the commands by apply step
    if cmds:
        c_steps = np.array(sorted(cmds), dtype=np.int64)
        c_vals = np.array([cmds[k] for k in c_steps.tolist()])
        idx = np.searchsorted(c_steps, steps, side="right") - 1
        ok = idx >= 0
        for j, name in enumerate(("w_ref_rpm", "load_ref_nm")):
            col = np.full(n, math.nan)
            col[ok] = c_vals[idx[ok], j]
            cols[name] = col
    th = cols["theta_e"]
    err = (th - cols["theta_hat"] + np.pi) % (2 * np.pi) - np.pi
    cols["theta_err_deg"] = np.degrees(err)
    # Park transform of the sampled currents with the true angle (amplitude-invariant)
    i_al = cols["i_a"]
    i_be = (cols["i_a"] + 2.0 * cols["i_b"]) / math.sqrt(3.0)
    c, s_ = np.cos(th), np.sin(th)
    cols["i_d"] = c * i_al + s_ * i_be
    cols["i_q"] = -s_ * i_al + c * i_be
    cap.table = cols
    return cap


def write_csv(path: str, table: dict[str, Array]) -> None:
    """Write the per-step table as CSV with a header row (readable by numpy alone)."""
    names = [n for n, _ in COLUMNS]
    data = np.column_stack([table[n] for n in names])
    fmt = ["%d", "%.6f"] + ["%.9g"] * (len(names) - 2)
    np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt=fmt)


def read_csv(path: str) -> dict[str, Array]:
    """Read a table written by :func:`write_csv`."""
    arr = np.genfromtxt(path, delimiter=",", names=True)
    return {n: np.asarray(arr[n], dtype=float) for n in arr.dtype.names or ()}


def measure_latency(frames: list[can.Message], codec: Codec) -> dict[str, dict[str, float]]:
    """Latency seen across a link, per direction, from a two-bus capture.

    ``frames`` must carry ``channel`` 1 (plant side, bus A) and 2 (controller
    side, bus B), as :class:`bench._run.Recorder` tags them, and receive
    timestamps from one clock.  For each sample frame ``j`` first seen on B,
    the delay in periods is the number of plant samples A had carried by
    then minus ``j + 1``; for each duty frame, the number of plant samples A
    carried between the duty's appearance on B and on A.  Microseconds are
    the timestamp differences of the same frame on both sides.
    """
    sid, did = codec.frame_id("PhaseSamples"), codec.frame_id("PwmDuty")
    m = 1 << codec.step_bits("PhaseSamples")
    ordered = sorted(frames, key=lambda f: f.timestamp)
    seen_a: dict[tuple[int, int], float] = {}
    seen_b: dict[tuple[int, int], float] = {}
    a_count = 0
    a_count_at: dict[tuple[str, int, int], int] = {}
    unw = {1: _Unwrapper(m), 2: _Unwrapper(m), 3: _Unwrapper(m), 4: _Unwrapper(m)}
    for f in ordered:
        if f.arbitration_id not in (sid, did) or f.channel not in (1, 2):
            continue
        d = codec.decode(f)
        if d is None or d.reason is not None:
            continue
        ch = int(f.channel)
        kind = 0 if f.arbitration_id == sid else 2
        k, _ = unw[ch + kind](int(d.signals["step"]))
        key = (f.arbitration_id, k)
        store = seen_a if ch == 1 else seen_b
        if key in store:
            continue
        store[key] = f.timestamp
        if ch == 1 and f.arbitration_id == sid:
            a_count = max(a_count, k + 1)
        a_count_at[("A" if ch == 1 else "B", f.arbitration_id, k)] = a_count
    out: dict[str, dict[str, float]] = {}
    for name, fid, first, second in (
        ("samples", sid, "A", "B"),
        ("duties", did, "B", "A"),
    ):
        steps, us = [], []
        for (f_id, k), t_b in (seen_b if second == "B" else seen_a).items():
            if f_id != fid:
                continue
            src = seen_a if first == "A" else seen_b
            if (f_id, k) not in src:
                continue
            if name == "samples":
                steps.append(a_count_at[(second, f_id, k)] - (k + 1))
            else:
                steps.append(a_count_at[(second, f_id, k)] - a_count_at[(first, f_id, k)])
            us.append(1e6 * (t_b - src[(f_id, k)]))
        if steps:
            arr, us_arr = np.array(steps, dtype=float), np.array(us)
            out[name] = {
                "steps_median": float(np.median(arr)),
                "steps_min": float(arr.min()),
                "steps_max": float(arr.max()),
                "us_median": float(np.median(us_arr)),
                "us_p99": float(np.percentile(us_arr, 99)),
                "frames": float(len(arr)),
            }
    return out
