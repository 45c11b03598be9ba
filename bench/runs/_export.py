"""A run's signals in the formats a drive engineer's tools open: CSV, ASAM MDF4, Parquet.

``signals.csv`` is the run folder's table (:func:`bench.runs._analysis.write_csv`),
always written.  The same rows can also be written as

- **ASAM MDF4** (``signals.mf4``, asammdf: the ``[mf4]`` extra), which
  CANape, INCA, asammdf's GUI and MATLAB's ``mdf`` open: one channel group,
  the master channel ``t`` (s), every other column a channel with its unit
  and its description as the channel's comment;
- **Parquet** (``signals.parquet``, pyarrow: the ``[parquet]`` extra), which
  pandas, polars, DuckDB and Spark read: one column each, the unit and the
  description in each field's metadata (``unit``, ``description``).

Units and descriptions are not written here: they come from
:data:`bench.runs._analysis.COLUMNS`, the one description of the columns
(``signals.md``), by :func:`column_meta`.  The values are the table's, as
``signals.csv`` holds them (a NaN stays NaN: a period without the
controller's telemetry).
"""

from __future__ import annotations

import importlib
import os
import re
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from bench._errors import BenchError
from bench.runs._analysis import COLUMNS, write_csv

__all__ = [
    "EXPORT_FILES",
    "FORMATS",
    "check_formats",
    "column_meta",
    "export_signals",
    "format_of",
    "parse_formats",
    "write_signals",
]

#: The formats, in the order ``--signals-format`` lists them; csv is the run folder's own.
FORMATS = ("csv", "mf4", "parquet")
#: The file suffix of each format.
SUFFIX = {"csv": ".csv", "mf4": ".mf4", "parquet": ".parquet"}
#: The library each optional format needs, and the extra that installs it.
NEEDS = {"mf4": ("asammdf", "mf4"), "parquet": ("pyarrow", "parquet")}
#: The files ``bench run --signals-format`` adds to a run folder (removed before a new run).
EXPORT_FILES = tuple(f"signals{SUFFIX[f]}" for f in FORMATS if f != "csv")

#: Integer columns (counters and codes without NaN): written as integers.
_INTEGER = ("step",)

#: How :data:`COLUMNS` spells a unit after its description's last comma, and the
#: unit symbol written (ASAM MDF's ``unit``); a text after the last comma that is
#: not one of these is part of the description, and the column has no unit.
_UNITS = {
    "s": "s",
    "rad": "rad",
    "electrical degrees": "deg",
    "rpm": "rpm",
    "N m": "N m",
    "A": "A",
    "V": "V",
    "rad/s": "rad/s",
    "0..1": "1",
    "0/1": "",
    "PWM periods": "periods",
}


def column_meta() -> dict[str, tuple[str, str]]:
    """Each column's ``(unit, description)``, read from :data:`COLUMNS`.

    A description there ends with its unit after the last comma (``true
    electrical angle, rad``), possibly followed by a parenthesis (``PWM
    periods (255: none)``); a column described by its unit alone (``t``:
    ``s``) has the unit as its whole text.  The description kept is the
    whole text of :data:`COLUMNS`, as ``signals.md`` shows it.
    """
    out: dict[str, tuple[str, str]] = {}
    for name, text in COLUMNS:
        last = text.rpartition(", ")[2]
        last = re.sub(r"\s*\(.*\)$", "", last).strip()
        unit = _UNITS.get(last, "")
        out[name] = (unit, text)
    return out


def parse_formats(values: Iterable[str]) -> list[str]:
    """The formats named by ``--signals-format`` (repeated, or comma-separated), in
    :data:`FORMATS` order, csv always among them; an unknown name is one line."""
    chosen = {"csv"}
    for value in values:
        for name in (v.strip().lower() for v in value.split(",")):
            if name not in FORMATS:
                raise BenchError(
                    f"--signals-format: invalid choice: {name!r} (choose from "
                    + ", ".join(map(repr, FORMATS))
                    + "; several as mf4,parquet)"
                )
            chosen.add(name)
    return [f for f in FORMATS if f in chosen]


def check_formats(formats: Iterable[str], what: str = "--signals-format") -> None:
    """Each format's library importable, else one line naming it and its extra.

    Checked before a run starts, so a missing library costs no run and
    loses nothing.
    """
    for fmt in formats:
        if fmt not in NEEDS:
            continue
        module, extra = NEEDS[fmt]
        try:
            importlib.import_module(module)
        except ImportError as e:
            raise BenchError(
                f"{what} {fmt}: needs {module}, which is not installed ({e}); "
                f"pip install 'can-hil-bench[{extra}]', or write signals.csv only"
            ) from None


