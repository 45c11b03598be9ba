"""From a CAN capture to the per-step signal table.

Live runs and ``bench analyze`` share this code: a run records the raw frames
first and derives its table, metrics and plots from the capture, so a
capture analysed later gives exactly what the live run wrote.

Tolerated: captures that start mid-run (steps are counted from the first one
seen), gaps, other traffic (IDs not in the DBC are counted and skipped),
frames that fail their CRC or length (counted per reason), frames repeated
for a step (first one wins; identical copies counted apart from duplicates
whose content differs) and out-of-order counters (counted).  A sample, duty
or telemetry for a step ahead of the plant's frames around it in the capture
is not the run's (``future_counter``, counted with the rejected).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import can
import numpy as np
import numpy.typing as npt

from bench.nodes._counters import REJECT_FUTURE_COUNTER
from bench.wire._codec import Codec
from bench.wire._protocol import ANSWER_LEAD, PLANT_LEAD

Array = npt.NDArray[np.float64]


class NoRowsError(ValueError):
    """A capture without a single plant period (samples and truth of one step)."""


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
    ("mode", "controller mode: 0 disabled, 1 align, 2 polarity test, 3 run, 4 fault (DBC)"),
    ("duty_age", "age of the duty applied in the previous period, PWM periods (255: none)"),
    ("fault_active", "faults of the scenario's [[faults]] timeline active in period k, count"),
    ("i_a_true", "true phase-A current (PlantCurrents, DBC 2.4: a run with faults; else nan), A"),
    ("i_b_true", "true phase-B current, A"),
    ("i_c_true", "true phase-C current (-i_a_true - i_b_true: star connection), A"),
)


#: Signals a frame sent again for its step may carry anew, by message: a
#: controller sends its newest ``CtrlTelemetry`` again when its command
#: acknowledgement moves (DBC 2.2, docs/PROTOCOL.md), so a later telemetry of
#: a step that differs only there (and in its CRC) is a copy, not a duplicate.
_UPDATED_AGAIN: dict[str, tuple[str, ...]] = {
    "CtrlTelemetry": ("crc", "cmd_ack", "cmd_ack_valid"),
}


@dataclass(slots=True)
class Capture:
    """Decoded content of a capture."""

    table: dict[str, Array]
    frames: int = 0
    unknown_ids: int = 0
    rejected: dict[str, int] = field(default_factory=dict)
    #: Later frames of a message's step whose content differs from the first one's.
    duplicates: int = 0
    #: Later frames of a message's step identical to the first one: the designed
    #: copies (every command is sent twice), resends and retransmissions, and a
    #: latency link's copy on the other bus.
    copies: int = 0
    out_of_order: int = 0
    incomplete_steps: int = 0
    first_step: int = 0
    #: Recorder frames (``PlantTruth``, ``CtrlTelemetry``) of another run: never scored.
    foreign: dict[str, int] = field(default_factory=dict)
    #: The run's nonce the table was built from (``PlantTruth.run_id``; None: no truth).
    run_id: int | None = None
    #: Rows (plant periods) without the controller's telemetry: the estimate columns NaN.
    steps_without_telemetry: int = 0

    @property
    def frames_foreign(self) -> int:
        return sum(self.foreign.values())

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


#: Messages of the per-step table and the signals taken from each, in table order.
_TABLE_MESSAGES: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("PhaseSamples", ("i_a", "i_b", "u_dc")),
    ("PlantTruth", ("theta_e", "w_m", "tau_e", "tau_L", "duty_age")),
    ("CtrlTelemetry", ("theta_hat", "w_hat", "err", "mode")),
    ("PwmDuty", ("duty_a", "duty_b", "duty_c", "enable")),
    ("BenchCommand", ("speed_ref", "load_torque")),
    ("PlantCurrents", ("i_a", "i_b")),
)


def _unwrap_sequential(raw: list[int], modulus: int) -> list[int]:
    """Full steps of a counter when nothing anchors it: relative to the highest so far."""
    out: list[int] = []
    u = _Unwrapper(modulus)
    for r in raw:
        out.append(u(r)[0])
    return out


def _full_steps(
    name: str,
    raw: npt.NDArray[np.int64],
    index: npt.NDArray[np.int64],
    bits: int,
    anchor: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]] | None,
) -> npt.NDArray[np.int64]:
    """Full step numbers of a message's counter values.

    A counter narrower than the widest one in the capture (``PhaseSamples``
    and ``PwmDuty`` carry 10 bits, ``BenchCommand`` 16, ``PlantTruth`` and
    ``CtrlTelemetry`` 32) is unwrapped to the step nearest that of the latest
    wide-counter frame before it (the first one for frames before any), so
    a capture that starts mid-run or has gaps longer than the narrow counter's
    range still lines up all messages of a step.  Without wide counters the
    narrow ones are unwrapped one after the other from the first value.
    """
    m = 1 << bits
    if anchor is None or len(anchor[0]) == 0:
        if len(raw) < 2 or np.all(np.abs(np.diff(raw)) < m // 2):
            return raw.copy()  # no counter wrap: sequential unwrapping keeps every value
        return np.array(_unwrap_sequential(raw.tolist(), m), dtype=np.int64)
    a_idx, a_step = anchor
    pos = np.searchsorted(a_idx, index, side="right") - 1
    expected = a_step[np.maximum(pos, 0)]
    half = m // 2
    full: npt.NDArray[np.int64] = expected + (raw - expected + half) % m - half
    return full


def _keep_frames(b: Any, keep: Any) -> None:
    """Keep only the frames ``keep`` (a mask) of one message's decoded batch ``b``."""
    b.index = b.index[keep]
    b.signals = {k: v[keep] for k, v in b.signals.items()}


