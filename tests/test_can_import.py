"""python-can in the command line's processes: imported without asammdf, and a ``.mf4``
capture still read (bench/wire/_canimport.py)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("asammdf")

WRITE_MF4 = """
import sys, can
with can.Logger(sys.argv[1]) as log:
    for i in range(5):
        log.on_message_received(can.Message(timestamp=1.0 + i, arbitration_id=0x100 + i,
                                            is_extended_id=False, data=bytes([i] * 8)))
"""

READ_AFTER_CLI = """
import sys
import bench.cli  # the command line's start-up: python-can without its MF4 support
import can
print("asammdf" in sys.modules, "pandas" in sys.modules)
from pathlib import Path
from bench.captures._read import _open_reader
print([(m.arbitration_id, bytes(m.data)[0]) for m in _open_reader(Path(sys.argv[1]))])
"""


def _py(code: str, *args: str) -> str:
    r = subprocess.run(
        [sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 0, r.stderr
    return r.stdout


def test_the_command_line_starts_without_asammdf_and_still_reads_an_mf4_capture(
    tmp_path: Path,
) -> None:
    f = tmp_path / "x.mf4"
    _py(WRITE_MF4, str(f))
    first, frames = _py(READ_AFTER_CLI, str(f)).splitlines()
    assert first == "False False"  # python-can imported (bench.cli), asammdf and pandas not
    assert frames == str([(0x100 + i, i) for i in range(5)])