def format_of(path: str | os.PathLike[str], fmt: str | None = None) -> str:
    """``fmt``, or the format of ``path``'s suffix (``.csv``, ``.mf4``, ``.parquet``)."""
    if fmt is None:
        suffix = Path(path).suffix.lower()
        by_suffix = {s: f for f, s in SUFFIX.items()}
        if suffix not in by_suffix:
            raise BenchError(
                f"{path}: unknown signals format {suffix or '(no suffix)'!r}: name it "
                f"(format={'|'.join(FORMATS)}) or use a suffix .csv, .mf4 or .parquet"
            )
        return by_suffix[suffix]
    if fmt not in FORMATS:
        raise BenchError(
            f"format: invalid choice: {fmt!r} (choose from {', '.join(map(repr, FORMATS))})"
        )
    return fmt


def write_signals(
    table: Mapping[str, np.ndarray],
    path: str | os.PathLike[str],
    fmt: str,
    *,
    title: str = "",
) -> Path:
    """Write the signals ``table`` (the columns of :data:`COLUMNS`) to ``path`` as ``fmt``.

    ``title`` (e.g. ``"wen-5.1 tt-dq"``) is the file's own comment: the MDF
    header's, the Parquet schema's ``title``.  A missing library, or a file
    that cannot be written, is a :class:`~bench._errors.BenchError` (one line).
    """
    path = Path(path)
    check_formats([fmt], what="format")
    missing = [n for n, _ in COLUMNS if n not in table]
    if missing:
        raise BenchError(f"{path}: the signals lack the columns {', '.join(missing)}")
    cols = {n: _values(n, table[n]) for n, _ in COLUMNS}
    try:
        if fmt == "csv":
            write_csv(str(path), {n: np.asarray(v, dtype=float) for n, v in cols.items()})
        elif fmt == "mf4":
            _write_mf4(cols, path, title)
        else:
            _write_parquet(cols, path, title)
    except OSError as e:
        raise BenchError(
            f"{path}: cannot write the signals as {fmt} ({e.strerror or type(e).__name__})"
        ) from None
    return path


def _values(name: str, column: Any) -> np.ndarray:
    arr = np.asarray(column, dtype=float)
    if name in _INTEGER and np.all(np.isfinite(arr)):
        return arr.astype(np.int64)
    return arr


def _write_mf4(cols: Mapping[str, np.ndarray], path: Path, title: str) -> None:
    from asammdf import MDF, Signal

    meta = column_meta()
    t = np.asarray(cols["t"], dtype=float)
    signals = [
        Signal(
            samples=v,
            timestamps=t,
            name=name,
            unit=meta[name][0],
            comment=meta[name][1],
        )
        for name, v in cols.items()
        if name != "t"
    ]
    mdf = MDF(version="4.10")
    try:
        mdf.header.comment = title or "can-hil-bench signals"
        mdf.append(signals, comment="signals.csv: one row per PWM period (signals.md)")
        mdf.save(path, overwrite=True)
    finally:
        mdf.close()


def _write_parquet(cols: Mapping[str, np.ndarray], path: Path, title: str) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    meta = column_meta()
    fields = [
        pa.field(
            name,
            pa.from_numpy_dtype(v.dtype),
            metadata={"unit": meta[name][0], "description": meta[name][1]},
        )
        for name, v in cols.items()
    ]
    schema = pa.schema(fields, metadata={"title": title or "can-hil-bench signals"})
    table = pa.Table.from_arrays([pa.array(v) for v in cols.values()], schema=schema)
    pq.write_table(table, path)


def export_signals(folder: Path, formats: Iterable[str], *, title: str = "") -> list[str]:
    """Write the run folder's ``signals.csv`` again as each of ``formats`` but csv,
    beside it (``signals.mf4``, ``signals.parquet``); the names written.

    The values are those ``signals.csv`` holds, so every file of a run says the same.
    A run that recorded no ``signals.csv`` gets none of them either.
    """
    from bench.runs._analysis import read_csv

    wanted = [f for f in formats if f != "csv"]
    csv = folder / "signals.csv"
    if not wanted or not csv.is_file():
        return []
    table = read_csv(str(csv))
    return [
        write_signals(table, folder / f"signals{SUFFIX[f]}", f, title=title).name for f in wanted
    ]
