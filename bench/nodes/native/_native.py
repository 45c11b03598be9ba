"""Build the native loop's library and programs, and read its counters (ctypes).

:func:`build` writes the DBC's C code with ``bench codegen`` (the same command
firmware/Makefile runs) and compiles ``libbench_native.so`` and ``echo`` with
the system's C compiler; :func:`timing_run` runs the clock alone
(``bn_timing_run``) and returns its counters.
"""

from __future__ import annotations

import ctypes
import os
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bench._errors import BenchError

__all__ = ["HERE", "LIB_SOURCES", "NativeBuild", "Stats", "build", "load", "timing_run"]

HERE = Path(__file__).resolve().parent
#: The library's sources (beside this file).
LIB_SOURCES = ("bn_bus.c", "bn_msgpack.c", "bn_clock.c")
#: The controller node's sources (beside this file); the library links them with the DBC's
#: C code and the controller core that ``bench codegen`` writes (``gen/``, ``gen/core/``).
CTL_SOURCES = ("bn_ctl.c",)
#: Flags of every compile: C99 (with the POSIX and Linux calls), warnings as errors; no
#: fused multiply-add, as the controller core's own build (controller/core/cc_math.h).
CFLAGS = ("-std=c99", "-D_GNU_SOURCE", "-O2", "-Wall", "-Wextra", "-Werror", "-ffp-contract=off")


@dataclass(frozen=True, slots=True)
class NativeBuild:
    """Where :func:`build` put its files."""

    lib: Path
    echo: Path
    gen: Path


def compiler() -> str:
    """The C compiler (``$CC``, else cc or gcc); :class:`BenchError` when there is none."""
    for name in (os.environ.get("CC"), "cc", "gcc"):
        if name and (path := shutil.which(name)):
            return path
    raise BenchError("native loop: no C compiler (set CC, or install gcc)")


def build(out_dir: Path) -> NativeBuild:
    """Generate the DBC's C code into ``out_dir/gen`` and compile the library and ``echo``."""
    cc = compiler()
    out_dir.mkdir(parents=True, exist_ok=True)
    gen = out_dir / "gen"
    _run([sys.executable, "-m", "bench", "codegen", str(gen)], "bench codegen")
    lib_src = [str(HERE / s) for s in LIB_SOURCES]
    gen_src = [str(gen / "bench_dbc.c"), str(gen / "bench_e2e.c")]
    includes = [f"-I{HERE}", f"-I{gen}"]
    ctl_src = [str(HERE / s) for s in CTL_SOURCES] + sorted(str(p) for p in gen.glob("core/*.c"))
    lib = out_dir / "libbench_native.so"
    _run(
        [
            cc,
            *CFLAGS,
            "-fPIC",
            "-shared",
            *includes,
            f"-I{gen / 'core'}",
            "-o",
            str(lib),
            *lib_src,
            *gen_src,
            *ctl_src,
            "-lm",
        ],
        "compile",
    )
    echo = out_dir / "echo"
    _run(
        [cc, *CFLAGS, *includes, "-o", str(echo), str(HERE / "echo.c"), *lib_src, *gen_src, "-lm"],
        "compile",
    )
    return NativeBuild(lib, echo, gen)


def _run(cmd: list[str], what: str) -> None:
    res = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if res.returncode != 0:
        lines = (res.stderr or res.stdout).strip().splitlines()
        raise BenchError(f"native loop: {what} failed: {lines[0] if lines else res.returncode}")


class Rt(ctypes.Structure):
    """``bn_rt_t``: the real-time settings asked for and granted."""

    _fields_ = [
        ("priority", ctypes.c_int32),
        ("fifo", ctypes.c_int32),
        ("memory_locked", ctypes.c_int32),
        ("cpu", ctypes.c_int32),
        ("err_sched", ctypes.c_int32),
        ("err_mlock", ctypes.c_int32),
        ("err_cpu", ctypes.c_int32),
    ]


