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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import can

from bench import _jsonio as jsonio
from bench._errors import CaptureError, ScenarioError
from bench.runs._results import (
    RunResult,
    finish_run,
    frames_warning,
    plant_record,
    scoring_scenario,
)
from bench.scenarios._schema import Scenario, load_scenario, scenario_from_dict
from bench.wire._canimport import load_mf4
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


def _open_reader(path: Path) -> Iterable[can.Message]:
    """python-can's reader of a binary capture (text ones: :func:`_read_text_lines`)."""
    if path.suffix.lower() == ".mf4":
        load_mf4()  # python-can's MF4 support, left out of the command line's start-up
    return can.LogReader(str(path))


class _CountedLines(io.StringIO):
    """A text capture's lines for a python-can reader, counting the lines it has taken."""

    def __init__(self, lines: list[str]) -> None:
        super().__init__("".join(lines))
        self.taken = 0

    # (iterating a subclass of StringIO goes through readline)
    def readline(self, size: int | None = -1) -> str:  # type: ignore[override]
        line = super().readline(-1 if size is None else size)
        if line:
            self.taken += 1
        return line


#: Unparsable lines of a text capture named in the warning (the rest are counted).
SKIPPED_SHOWN = 3


def _read_text_lines(
    path: Path, cut_at: int | None
) -> tuple[list[can.Message], list[tuple[int, str]], str | None]:
    """Every frame of a text capture, skipping the lines python-can's reader cannot parse.

    python-can's text readers stop at the first line they fail on, which
    would drop the rest of the file.  The reader is restarted after the bad
    line with the file's header (the lines before its first frame: the ASC
    ``date``/``base``/trigger lines that set the time base, the CSV header
    row), so one bad line costs one line.  Returns the frames, the skipped
    lines (1-based line number, the reader's error) and why reading stopped
    early (None: it read to the end): after :data:`MAX_SKIPPED` bad lines,
    or :data:`MAX_SKIPPED` in a row before any frame (not a capture of this
    format), the rest is not tried line by line.
    """
    data = path.read_bytes()
    if cut_at is not None:
        data = data[:cut_at]
    lines = data.decode("utf-8", errors="replace").splitlines(keepends=True)
    reader_cls = _TEXT_READERS[path.suffix.lower()]
    frames: list[can.Message] = []
    skipped: list[tuple[int, str]] = []
    header: list[str] | None = None
    start = 0  # index in ``lines`` of the first line after the header the reader gets
    while True:
        prefix = header or []
        feed = _CountedLines([*prefix, *lines[start:]])
        reader = reader_cls(feed)
        try:
            for msg in reader:
                if header is None:
                    # the lines before the one that gave the first frame
                    header = lines[: max(0, feed.taken - 1)]
                frames.append(msg)
            return frames, skipped, None
        except Exception as e:
            bad = start + feed.taken - len(prefix) - 1  # index of the line it failed on
            if bad < start:
                raise  # failed in the header: nothing to skip
            if header is None:
                header = lines[:bad]
            skipped.append((bad + 1, f"{type(e).__name__}: {e}"))
            start = bad + 1
            if len(skipped) >= MAX_SKIPPED:
                return (
                    frames,
                    skipped,
                    (f"reading stopped at line {bad + 1} after {len(skipped)} unparsable lines"),
                )
        finally:
            try:
                reader.stop()
            except Exception:
                pass


#: Unparsable lines of a text capture tried one by one before the rest is given up.
MAX_SKIPPED = 1000


@dataclass(frozen=True, slots=True)
class CaptureRead:
    """What :func:`read_capture_counted` read from a capture.

    Parameters
    ----------
    frames : list of can.Message
        Every frame read, in file order.
    problem : str or None
        Why the capture is incomplete (cut short, a corrupt record); None when whole.
    lines_skipped : list of (int, str)
        Lines of a text capture that python-can could not parse, skipped:
        (1-based line number, the reader's error).
    """

    frames: list[can.Message]
    problem: str | None
    lines_skipped: list[tuple[int, str]]


def skipped_warning(path: Path, skipped: list[tuple[int, str]]) -> str:
    """The one-line warning about the unparsable lines of a text capture."""
    shown = "; ".join(f"line {n}: {why}" for n, why in skipped[:SKIPPED_SHOWN])
    more = f"; and {len(skipped) - SKIPPED_SHOWN} more" if len(skipped) > SKIPPED_SHOWN else ""
    return (
        f"warning: {path}: {len(skipped)} unparsable line{'s' * (len(skipped) != 1)} "
        f"skipped, the rest read ({shown}{more})"
    )


def read_capture(path: Path) -> tuple[list[can.Message], str | None]:
    """All frames python-can can read from ``path``, and why the capture is incomplete (or None).

    Unparsable lines of a text capture are skipped (:func:`read_capture_counted`
    says which).
    """
    got = read_capture_counted(path)
    return got.frames, got.problem


def read_capture_counted(path: Path) -> CaptureRead:
    """All frames python-can can read from ``path``, why it is incomplete, the lines skipped.

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
    if suffix in _TEXT_READERS:
        try:
            text_frames, skipped, stopped = _read_text_lines(path, cut_at)
        except Exception as e:
            raise CaptureError(
                f"{path}: not a {suffix} capture python-can can read ({type(e).__name__}: {e})"
            ) from None
        if not text_frames:
            first = f" (line {skipped[0][0]}: {skipped[0][1]})" if skipped else ""
            raise CaptureError(f"{path}: no frames could be read{first}")
        if stopped:
            problems.insert(0, stopped)
        return CaptureRead(text_frames, "; ".join(problems) or None, skipped)
    try:
        reader = _open_reader(path)
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
    return CaptureRead(frames, problem, [])


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
        f"{cap.duplicates} duplicates (a second, different frame for a step), "
        f"{cap.copies} identical copies (each command is sent twice; resends; "
        "a latency link's second bus), "
        f"{cap.out_of_order} out of order, "
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
    got = read_capture_counted(path)
    frames, problem = got.frames, got.problem
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
    if got.lines_skipped:
        say(skipped_warning(capture, got.lines_skipped))
    if span is not None:
        T_s = sample_period(scn)
        scn, moved = scoring_scenario(scn, span[0] * T_s, span[1] * T_s)
        if moved:
            say(moved)
    out = out_dir or capture.parent
    out.mkdir(parents=True, exist_ok=True)
    # the plant of the scenario analysed with (a capture made elsewhere has no meta.json)
    meta = dict(meta, **plant_record(scn), analyzed_from=str(capture), scenario=scn.to_dict())
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
    if warn := frames_warning(res.metrics):
        say(warn)
    if got.lines_skipped:
        res.metrics["capture_lines_skipped"] = len(got.lines_skipped)
    if problem:
        res.metrics["capture_truncated"] = True
        res.metrics["capture_read_error"] = problem
    if problem or got.lines_skipped:
        (out / "metrics.json").write_text(
            jsonio.dumps(res.metrics, indent=2, sort_keys=True) + "\n"
        )
    return res


# -- replay ----------------------------------------------------------------------------
