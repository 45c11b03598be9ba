"""Captures: read any python-can log, analyse it as a live run would.

``bench analyze LOG`` reads the capture with python-can's own readers
(``.blf``, ``.asc``, ``.log``, ``.trc``, ``.csv``, ``.mf4`` with its optional
dependency), decodes it with the DBC and writes the same ``signals.csv``,
``metrics.json`` and plots a live run writes.  The scenario (for the PWM
period, the scoring window and the paper's numbers) comes from the
``meta.json`` beside the capture, or from ``--scenario`` for a capture made
elsewhere.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import can

from bench._codec import Codec
from bench._errors import CaptureError, ScenarioError
from bench._run import RunResult, finish_run
from bench._scenario import Scenario, load_scenario, parse_scenario


def read_capture(path: Path) -> tuple[list[can.Message], str | None]:
    """All frames python-can can read from ``path``, and why reading stopped early (or None)."""
    if not path.is_file():
        raise CaptureError(f"{path}: no such capture file")
    try:
        reader = can.LogReader(str(path))
    except ValueError as e:
        raise CaptureError(f"{path}: not a capture python-can can read ({e})") from None
    except Exception as e:  # a reader that fails on the header
        raise CaptureError(f"{path}: unreadable capture: {type(e).__name__}: {e}") from None
    frames: list[can.Message] = []
    problem: str | None = None
    try:
        for msg in reader:
            frames.append(msg)
    except Exception as e:  # truncated or corrupt tail: keep what was read
        problem = f"{type(e).__name__}: {e}"
    finally:
        try:
            reader.stop()
        except Exception:
            pass
    if not frames:
        raise CaptureError(
            f"{path}: no frames could be read" + (f" ({problem})" if problem else "")
        )
    return frames, problem


def scenario_from_meta(meta: dict[str, Any]) -> Scenario:
    d = dict(meta["scenario"])
    src = d.pop("source", "meta.json")
    d = {k: v for k, v in d.items() if v is not None}
    return parse_scenario(d, src)


def analyze_capture(
    path: Path,
    *,
    out_dir: Path | None = None,
    scenario: str | None = None,
    codec: Codec | None = None,
) -> RunResult:
    """Decode a capture into the files of a run."""
    codec = codec or Codec()
    frames, problem = read_capture(path)
    meta_path = path.parent / "meta.json"
    meta: dict[str, Any] = {}
    if meta_path.is_file():
        try:
            meta = json.loads(meta_path.read_text())
        except (OSError, ValueError) as e:
            raise CaptureError(f"{meta_path}: unreadable run metadata ({e})") from None
    if scenario is not None:
        scn = load_scenario(scenario)
    elif meta:
        scn = scenario_from_meta(meta)
    else:
        raise ScenarioError(
            f"{path}: no meta.json beside the capture; give --scenario NAME_OR_FILE for its PWM rate and motor"
        )
    out = out_dir or path.parent
    out.mkdir(parents=True, exist_ok=True)
    meta = dict(meta, analyzed_from=str(path))
    if problem:
        meta["capture_read_error"] = problem
    try:
        return finish_run(
            frames, codec, scn, out, meta=meta, wall_s=float(meta.get("wall_s", 0.0)), capture=path
        )
    except ValueError as e:
        raise CaptureError(f"{path}: {e}") from None