def _own_run(dec: Any, run_id: int | None, cap: Capture) -> None:
    """Drop the recorder frames of other runs from ``dec``, counting them in ``cap``.

    ``PlantTruth.run_id`` is the nonce of the run whose plant sent it; without
    ``run_id`` given, the capture's run is the nonce of most truth frames.
    ``CtrlTelemetry`` with run_id 0 (a controller that reads no truth) is kept.
    """
    truth = dec.messages.get("PlantTruth")
    if truth is None or len(truth.index) == 0 or "run_id" not in truth.signals:
        cap.run_id = run_id
        return
    if run_id is None:
        ids, counts = np.unique(truth.signals["run_id"].astype(np.int64), return_counts=True)
        run_id = int(ids[np.argmax(counts)])
    cap.run_id = run_id
    for name, allow_zero in (
        ("PlantTruth", False),
        ("PlantCurrents", False),
        ("CtrlTelemetry", True),
    ):
        b = dec.messages.get(name)
        if b is None or "run_id" not in b.signals:
            continue
        rid = b.signals["run_id"].astype(np.int64)
        keep = rid == run_id
        if allow_zero:
            keep |= rid == 0
        n_bad = int(len(keep) - np.count_nonzero(keep))
        if n_bad:
            cap.foreign[name] = n_bad
            _keep_frames(b, keep)


def _all_full_steps(dec: Any, bits: dict[str, int]) -> dict[str, npt.NDArray[np.int64]]:
    """Per message of the table, the step each of its valid frames belongs to (a duty's:
    the sample it answers, its tag - 1), unwrapped by :func:`_full_steps`."""
    wide = max(bits.values())
    # anchor of the narrow counters: every valid frame with a wide counter
    a_parts = [
        (dec.messages[n].index, dec.messages[n].signals["step"])
        for n, _ in _TABLE_MESSAGES
        if bits[n] == wide and n in dec.messages
    ]
    anchor = None
    if a_parts:
        a_idx = np.concatenate([p[0] for p in a_parts])
        a_step = np.concatenate([p[1] for p in a_parts]).astype(np.int64)
        o = np.argsort(a_idx, kind="stable")
        anchor = (a_idx[o], a_step[o])
    out: dict[str, npt.NDArray[np.int64]] = {}
    for name, _ in _TABLE_MESSAGES:
        b = dec.messages.get(name)
        if b is None or len(b.index) == 0:
            continue
        raw = b.signals["step"].astype(np.int64)
        full = _full_steps(name, raw, b.index, bits[name], anchor if bits[name] < wide else None)
        if name == "PwmDuty":
            full = full - 1  # the duty tagged k+1 answers sample k
        out[name] = full
    return out


