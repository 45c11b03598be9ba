"""Reading captures: any python-can log, analysed as a live run would be.

``bench analyze LOG`` reads the capture with python-can's own readers
(``.blf``, ``.asc``, ``.log``, ``.trc``, ``.csv``, ``.mf4`` with its optional
dependency), decodes it with the DBC and writes the same ``signals.csv``,
``metrics.json`` and plots a live run writes (:func:`bench.runs._results.finish_run`).
The scenario (for the PWM period, the scoring window and the paper's numbers)
comes from the ``meta.json`` beside the capture, or from ``--scenario`` for a
capture made elsewhere.  A capture cut short is read up to where it ends,
and said so.
"""

from __future__ import annotations

import io
import json
import sys
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import can

from bench import _jsonio as jsonio
from bench._errors import CaptureError, ScenarioError
from bench.runs._results import RunResult, finish_run
from bench.scenarios._schema import Scenario, load_scenario, scenario_from_dict
from bench.wire._codec import Codec

#: Suffixes python-can reads (``.mf4`` needs ``asammdf``), in the order a folder is searched.
CAPTURE_SUFFIXES = (".blf", ".asc", ".log", ".trc", ".csv", ".mf4")


def _find_in_folder(path: Path) -> Path:
    """The capture of a run folder: the one its ``meta.json`` names, else the first ``capture.*``.

    A folder reused by runs in different formats may hold an older
    ``capture.*`` beside the latest run's; ``meta.json`` (rewritten by every
    run) names the latest one in ``capture``.
    """
    try:
        named = json.loads((path / "meta.json").read_text()).get("capture")
    except (OSError, ValueError, AttributeError):
        named = None
    if isinstance(named, str) and named:
        cand = path / Path(named).name
        if cand.is_file():
            return cand
    for suffix in CAPTURE_SUFFIXES:
        cand = path / f"capture{suffix}"
        if cand.is_file():
            return cand
    raise CaptureError(f"{path}: a folder without capture.* ({', '.join(CAPTURE_SUFFIXES)})")


#: Text formats python-can reads line by line (a cut last line is dropped, not parsed).
_TEXT_READERS: dict[str, type[can.io.generic.TextIOMessageReader]] = {
    ".asc": can.ASCReader,
    ".log": can.CanutilsLogReader,
    ".trc": can.TRCReader,
    ".csv": can.CSVReader,
}


def _blf_header(path: Path) -> tuple[int, int]:
    """File size and object count a BLF header declares (both 0 for an unfinished file).

    Raises
    ------
    CaptureError
        The file is too short for a BLF header or lacks its ``LOGG`` signature.
    """
    from can.io.blf import FILE_HEADER_STRUCT

    with path.open("rb") as f:
        data = f.read(FILE_HEADER_STRUCT.size)
    if len(data) < FILE_HEADER_STRUCT.size:
        raise CaptureError(
            f"{path}: not a readable BLF capture ({len(data)} bytes, "
            f"shorter than the {FILE_HEADER_STRUCT.size}-byte BLF file header)"
        )
    header = FILE_HEADER_STRUCT.unpack(data)
    if header[0] != b"LOGG":
        raise CaptureError(f"{path}: not a readable BLF capture (no 'LOGG' signature at its start)")
    return int(header[10]), int(header[12])


def _blf_problem(path: Path, declared: tuple[int, int], n_read: int) -> str | None:
    """Why a BLF looks incomplete: its size or object count against its header."""
    from can.io.blf import FILE_HEADER_SIZE

    size_decl, count = declared
    size = path.stat().st_size
    if count == 0 and size_decl <= FILE_HEADER_SIZE and size > FILE_HEADER_SIZE:
        return (
            "the BLF header was never completed (its writer did not close the file), "
            "so the capture may end early"
        )
    if size < size_decl:
        return (
            f"truncated BLF: {size} of the {size_decl} bytes its header declares "
            f"({n_read} of its {count} frames read)"
        )
    if n_read < count:
        return (
            f"{n_read} of the {count} objects the BLF header counts were read "
            "(a damaged file, or object types python-can does not read)"
        )
    return None


def _text_tail(path: Path) -> tuple[int | None, bool]:
    """Where the last complete line of a text capture ends (None: the file ends with
    one), and whether an ASC file's ``End TriggerBlock`` footer is missing."""
    size = path.stat().st_size
    with path.open("rb") as f:
        f.seek(max(0, size - 4096))
        tail = f.read()
    no_footer = path.suffix.lower() == ".asc" and b"end triggerblock" not in tail.lower()
    if not tail or tail.endswith((b"\n", b"\r")):
        return None, no_footer
    nl = max(tail.rfind(b"\n"), tail.rfind(b"\r"))
    if nl < 0 and size > len(tail):  # a last line longer than 4 kB: find its start
        data = path.read_bytes()
        nl = max(data.rfind(b"\n"), data.rfind(b"\r"))
        return nl + 1, no_footer
    return size - len(tail) + nl + 1, no_footer


