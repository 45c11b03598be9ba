"""Shared helpers of the tests: SocketCAN (vcan) availability.

SocketCAN tests (``@pytest.mark.socketcan``) need ``vcan0`` (some also
``vcan1``) with CAN FD enabled.  Where it is missing they are skipped, except
when ``tools/vcan-tests`` runs them (it sets ``VCAN_TESTS_RUNNER``): then a
missing interface is a failure, so a broken setup cannot pass as skipped.
"""

from __future__ import annotations

import atexit
import os
import shutil
import socket
import tempfile

import pytest

# pytester: the hil plugin's own tests run pytest on a test file of a user's
pytest_plugins = ["pytester"]

# bench rtcheck keeps this host's result under $XDG_CACHE_HOME and bench run reads
# it: the tests (and the node processes they start) use a folder of their own
os.environ["XDG_CACHE_HOME"] = _CACHE = tempfile.mkdtemp(prefix="bench-tests-cache-")
atexit.register(shutil.rmtree, _CACHE, ignore_errors=True)

#: Set by tools/vcan-tests (``native`` or ``uml``).
RUNNER_ENV = "VCAN_TESTS_RUNNER"


def vcan_problem(channel: str = "vcan0") -> str | None:
    """Why a CAN_RAW socket with CAN FD cannot be bound to ``channel`` here, or None."""
    af_can = getattr(socket, "AF_CAN", None)
    if af_can is None:
        return "this Python has no socket.AF_CAN"
    try:
        with socket.socket(af_can, socket.SOCK_RAW, socket.CAN_RAW) as sock:
            sock.setsockopt(socket.SOL_CAN_RAW, socket.CAN_RAW_FD_FRAMES, 1)
            sock.bind((channel,))
    except OSError as exc:
        return f"cannot bind a CAN FD raw socket to {channel}: {exc}"
    return None


def require_vcan(*channels: str) -> None:
    """Skip the calling test when a channel is unusable; fail instead under tools/vcan-tests."""
    for channel in channels or ("vcan0",):
        problem = vcan_problem(channel)
        if problem is None:
            continue
        reason = (
            f"{problem} (tools/vcan-tests runs SocketCAN tests natively or inside User-Mode Linux)"
        )
        if os.environ.get(RUNNER_ENV):
            pytest.fail(f"{RUNNER_ENV}={os.environ[RUNNER_ENV]}: {reason}")
        pytest.skip(reason)


@pytest.fixture
def vcan0() -> str:
    """The name ``vcan0``, after checking that it carries CAN FD frames."""
    require_vcan("vcan0")
    return "vcan0"


@pytest.fixture
def vcan_pair() -> tuple[str, str]:
    """``vcan0`` and ``vcan1`` (the two sides of a latency link), checked."""
    require_vcan("vcan0", "vcan1")
    return "vcan0", "vcan1"


@pytest.fixture(scope="session")
def native_library() -> None:
    """The native node loops' library, built into this session's cache before the test.

    The cache above is new each session, so the first run of a session builds the
    library (code generation and the C compiler: 150 s measured at load 15 on 2
    cores) before its nodes start.  A test that waits a bounded time for a run to
    start, or times how a run ends, takes this fixture so that the build is not in
    its clock.  No compiler: the nodes serve in Python and say so; nothing to do.
    """
    from bench._errors import BenchError
    from bench.nodes.native._native import library_path

    try:
        library_path()
    except BenchError:
        pass
