"""The pytest plugin of the bench (entry point ``pytest11``): the ``hil`` fixture.

::

    def test_speed_loop(hil):
        run = hil.run("wen-5.1", estimator="tt-dq", duration=1.5)
        assert_within(run, theta_err_abs_mean_deg=4.0)

``hil.run(...)`` takes :func:`bench.run`'s arguments.  Each run's folder is
kept under the test's ``tmp_path`` (``hil-1-wen-5.1``, ...); the run's
metrics go into the JUnit XML as properties (``hil.<metric>``, a later run
of the same test ``hil.<n>.<metric>``), with its transport, folder and exit
status; its ``run.png`` goes into the HTML report where pytest-html is
installed.  Where it ran is said in the test's output (``hil: ...``).

Options: ``--hil-interface`` and ``--hil-channel`` name the bus (python-can's
names); ``--hil-engine`` the engine (``bench run --engine``).  Without a bus
named: vcan0 where the kernel has it up; else the bench's controller runs
in-process (the two-process trace at in-process speed), and a controller
under test (``controller="external"``) over udp_multicast.

The plugin is loaded into every pytest session of an environment the bench
is installed in: it imports nothing of the bench until a test asks for
``hil``.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest

__all__ = ["Hil"]

_PNG_KEY = pytest.StashKey[list[Path]]()


def pytest_addoption(parser: pytest.Parser) -> None:
    g = parser.getgroup("hil", "can-hil-bench: the hil fixture (docs/TESTING.md)")
    g.addoption(
        "--hil-interface",
        help="python-can interface of hil.run's bus (socketcan, udp_multicast, ...); default "
        "vcan0 where it is up, else in-process (udp_multicast for an external controller)",
    )
    g.addoption("--hil-channel", help="its channel (vcan0, can0, a multicast group, ...)")
    g.addoption(
        "--hil-engine",
        default="auto",
        choices=("auto", "compiled", "python"),
        help="engine of the plant and the controller (bench run --engine; default auto)",
    )


class Hil:
    """The ``hil`` fixture: :meth:`run` is :func:`bench.run` with the test's folder and bus."""

    def __init__(self, request: pytest.FixtureRequest, tmp_path: Path) -> None:
        self._request = request
        self._tmp = tmp_path
        self._n = 0
        opt = request.config.getoption
        self.interface: str | None = opt("--hil-interface")
        self.channel: str | None = opt("--hil-channel")
        self.engine: str = opt("--hil-engine")
        self.runs: list[Any] = []

    def transport(self, controller: str = "bench") -> str | None:
        """The ``transport=`` of a run with ``controller`` (None: in-process)."""
        if self.interface:
            return f"{self.interface}:{self.channel}" if self.channel else self.interface
        if self.channel:
            from bench._errors import InterfaceError

            raise InterfaceError("--hil-channel given without --hil-interface")
        from bench.wire._bus import default_transport

        iface, chan, _ = default_transport()
        if iface == "socketcan":
            return f"{iface}:{chan}"
        return "udp_multicast" if controller == "external" else None

    def run(self, scenario: Any, **kw: Any) -> Any:
        """:func:`bench.run` (same arguments); the folder defaults to one under ``tmp_path``."""
        from bench._api import run as bench_run

        self._n += 1
        n = self._n
        name = Path(str(getattr(scenario, "name", scenario))).name
        name = re.sub(r"\.(toml|json)$", "", name)  # a file's stem; wen-5.1 stays wen-5.1
        name = re.sub(r"[^A-Za-z0-9_.-]+", "-", name)
        kw.setdefault("out", self._tmp / f"hil-{n}-{name}")
        if "transport" not in kw:
            kw["transport"] = self.transport(kw.get("controller", "bench"))
        kw.setdefault("engine", self.engine)
        print(f"hil: {name} over {kw['transport'] or 'in-process'} -> {kw['out']}", flush=True)
        run = bench_run(scenario, **kw)
        self.runs.append(run)
        self._record(n, run)
        return run

    def _record(self, n: int, run: Any) -> None:
        prefix = "hil." if n == 1 else f"hil.{n}."
        # what record_property does, without its warning under junit_family xunit2 (whose
        # schema has no per-test properties; pytest writes them all the same)
        props = self._request.node.user_properties

        def record(name: str, value: object) -> None:
            props.append((name, value))

        record(f"{prefix}transport", run.transport)
        record(f"{prefix}folder", str(run.folder))
        record(f"{prefix}exit_status", run.exit_status)
        for key, value in run.metrics.items():
            if value is None or isinstance(value, bool | int | float | str):
                record(f"{prefix}{key}", value)
            else:  # a list or a table (faults, rejections by reason): as compact JSON
                record(f"{prefix}{key}", json.dumps(value, separators=(",", ":"), sort_keys=True))
        png = run.folder / "run.png" if run.folder is not None else None
        if png is not None and png.is_file():
            self._request.node.stash.setdefault(_PNG_KEY, []).append(png)


@pytest.fixture
def hil(request: pytest.FixtureRequest, tmp_path: Path) -> Hil:
    """The runs on the bench of this test, ``hil.run(scenario, estimator=..., ...)`` (docs/TESTING.md)."""
    return Hil(request, tmp_path)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Any:
    """The runs' ``run.png`` into the HTML report, where pytest-html is installed."""
    outcome = yield
    pngs = item.stash.get(_PNG_KEY, None)
    if call.when != "call" or not pngs:
        return
    try:
        from pytest_html import extras  # type: ignore[import-not-found,unused-ignore]
    except ImportError:
        return  # no pytest-html: nothing to attach to
    import base64

    report = outcome.get_result()
    found = list(getattr(report, "extras", []))
    for png in pngs:
        found.append(
            extras.png(base64.b64encode(png.read_bytes()).decode("ascii"), png.parent.name)
        )
    report.extras = found
