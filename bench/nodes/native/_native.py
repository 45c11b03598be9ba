"""Build the native loop's library and programs, and read its counters (ctypes).

:func:`build` writes the DBC's C code with ``bench codegen`` (the same command
firmware/Makefile runs) and compiles the one library of the native pieces,
``libbench_native.so`` (transports, clock, the plant unit and its loop, the
controller unit, the in-process pair, with the plant core and the controller
core), and ``echo`` with the system's C compiler; :func:`library` builds it once
per source change into the user's cache and loads it once per process (the
plant node, the controller node and the in-process pair share it);
:func:`timing_run` runs the clock alone (``bn_timing_run``) and returns its
counters.  :class:`Frame` and :class:`Sig` mirror ``bn_frame_t`` and
``bn_sig_t`` (``bn.h``) for every user of the library.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bench._errors import BenchError
from bench.wire._bus import UDP_HOP_LIMIT

__all__ = [
    "CMD_SEEN",
    "HELD",
    "HERE",
    "LIB_SOURCES",
    "CmdSeen",
    "Frame",
    "Held",
    "NativeBuild",
    "Sig",
    "Stats",
    "build",
    "copy_span",
    "library",
    "library_path",
    "load",
    "timing_run",
]

HERE = Path(__file__).resolve().parent
#: The library's sources (beside this file).
LIB_SOURCES = ("bn_bus.c", "bn_msgpack.c", "bn_clock.c")
#: The plant node's and the controller node's units and loops, the in-process pair and
#: the recorder's receive thread (beside this file); the library links them with the DBC's C code and the controller
#: core that ``bench codegen`` writes (``gen/``, ``gen/core/``) and the plant core.
NODE_SOURCES = (
    "bn_plant.c",
    "bn_plant_loop.c",
    "bn_ctl.c",
    "bn_cmdseen.c",
    "bn_pair.c",
    "bn_rec.c",
)
#: The plant core's sources (the ones ``plant_rt._cplant`` is built from).
PLANT_CORE_DIR = HERE.parents[2] / "plant_rt" / "core"
#: Flags of every compile: C99 (with the POSIX and Linux calls), warnings as errors; no
#: fused multiply-add and no fast math, as the cores' own builds (controller/core/cc_math.h,
#: setup.py): the same arithmetic as the Plant and the Controller in Python.  Link-time
#: optimisation (one compile and link of every source) inlines the cores' small functions
#: across their files into the pair's and the nodes' loops (6 % of the in-process step,
#: docs/BENCHMARKS.md); it moves no rounding: each operation is still the same one in
#: double precision, so the traces are the same bits.  A compiler that cannot link with
#: it (clang without its linker plug-in) builds without (:data:`LTO_FLAGS`, :func:`_compile`).
CFLAGS = (
    "-std=c99",
    "-D_GNU_SOURCE",
    "-O2",
    "-flto",
    "-fno-semantic-interposition",
    "-Wall",
    "-Wextra",
    "-Werror",
    "-ffp-contract=off",
    "-fno-fast-math",
    f"-DBN_UDP_HOPS={UDP_HOP_LIMIT}",  # bn.h: the bench's one hop limit (bench/wire/_bus.py)
)
#: The flags of :data:`CFLAGS` that only make the build faster: left out when it fails with them.
LTO_FLAGS = ("-flto", "-fno-semantic-interposition")


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
    node_src = [str(HERE / s) for s in NODE_SOURCES]
    node_src += sorted(str(p) for p in gen.glob("core/*.c"))
    node_src += sorted(str(p) for p in PLANT_CORE_DIR.glob("*.c"))
    lib = out_dir / "libbench_native.so"
    _run(
        [
            cc,
            *CFLAGS,
            "-fPIC",
            "-shared",
            *includes,
            f"-I{gen / 'core'}",
            f"-I{PLANT_CORE_DIR}",
            "-o",
            str(lib),
            *lib_src,
            *gen_src,
            *node_src,
            "-lm",
            "-pthread",
        ],
        "compile",
        retry_without=LTO_FLAGS,
    )
    echo = out_dir / "echo"
    _run(
        [cc, *CFLAGS, *includes, "-o", str(echo), str(HERE / "echo.c"), *lib_src, *gen_src, "-lm"],
        "compile",
        retry_without=LTO_FLAGS,
    )
    return NativeBuild(lib, echo, gen)


def _sources_digest() -> str:
    """A digest of everything the library is built from (C sources, DBC, code generator,
    plant core, controller core) and the flags."""
    from bench.wire._codec import default_codec
    from controller import core_sources

    h = hashlib.sha256()
    files = sorted(HERE.glob("*.[ch]")) + sorted(PLANT_CORE_DIR.glob("*.[ch]"))
    files += list(core_sources())
    files.append(Path(default_codec().path))
    files.append(HERE.parents[1] / "wire" / "_cgen.py")
    files.append(HERE.parents[1] / "wire" / "_ctlgen.py")  # bench_wire.h
    for f in files:
        h.update(f.name.encode())
        h.update(f.read_bytes())
    h.update(" ".join(CFLAGS).encode())
    return h.hexdigest()[:16]


def _cache_root() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "can-hil-bench"


_PATHS: dict[str, Path] = {}


def library_path() -> Path:
    """``libbench_native.so`` for the present sources: built once per source change into the
    user's cache (``$XDG_CACHE_HOME/can-hil-bench/native-<digest>``, an atomic rename, so
    that processes building at once agree), looked up once per process.

    :class:`BenchError` with one line when it cannot be built (no C compiler, a compile
    error); :class:`OSError` when the cache cannot be written.
    """
    key = "lib"
    if key in _PATHS:
        return _PATHS[key]
    final = _cache_root() / f"native-{_sources_digest()}"
    lib = final / "libbench_native.so"
    if not lib.exists():
        final.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix="build-", dir=final.parent))
        try:
            build(tmp)
            try:
                tmp.rename(final)  # atomic: another process may have built it meanwhile
            except OSError:
                if not lib.exists():
                    raise
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)
    _PATHS[key] = lib
    return lib


_LIB: list[ctypes.CDLL] = []


def library() -> ctypes.CDLL:
    """The library (:func:`library_path`), loaded once per process with :func:`load`'s
    declarations; the plant node, the controller node and the pair add their own."""
    if not _LIB:
        _LIB.append(load(library_path()))
    return _LIB[0]


def _run(cmd: list[str], what: str, retry_without: tuple[str, ...] = ()) -> None:
    """Run a build step; one line when it fails.  ``retry_without``: flags that only make
    the build faster, dropped for a second try when the first fails."""
    res = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if res.returncode != 0 and retry_without:
        res = subprocess.run(
            [a for a in cmd if a not in retry_without], capture_output=True, text=True, check=False
        )
    if res.returncode != 0:
        lines = (res.stderr or res.stdout).strip().splitlines()
        raise BenchError(f"native loop: {what} failed: {lines[0] if lines else res.returncode}")


#: ``bn_frame_t.flags`` (bn.h's enum).
BN_EXT, BN_FD, BN_BRS, BN_ESI, BN_RTR, BN_ERR = 1, 2, 4, 8, 16, 32


class Frame(ctypes.Structure):
    """``bn_frame_t`` (bn.h)."""

    _fields_ = [
        ("id", ctypes.c_uint32),
        ("len", ctypes.c_uint8),
        ("flags", ctypes.c_uint8),
        ("data", ctypes.c_uint8 * 64),
        ("t_ns", ctypes.c_int64),
    ]


#: Frames a real-time node loop holds for Python (bn.h's BN_HELD).
HELD = 64


class Held(ctypes.Structure):
    """``bn_held_t`` (bn.h): the command frames a real-time loop held for the slack of a
    period: ``total`` held, the most at once (``max``), handed over at once (``full``)."""

    _fields_ = [
        ("total", ctypes.c_uint64),
        ("max", ctypes.c_uint64),
        ("full", ctypes.c_uint64),
        ("n", ctypes.c_int32),
        ("head", ctypes.c_int32),
        ("f", Frame * HELD),
    ]


#: ``BN_CMD_SEEN`` (bn.h): the bench commands a native node keeps to drop their copies;
#: at most the 64 keys ``CommandQueue.recent`` holds (tests/test_native_commands.py).
CMD_SEEN = 16


class CmdSeen(ctypes.Structure):
    """``bn_cmd_seen_t`` (bn.h): the bench commands Python took, whose copies the loop drops."""

    _fields_ = [
        ("id", ctypes.c_uint32),
        ("n", ctypes.c_int32),
        ("head", ctypes.c_int32),
        ("span", ctypes.c_int64),
        ("len", ctypes.c_uint8 * CMD_SEEN),
        ("flags", ctypes.c_uint8 * CMD_SEEN),
        ("data", (ctypes.c_uint8 * 8) * CMD_SEEN),
        ("k", ctypes.c_int64 * CMD_SEEN),
        ("copies", ctypes.c_uint64),
    ]


def copy_span(modulus: int) -> int:
    """Steps a bench command's copy may come after it and still be dropped as one
    (``bn_cmd_seen_t.span``, bn.h): an eighth of the step counter's ``modulus``."""
    return modulus // 8


class Sig(ctypes.Structure):
    """``bn_sig_t`` (bn.h): :meth:`bench.wire._codec.Codec.signal_table` of one signal."""

    _fields_ = [
        ("lo", ctypes.c_double),
        ("hi", ctypes.c_double),
        ("scale", ctypes.c_double),
        ("offset", ctypes.c_double),
        ("modulus", ctypes.c_int64),
        ("chk_lo", ctypes.c_double),
        ("chk_hi", ctypes.c_double),
    ]


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
    seen = ctypes.POINTER(CmdSeen)
    dll.bn_cmd_seen_init.argtypes = [seen, ctypes.c_uint32, ctypes.c_int64]
    dll.bn_cmd_seen_init.restype = None
    dll.bn_cmd_seen_take.argtypes = [seen, ctypes.POINTER(Frame), ctypes.c_int64]
    dll.bn_cmd_seen_take.restype = None
    dll.bn_cmd_seen_copy.argtypes = [seen, ctypes.POINTER(Frame), ctypes.c_int64]
    dll.bn_cmd_seen_copy.restype = ctypes.c_int
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