class Stats(ctypes.Structure):
    """``bn_stats_t``: the clock's counters, read after the run (bn.h names each field)."""

    _fields_ = [
        ("periods", ctypes.c_uint64),
        ("missed", ctypes.c_uint64),
        ("late_half", ctypes.c_uint64),
        ("stalls", ctypes.c_uint64),
        ("skipped", ctypes.c_uint64),
        ("period_ns", ctypes.c_int64),
        ("wall_ns", ctypes.c_int64),
        ("late_min_ns", ctypes.c_int64),
        ("late_max_ns", ctypes.c_int64),
        ("busy_median_ns", ctypes.c_int64),
        ("busy_max_ns", ctypes.c_int64),
        ("rt", Rt),
    ]

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {f[0]: getattr(self, f[0]) for f in self._fields_[:-1]}
        out["rt"] = {f[0]: getattr(self.rt, f[0]) for f in Rt._fields_}
        return out


class TimingCfg(ctypes.Structure):
    """``bn_timing_cfg_t``."""

    _fields_ = [
        ("period_ns", ctypes.c_int64),
        ("busy_tail_ns", ctypes.c_int64),
        ("stall_ns", ctypes.c_int64),
        ("work_ns", ctypes.c_int64),
        ("periods", ctypes.c_uint64),
        ("rt_priority", ctypes.c_int32),
        ("lock_memory", ctypes.c_int32),
        ("cpu", ctypes.c_int32),
    ]


def load(lib: Path) -> ctypes.CDLL:
    """The built library, with the argument types of the calls Python makes."""
    dll = ctypes.CDLL(str(lib), use_errno=True)
    dll.bn_timing_run.argtypes = [
        ctypes.POINTER(TimingCfg),
        ctypes.POINTER(ctypes.c_uint32),
        ctypes.POINTER(Stats),
    ]
    dll.bn_timing_run.restype = ctypes.c_int
    dll.bn_mp_pack.argtypes = [
        ctypes.c_void_p,
        ctypes.c_double,
        ctypes.POINTER(ctypes.c_uint8),
        ctypes.c_size_t,
    ]
    dll.bn_mp_pack.restype = ctypes.c_size_t
    dll.bn_mp_unpack.argtypes = [ctypes.c_char_p, ctypes.c_size_t, ctypes.c_void_p]
    dll.bn_mp_unpack.restype = ctypes.c_int
    return dll


def timing_run(
    dll: ctypes.CDLL,
    period_s: float,
    periods: int,
    *,
    busy_tail_s: float = 0.0,
    work_s: float = 0.0,
    stall_s: float | None = None,
    rt_priority: int = 0,
    lock_memory: bool = False,
    cpu: int = -1,
) -> dict[str, Any]:
    """The clock alone for ``periods`` periods of ``period_s`` (``bn_timing_run``).

    ``work_s`` of spinning per period stands in for the loop's work;
    ``stall_s`` defaults to the Python clock's (:func:`bench.nodes._clock.default_stall_s`).
    The calling thread gets its scheduling class, affinity and memory lock back.
    """
    from bench.nodes._clock import default_stall_s

    stall = default_stall_s(period_s) if stall_s is None else stall_s
    cfg = TimingCfg(
        period_ns=round(period_s * 1e9),
        busy_tail_ns=round(busy_tail_s * 1e9),
        stall_ns=round(stall * 1e9),
        work_ns=round(work_s * 1e9),
        periods=periods,
        rt_priority=rt_priority,
        lock_memory=int(lock_memory),
        cpu=cpu,
    )
    busy = (ctypes.c_uint32 * max(1, periods))()
    stats = Stats()
    rc = dll.bn_timing_run(ctypes.byref(cfg), busy, ctypes.byref(stats))
    if rc != 0:
        raise OSError(-rc, os.strerror(-rc))
    return stats.as_dict()