#: The plant's messages, whose steps say how far the plant has come in a capture.
_PLANT_MESSAGES = ("PhaseSamples", "PlantTruth")
#: The controller's answers, never for a step the plant has not reached.
_ANSWER_MESSAGES = ("PwmDuty", "CtrlTelemetry")
#: No plant step yet (before the capture's first plant frame).
_NONE = np.iinfo(np.int64).min


class _PlantSteps:
    """The plant's steps (``PhaseSamples``, ``PlantTruth``) by capture index."""

    def __init__(self, dec: Any, fulls: dict[str, npt.NDArray[np.int64]]) -> None:
        at = np.full(dec.frames + 1, _NONE, dtype=np.int64)
        for m in _PLANT_MESSAGES:
            if m in fulls:
                at[dec.messages[m].index + 1] = fulls[m]  # one message per index
        #: the plant's newest step before each capture index (the lowest int64: none)
        self.newest = np.maximum.accumulate(at)
        self.at = at[1:]

    def any(self) -> bool:
        return bool(self.newest[-1] != _NONE)

    def ahead(self, index: npt.NDArray[np.int64], k: npt.NDArray[np.int64], lead: int) -> Any:
        """Which frames (capture ``index``, step ``k``) are further than ``lead`` ahead of both
        the newest plant step before them and the step of the plant's next frame."""
        before = self.newest[index]
        bad = (before != _NONE) & (k > before + lead)
        if bad.any():  # rare: the plant's next frame after each suspect
            p_idx = np.flatnonzero(self.at != _NONE)
            pos = np.searchsorted(p_idx, index[bad], side="right")
            n = len(p_idx)
            nxt = np.where(pos < n, self.at[p_idx[np.minimum(pos, n - 1)]], _NONE)
            bad[bad] = k[bad] > nxt + lead
        return bad


def _drop(dec: Any, fulls: dict[str, npt.NDArray[np.int64]], name: str, bad: Any) -> int:
    """Remove the frames ``bad`` (a mask) of message ``name`` from ``dec`` and ``fulls``."""
    n_bad = int(np.count_nonzero(bad))
    if n_bad:
        keep = ~bad
        _keep_frames(dec.messages[name], keep)
        fulls[name] = fulls[name][keep]
    return n_bad


def _drop_implausible(dec: Any, fulls: dict[str, npt.NDArray[np.int64]], cap: Capture) -> bool:
    """Drop the frames whose step is ahead of what the plant had sent around them.

    - A duty tagged ``t`` answers sample ``t - 1`` and a telemetry of step ``k`` sample
      ``k``: the plant sent that sample before, so its step is at most the newest
      ``PhaseSamples`` / ``PlantTruth`` step before it in the capture (capture order,
      every channel) plus :data:`bench.wire._protocol.ANSWER_LEAD`.
    - A sample is at most :data:`bench.wire._protocol.PLANT_LEAD` ahead of that newest
      step.  Checked first: a forged sample would otherwise move the newest step for
      the answers after it.

    When the recorder lost the plant's frames before a genuine frame, or the capture
    has neighbours out of order (a real bus sends the frames queued in its mailboxes
    by identifier, a log may merge interfaces), the plant's next frame after it vouches
    for it instead, with the same lead: the plant goes on with the rest of that instant
    and the next, so only a frame ahead of both is taken for another's.  It is
    not the run's (a random frame that passed the E2E CRC with a counter in the unwrap
    window, which would take the place of the genuine frame of its step): counted in
    ``cap.rejected`` as ``future_counter`` and removed from ``dec`` (and ``fulls``), so
    that it takes no part.  Frames before the capture's first plant frame (a capture
    started mid-run) are kept.  True when a frame was dropped.
    """
    if not any(n in fulls for n in _PLANT_MESSAGES):
        return False
    n_bad = 0
    plant = _PlantSteps(dec, fulls)
    if "PhaseSamples" in fulls:
        b = dec.messages["PhaseSamples"]
        bad = plant.ahead(b.index, fulls["PhaseSamples"], PLANT_LEAD)
        n_bad = _drop(dec, fulls, "PhaseSamples", bad)
        if n_bad:
            plant = _PlantSteps(dec, fulls)
    if plant.any():
        for name in _ANSWER_MESSAGES:
            if name in fulls:
                bad = plant.ahead(dec.messages[name].index, fulls[name], ANSWER_LEAD)
                n_bad += _drop(dec, fulls, name, bad)
    if n_bad:
        cap.rejected[REJECT_FUTURE_COUNTER] = cap.rejected.get(REJECT_FUTURE_COUNTER, 0) + n_bad
    return n_bad > 0