def _open_reader(path: Path, cut_at: int | None) -> Iterable[can.Message]:
    """python-can's reader of ``path``; only its first ``cut_at`` bytes when given."""
    if cut_at is None:
        return can.LogReader(str(path))
    data = path.read_bytes()[:cut_at]
    text = io.TextIOWrapper(io.BytesIO(data), encoding="utf-8", errors="replace")
    return _TEXT_READERS[path.suffix.lower()](text)


def read_capture(path: Path) -> tuple[list[can.Message], str | None]:
    """All frames python-can can read from ``path``, and why the capture is incomplete (or None).

    ``path`` may also be a run folder (its ``capture.*`` is read).  A reader
    that stops on a corrupt object keeps what it read; python-can's readers
    stop silently at a truncated end, so the capture is also checked against
    what its format promises: a BLF's size and object count against its
    header, a text capture's last line (a line cut short is dropped, never
    parsed into a frame with missing bytes) and an ASC's ``End TriggerBlock``.

    Raises
    ------
    CaptureError
        Missing file, a format python-can does not read (or a file that is
        not what its suffix says), a missing optional reader, or no frame.
    """
    if path.is_dir():
        path = _find_in_folder(path)
    if not path.is_file():
        raise CaptureError(f"{path}: no such capture file")
    suffix = path.suffix.lower()
    problems: list[str] = []
    blf = _blf_header(path) if suffix == ".blf" else None
    cut_at: int | None = None
    if suffix in _TEXT_READERS:
        cut_at, no_footer = _text_tail(path)
        if cut_at is not None:
            problems.append("its last line is cut short (no line end); that line was dropped")
        if no_footer:
            problems.append("no 'End TriggerBlock' line at its end (the file was cut short)")
    try:
        reader = _open_reader(path, cut_at)
    except ValueError as e:
        raise CaptureError(f"{path}: not a capture python-can can read ({e})") from None
    except ImportError as e:
        raise CaptureError(
            f"{path}: reading {path.suffix} needs an optional package ({e.name or e}); "
            "for .mf4: pip install asammdf"
        ) from None
    except Exception as e:  # a reader that fails on the header
        raise CaptureError(f"{path}: unreadable capture: {type(e).__name__}: {e}") from None
    frames: list[can.Message] = []
    read_error: str | None = None
    try:
        for msg in reader:
            frames.append(msg)
    except Exception as e:  # truncated or corrupt tail: keep what was read
        read_error = f"{type(e).__name__}: {e}"
        problems.insert(0, f"reading stopped at a corrupt record ({read_error})")
    finally:
        try:
            reader.stop()  # type: ignore[attr-defined]
        except Exception:
            pass
    if blf is not None:
        why = _blf_problem(path, blf, len(frames))
        if why:
            problems.append(why)
    if not frames:
        kind = "not a readable BLF capture: " if blf is not None else ""
        raise CaptureError(
            f"{path}: {kind}no frames could be read" + (f" ({read_error})" if read_error else "")
        )
    problem = "; ".join(problems) if problems else None
    return frames, problem


def scenario_from_meta(meta: dict[str, Any]) -> Scenario:
    d = dict(meta["scenario"])
    return scenario_from_dict(d, str(d.get("source", "meta.json")))


def capture_scenario(path: Path, scenario: str | None) -> tuple[Scenario, dict[str, Any]]:
    """The scenario of a capture and the run metadata beside it (empty when none).

    ``scenario`` (a name or TOML path) wins over the ``meta.json`` beside the
    capture; without either, the PWM rate and the motor are unknown.
    """
    folder = path if path.is_dir() else path.parent
    meta_path = folder / "meta.json"
    meta: dict[str, Any] = {}
    if meta_path.is_file():
        try:
            meta = json.loads(meta_path.read_text())
        except (OSError, ValueError) as e:
            raise CaptureError(f"{meta_path}: unreadable run metadata ({e})") from None
    if scenario is not None:
        return load_scenario(scenario), meta
    if meta:
        if not isinstance(meta.get("scenario"), dict):
            raise CaptureError(
                f"{meta_path}: no scenario in this metadata; "
                "give --scenario NAME_OR_FILE for the capture's PWM rate and motor"
            )
        try:
            return scenario_from_meta(meta), meta
        except (KeyError, TypeError) as e:
            raise CaptureError(f"{meta_path}: no usable scenario in the metadata ({e})") from None
    raise ScenarioError(
        f"{path}: no meta.json beside the capture; give --scenario NAME_OR_FILE for its PWM rate and motor"
    )


def _summarize(
    frames: Sequence[can.Message], codec: Codec, problem: str | None
) -> tuple[str, tuple[int, int] | None]:
    """One line on the capture's counters, and its first and last step (None: no step)."""
    from bench.runs._analysis import analyze_frames

    try:
        cap = analyze_frames(frames, codec, T_s=1.0, n_p=1)
    except ValueError:
        return f"capture: {len(frames)} frames, no complete step", None
    rej = ", ".join(f"{k} {v}" for k, v in sorted(cap.rejected.items()))
    s = (
        f"capture: {cap.frames} frames, {cap.unknown_ids} with IDs not in the DBC, "
        f"{cap.frames_rejected} rejected{f' ({rej})' if rej else ''}, "
        f"{cap.duplicates} duplicates, {cap.out_of_order} out of order, "
        f"{cap.incomplete_steps} incomplete steps, first step {cap.first_step}"
    )
    if problem:
        s += "; incomplete capture (see the warning)"
    steps = cap.table["step"]
    span = (int(steps[0]), int(steps[-1])) if len(steps) else None
    return s, span


