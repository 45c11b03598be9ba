"""A run's signals as ASAM MDF4 and Parquet (``bench run --signals-format``, ``Run.save``):
the same samples as ``signals.csv``, each column's unit and description from ``COLUMNS``,
and one line (no traceback, no run lost) when a library is missing."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import bench
from bench.runs._analysis import COLUMNS, read_csv
from bench.runs._export import column_meta, parse_formats

ROOT = Path(__file__).resolve().parents[1]
BENCH = [sys.executable, "-m", "bench"]
SCENARIO = ROOT / "tests" / "data" / "firmware-100rpm.toml"


@pytest.fixture(scope="module")
def a_run(tmp_path_factory: pytest.TempPathFactory) -> bench.Run:
    return bench.run("wen-5.1", estimator="tt-dq", duration=0.3, out=tmp_path_factory.mktemp("r"))


def test_units_and_descriptions_come_from_the_columns() -> None:
    meta = column_meta()
    assert list(meta) == [n for n, _ in COLUMNS]
    assert {n: d for n, (_, d) in meta.items()} == dict(COLUMNS)
    units = {n: u for n, (u, _) in meta.items()}
    assert units["t"] == "s" and units["theta_e"] == "rad" and units["theta_err_deg"] == "deg"
    assert units["w_hat_rpm"] == "rpm" and units["tau_L"] == "N m" and units["i_q"] == "A"
    assert units["u_dc"] == "V" and units["d_a"] == "1" and units["duty_age"] == "periods"
    # a column whose description ends in no unit (a counter or a flag) has none, rather
    # than a guessed one
    assert {n for n, u in units.items() if not u} == {"step", "enable", "mode", "fault_active"}


def _same(a: np.ndarray, b: np.ndarray) -> None:
    np.testing.assert_array_equal(np.asarray(a, dtype=float), np.asarray(b, dtype=float))


def test_mf4_round_trip(a_run: bench.Run, tmp_path: Path) -> None:
    from asammdf import MDF

    path = a_run.save(tmp_path / "signals.mf4")
    sig = a_run.signals
    meta = column_meta()
    mdf = MDF(path)
    try:
        assert "wen-5.1 tt-dq" in mdf.header.comment
        for name, _ in COLUMNS:
            if name == "t":
                continue
            ch = mdf.get(name)
            _same(ch.samples, sig[name])
            _same(ch.timestamps, sig["t"])  # the master channel is signals.csv's t
            assert (ch.unit, ch.comment) == meta[name], name
        assert mdf.get("step").samples.dtype.kind == "i"
    finally:
        mdf.close()


def test_parquet_round_trip(a_run: bench.Run, tmp_path: Path) -> None:
    import pyarrow.parquet as pq

    path = a_run.save(tmp_path / "s.parquet")
    table = pq.read_table(path)
    assert table.column_names == [n for n, _ in COLUMNS]
    assert table.num_rows == len(a_run.signals["t"]) > 2000
    meta = column_meta()
    for name in table.column_names:
        _same(table.column(name).to_numpy(zero_copy_only=False), a_run.signals[name])
        md = table.schema.field(name).metadata
        assert (md[b"unit"].decode(), md[b"description"].decode()) == meta[name]
    assert table.schema.metadata[b"title"] == b"wen-5.1 tt-dq"


def test_csv_written_again_reads_back_the_same(a_run: bench.Run, tmp_path: Path) -> None:
    path = a_run.save(tmp_path / "copy", format="csv")
    assert path.read_text() == (a_run.folder / "signals.csv").read_text()  # type: ignore[operator]


def test_formats_and_suffixes_are_checked(a_run: bench.Run, tmp_path: Path) -> None:
    with pytest.raises(bench.BenchError, match=r"unknown signals format '\.h5'"):
        a_run.save(tmp_path / "x.h5")
    with pytest.raises(bench.BenchError, match="format: invalid choice: 'hdf5'"):
        a_run.save(tmp_path / "x.mf4", format="hdf5")
    assert parse_formats(["parquet", "mf4,csv"]) == ["csv", "mf4", "parquet"]
    assert parse_formats([]) == ["csv"]
    with pytest.raises(bench.BenchError, match="--signals-format: invalid choice: 'xls'"):
        parse_formats(["mf4,xls"])


def test_a_missing_library_is_one_line_and_the_run_is_kept(
    a_run: bench.Run, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    assert a_run.folder is not None
    before = {p.name: p.read_bytes() for p in a_run.folder.iterdir() if p.is_file()}
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # import pyarrow: ImportError
    with pytest.raises(bench.BenchError, match=r"needs pyarrow.*can-hil-bench\[parquet\]"):
        a_run.save(tmp_path / "s.parquet")
    assert not (tmp_path / "s.parquet").exists()
    assert {p.name: p.read_bytes() for p in a_run.folder.iterdir() if p.is_file()} == before


def test_cli_refuses_before_the_run_when_a_library_is_missing(tmp_path: Path) -> None:
    fake = tmp_path / "site"
    (fake / "asammdf").mkdir(parents=True)
    (fake / "asammdf" / "__init__.py").write_text("raise ImportError('no asammdf here')\n")
    out = tmp_path / "run"
    p = subprocess.run(
        [*BENCH, "run", str(SCENARIO), "--signals-format", "mf4", "--out", str(out)],
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": f"{fake}:{ROOT}"},
        timeout=120,
    )
    assert p.returncode == 2, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in p.stderr, p.stderr
    assert lines[0].startswith("bench: error: --signals-format mf4: needs asammdf")
    assert "can-hil-bench[mf4]" in lines[0]
    assert not out.exists()  # refused before any node started: no run to lose


@pytest.mark.slow
def test_cli_writes_every_format_asked(tmp_path: Path) -> None:
    out = tmp_path / "run"
    formats = ("--signals-format", "mf4", "--signals-format", "parquet")
    p = subprocess.run(
        [*BENCH, "run", str(SCENARIO), "--duration", "0.2", "-q", *formats, "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert p.returncode == 0, p.stderr
    files = next(x for x in p.stdout.splitlines() if x.startswith("files:"))
    assert "signals.csv, signals.mf4, signals.parquet" in files
    import pyarrow.parquet as pq
    from asammdf import MDF

    csv = read_csv(str(out / "signals.csv"))
    mdf = MDF(out / "signals.mf4")
    try:
        _same(mdf.get("w_m_rpm").samples, csv["w_m_rpm"])
    finally:
        mdf.close()
    table = pq.read_table(out / "signals.parquet")
    _same(table.column("theta_err_deg").to_numpy(zero_copy_only=False), csv["theta_err_deg"])