def analyze_frames(
    frames: Iterable[can.Message],
    codec: Codec,
    *,
    T_s: float,
    n_p: int,
    run_id: int | None = None,
) -> Capture:
    """Decode frames into the per-step table (one row per plant period).

    The whole capture is decoded at once (:func:`bench.wire._batch_decode.decode_batch`,
    the same values and rejections as :meth:`Codec.decode` frame by frame).
    Per message, in capture order: the first frame of a step wins; a later
    frame of that step counts as a copy when its content is the first one's
    (a command sent twice, a resend, a retransmission, a latency link's
    other bus) and as a duplicate when it differs; and a step below the
    highest seen so far counts as out of order.  The table has one row per
    step that has samples and truth (the plant's period); the controller's
    columns (telemetry, duty) are NaN in a row it sent nothing for
    (``steps_without_telemetry``: a controller that died and left the plant
    in its safe state, a frame lost, a drive that sends no telemetry), so
    the plant's side of every period is in the table.

    Frames that fail their E2E check (every message has one since DBC 2.1,
    the recorder's ``PlantTruth`` and ``CtrlTelemetry`` included) are counted
    in ``rejected`` and take no part, not even in the step unwrapping; so are
    a sample, a duty and a telemetry for a step ahead of the plant's frames
    around them in the capture (``future_counter``, :func:`_drop_implausible`). The
    recorder frames of another run (``run_id`` not the run's, see
    :func:`_own_run`) are counted in ``foreign`` and take no part either.

    Raises
    ------
    NoRowsError
        No step has samples and truth (the message says what the capture holds).
    """
    from bench.wire._batch_decode import decode_batch

    seq = frames if isinstance(frames, Sequence) else list(frames)
    dec = decode_batch(seq, codec)
    cap = Capture(
        table={},
        frames=dec.frames,
        unknown_ids=dec.unknown_ids,
        rejected=dict(dec.rejected),
    )
    _own_run(dec, run_id, cap)
    bits = {name: codec.step_bits(name) for name, _ in _TABLE_MESSAGES}
    fulls = _all_full_steps(dec, bits)
    if _drop_implausible(dec, fulls, cap):
        fulls = _all_full_steps(dec, bits)  # a dropped telemetry may have anchored some
    stores: dict[str, tuple[npt.NDArray[np.int64], Array]] = {}
    for name, sigs in _TABLE_MESSAGES:
        b = dec.messages.get(name)
        if b is None or len(b.index) == 0:
            stores[name] = (np.zeros(0, dtype=np.int64), np.zeros((0, len(sigs))))
            continue
        full = fulls[name]
        steps_u, first, inv = np.unique(full, return_index=True, return_inverse=True)
        later = np.ones(len(full), dtype=bool)
        later[first] = False
        if later.any():
            # a later frame of a step is a copy when every signal equals the first
            # frame's, but for what a frame sent again may update (_UPDATED_AGAIN)
            same = np.ones(int(np.count_nonzero(later)), dtype=bool)
            ref = first[inv[later]]
            for sig, v in b.signals.items():
                if sig in _UPDATED_AGAIN.get(name, ()):
                    continue
                same &= (v[later] == v[ref]) | (np.isnan(v[later]) & np.isnan(v[ref]))
            n_same = int(np.count_nonzero(same))
            cap.copies += n_same
            cap.duplicates += len(same) - n_same
        if len(full) > 1:
            prev_max = np.maximum.accumulate(full)[:-1]
            back = np.zeros(len(full), dtype=bool)
            back[1:] = full[1:] < prev_max
            is_first = np.zeros(len(full), dtype=bool)
            is_first[first] = True
            cap.out_of_order += int(np.count_nonzero(back & is_first))
        vals = np.column_stack([b.signals[s][first] for s in sigs])
        stores[name] = (steps_u, vals)
    s_steps = stores["PhaseSamples"][0]
    t_steps = stores["PlantTruth"][0]
    e_steps = stores["CtrlTelemetry"][0]
    # (each store's steps are sorted and unique)
    # a row per plant period (samples and truth); the controller's telemetry where it came
    steps = np.intersect1d(s_steps, t_steps, assume_unique=True)
    if len(steps) == 0:
        held = ", ".join(f"{name} {len(stores[name][0])}" for name, _ in _TABLE_MESSAGES)
        raise NoRowsError(
            "no step has samples and truth together "
            f"(valid steps per message: {held}; {cap.unknown_ids} frames with other IDs, "
            f"{cap.frames_rejected} rejected)"
        )
    every = np.sort(np.concatenate([s_steps, t_steps, e_steps]))
    n_union = int(np.count_nonzero(np.diff(every))) + 1
    cap.incomplete_steps = n_union - len(steps)
    cap.steps_without_telemetry = int(len(steps) - np.count_nonzero(np.isin(steps, e_steps)))
    cap.first_step = int(steps[0])
    n = len(steps)
    cols = {name: np.full(n, math.nan) for name, _ in COLUMNS}
    cols["step"] = steps.astype(float)
    cols["t"] = steps * T_s

    def take(store: tuple[npt.NDArray[np.int64], Array], j: int) -> Array:
        st, va = store
        pos = np.searchsorted(st, steps)
        pos_c = np.minimum(pos, max(len(st) - 1, 0))
        hit = (pos < len(st)) & (st[pos_c] == steps) if len(st) else np.zeros(n, dtype=bool)
        col = np.full(n, math.nan)
        col[hit] = va[pos_c[hit], j]
        return col

    cols["i_a"], cols["i_b"], cols["u_dc"] = (take(stores["PhaseSamples"], j) for j in range(3))
    cols["i_c"] = -cols["i_a"] - cols["i_b"]
    cols["i_a_true"], cols["i_b_true"] = (take(stores["PlantCurrents"], j) for j in range(2))
    cols["i_c_true"] = -cols["i_a_true"] - cols["i_b_true"]
    cols["theta_e"], cols["w_m_rpm"], cols["tau_e"], cols["tau_L"], cols["duty_age"] = (
        take(stores["PlantTruth"], j) for j in range(5)
    )
    cols["theta_hat"], cols["w_hat_rpm"], cols["est_err"], cols["mode"] = (
        take(stores["CtrlTelemetry"], j) for j in range(4)
    )
    # wire units: w_m mechanical rad/s, w_hat electrical rad/s
    rpm = 60.0 / (2.0 * math.pi)
    cols["w_m_rpm"] = cols["w_m_rpm"] * rpm
    cols["w_hat_rpm"] = cols["w_hat_rpm"] * (rpm / n_p)
    cols["d_a"], cols["d_b"], cols["d_c"], cols["enable"] = (
        take(stores["PwmDuty"], j) for j in range(4)
    )
    # references in force: forward fill of the commands by apply step
    c_steps, c_vals = stores["BenchCommand"]
    if len(c_steps):
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