def capture_summary(frames: Sequence[can.Message], codec: Codec, problem: str | None) -> str:
    """One line on what a capture holds besides the run: other IDs, rejections, order."""
    return _summarize(frames, codec, problem)[0]


def incomplete_warning(path: Path, problem: str, n_frames: int) -> str:
    """The one-line warning about an incomplete capture (what was kept)."""
    return f"warning: {path}: incomplete capture: {problem}; using the {n_frames} frames read"


def scoring_scenario(scn: Scenario, t_first: float, t_end: float) -> tuple[Scenario, str | None]:
    """The scenario to score a capture spanning ``t_first`` .. ``t_end`` (s) with, and what changed.

    A live run shorter than its scenario's scoring start is scored over its
    second half (:meth:`Scenario.with_overrides` with its ``duration``).  A
    capture whose span ends at or before ``score_from_s`` is scored the same
    way, from the middle of its span, with the scenario's duration set to the
    span's end, so that a capture of a shortened run scores as the live run
    did and the ``meta.json`` written with it scores the same again.
    """
    if scn.score_from_s < t_end:
        return scn, None
    t_end = round(t_end, 9)
    start = round(t_first + (t_end - t_first) / 2, 9)
    out = scn.with_overrides(duration=max(t_end, 1e-3), score_from_s=start)
    return out, (
        f"capture ends at {t_end:g} s, not after the scenario's scoring start "
        f"({scn.score_from_s:g} s): scoring its second half, from {start:g} s "
        "(as a run of that duration is scored)"
    )


def analyze_capture(
    path: Path,
    *,
    out_dir: Path | None = None,
    scenario: str | None = None,
    codec: Codec | None = None,
    echo: Callable[[str], None] | None = None,
    plots: bool = True,
    duration: float | None = None,
    dut_name: str | None = None,
) -> RunResult:
    """Decode a capture into the files of a run.

    Parameters
    ----------
    path : Path
        Capture file (any python-can format) or run folder.
    out_dir : Path, optional
        Where to write; default beside the capture.
    scenario : str, optional
        Scenario name or file; default from ``meta.json`` beside the capture.
    echo : callable, optional
        Receives the one-line summary of the capture's counters and any
        warning line (default: stderr).
    plots : bool
        Draw ``run.png``.
    duration : float, optional
        The run's length (s) when it was shorter than its scenario's (a
        controller under test stopped early): the periods after it are not
        counted as missing.
    dut_name : str, optional
        The capture is of a controller under test of this name (for the
        labels); default from ``meta.json``.

    The ``meta.json`` written carries the scenario used (as a live run's
    does), so a later ``bench analyze`` or ``bench rerun`` of the same folder
    needs no ``--scenario``.  An incomplete capture (see
    :func:`read_capture`) is analysed as far as it was read, with a warning
    and ``capture_truncated``/``capture_read_error`` in ``metrics.json``.
    """
    from bench.scenarios._setup import sample_period

    codec = codec or Codec()
    frames, problem = read_capture(path)
    capture = path if path.is_file() else _find_in_folder(path)
    scn, meta = capture_scenario(path, scenario)
    if duration is not None:
        scn = scn.with_overrides(duration=duration)
    if dut_name is not None:
        meta = dict(meta, controller="external", controller_name=dut_name, estimator="external")
    say = echo or (lambda s: print(s, file=sys.stderr))
    line, span = _summarize(frames, codec, problem)
    say(line)
    if problem:
        say(incomplete_warning(capture, problem, len(frames)))
    if span is not None:
        T_s = sample_period(scn)
        scn, moved = scoring_scenario(scn, span[0] * T_s, span[1] * T_s)
        if moved:
            say(moved)
    out = out_dir or capture.parent
    out.mkdir(parents=True, exist_ok=True)
    meta = dict(meta, analyzed_from=str(capture), scenario=scn.to_dict())
    meta.pop("capture_read_error", None)
    if problem:
        meta["capture_read_error"] = problem
    wall_s = float(meta.get("wall_s", 0.0))
    try:
        res = finish_run(
            frames, codec, scn, out, meta=meta, wall_s=wall_s, capture=capture, plots=plots
        )
    except ValueError as e:
        raise CaptureError(f"{capture}: {e}") from None
    if problem:
        res.metrics["capture_truncated"] = True
        res.metrics["capture_read_error"] = problem
        (out / "metrics.json").write_text(
            jsonio.dumps(res.metrics, indent=2, sort_keys=True) + "\n"
        )
    return res


# -- replay ----------------------------------------------------------------------------