def signals_doc(codec: Codec | None = None) -> str:
    """``signals.md``: every column of ``signals.csv`` with its unit, and the mode codes.

    From :data:`COLUMNS` and the DBC's value tables (``CtrlTelemetry.mode``), so
    the description cannot differ from what the table holds.
    """
    from bench.wire._codec import default_codec

    codec = codec or default_codec()
    modes: dict[Any, Any] = codec.message("CtrlTelemetry").get_signal_by_name("mode").choices or {}
    lines = [
        "# signals.csv",
        "",
        "One row per PWM period k (the plant's sample instant t = k T_s), in the "
        "columns below; angles are electrical, speeds mechanical. Written by "
        "`bench run` and `bench analyze` from the capture; `bench plot RUN_DIR "
        "--signals a,b` draws any of them.",
        "",
        "| column | meaning, unit |",
        "|---|---|",
        *(f"| `{name}` | {what} |" for name, what in COLUMNS),
        "",
        "`mode` (the controller's, `CtrlTelemetry.mode` in `dbc/bench.dbc`):",
        "",
        "| code | mode |",
        "|---|---|",
        *(f"| {int(k)} | {v} |" for k, v in sorted(modes.items())),
        "",
        "One row per plant period (samples and truth). A row with `mode` 0 (controller "
        "disabled) is not scored. The controller's columns (`theta_hat`, `theta_err_deg`, "
        "`w_hat_rpm`, `est_err`, `mode`, duties) are NaN (`nan`) in a period it sent "
        "nothing for (a controller that died, a lost frame, an external controller "
        "without telemetry): the plant's columns go on, the position error there is unknown.",
        "",
    ]
    return "\n".join(lines)


def read_csv(path: str) -> dict[str, Array]:
    """Read a table written by :func:`write_csv`."""
    arr = np.genfromtxt(path, delimiter=",", names=True)
    return {n: np.asarray(arr[n], dtype=float) for n in arr.dtype.names or ()}


def measure_latency(frames: Sequence[can.Message], codec: Codec) -> dict[str, dict[str, float]]:
    """Wall-clock latency across a link, per direction, from a two-bus capture.

    ``frames`` must carry ``channel`` 1 (plant side, bus A) and 2 (controller
    side, bus B), as :class:`bench.runs._recorder.Recorder` tags them, and receive
    timestamps from one clock.  For each sample frame, the time from its
    appearance on A to its appearance on B; for each duty frame, from B to A
    (microseconds, median and 99th percentile).

    In whole PWM periods, counted on the plant's own clock (the highest
    sample step seen on A so far): a sample ``j`` that appears on B while A
    has carried up to sample ``s`` was held ``s - j`` periods; a duty ``t``
    (the answer to sample ``t - 1``) that appears on A while A has carried
    up to ``s`` closed a loop of ``s - (t - 1)`` periods.  A frame is never
    released before the sample on A that triggers it, but the recorder may
    see the plant's next sample first (two sockets, one clock), which can
    only add a period; so the delay is the least count over all frames
    (``samples.steps``, and ``duties.steps`` = least loop minus
    ``samples.steps``).  No median is given: it would count the recorder's
    ordering (often one period more), not the link.  The plant's own
    ``duty_age`` (scored as ``loop_latency_steps``) is the exact round trip.
    """
    sid, did = codec.frame_id("PhaseSamples"), codec.frame_id("PwmDuty")
    m = 1 << codec.step_bits("PhaseSamples")
    first_seen: dict[tuple[int, int, int], float] = {}
    unw: dict[tuple[int, int], _Unwrapper] = {}
    a_max = -1  # the highest sample step carried on A so far
    held_s: list[int] = []  # per sample on B: periods it was held
    loop_d: list[int] = []  # per duty on A: periods since its sample left A
    for f in sorted(frames, key=lambda f: f.timestamp):
        if f.arbitration_id not in (sid, did) or f.channel not in (1, 2):
            continue
        d = codec.decode(f)
        if d is None or d.reason is not None:
            continue
        key = (int(f.channel), f.arbitration_id)
        k, _ = unw.setdefault(key, _Unwrapper(m))(int(d.signals["step"]))
        new = (*key, k) not in first_seen
        first_seen.setdefault((*key, k), f.timestamp)
        if key == (1, sid):
            a_max = max(a_max, k)
        elif new and a_max >= 0 and key == (2, sid):
            held_s.append(a_max - k)
        elif new and a_max >= 0 and key == (1, did):
            loop_d.append(a_max - (k - 1))
    out: dict[str, dict[str, float]] = {}
    for name, fid, src, dst in (("samples", sid, 1, 2), ("duties", did, 2, 1)):
        us = [
            1e6 * (t - first_seen[(src, fid, k)])
            for (ch, f_id, k), t in first_seen.items()
            if ch == dst and f_id == fid and (src, fid, k) in first_seen
        ]
        if us:
            arr = np.array(us)
            out[name] = {
                "us_median": float(np.median(arr)),
                "us_p99": float(np.percentile(arr, 99)),
                "frames": float(len(arr)),
            }
    if held_s and "samples" in out:
        n_s = min(held_s)
        out["samples"]["steps"] = float(n_s)
        if loop_d and "duties" in out:
            out["duties"]["steps"] = float(min(loop_d) - n_s)
    return out
