"""One rule for which loop serves a node (``bench.cli._common.choose_node_engine``).

``bench plant`` and ``bench controller`` both take it: ``auto`` runs the native
loop where it can serve, else the Python node with one line saying why;
``--engine native`` that cannot be served is refused with one line and exit 2;
``compiled`` and ``python`` run the Python node without asking.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from bench._errors import BenchError
from bench.cli._common import choose_node_engine
from tests.ports import free_port

ROOT = Path(__file__).resolve().parents[1]
GROUP = "239.74.163.7"


def test_the_rule_for_each_engine(capsys: pytest.CaptureFixture[str]) -> None:
    asked: list[str] = []

    def why_not(reason: str | None) -> Callable[[], str | None]:
        def f() -> str | None:
            asked.append("x")
            return reason

        return f

    for engine in ("compiled", "python"):
        assert choose_node_engine("plant", engine, why_not("no")) == "python"
    assert asked == []  # not even asked
    assert choose_node_engine("plant", "auto", why_not(None)) == "native"
    assert choose_node_engine("controller", "native", why_not(None)) == "native"
    assert capsys.readouterr().err == ""
    assert choose_node_engine("controller", "auto", why_not("no transport")) == "python"
    assert capsys.readouterr().err == "controller: the Python node serves this run: no transport\n"
    with pytest.raises(BenchError, match=r"^--engine native: no transport$"):
        choose_node_engine("plant", "native", why_not("no transport"))
    assert capsys.readouterr().err == ""


def _node(role: str, engine: str | None, interface: str) -> list[str]:
    return [sys.executable, "-m", "bench", role, "wen-5.1", "--interface", interface,
            "--channel", GROUP, "--port", str(free_port()),
            *(["--engine", engine] if engine else [])]  # fmt: skip


@pytest.mark.parametrize("role", ["plant", "controller"])
def test_both_nodes_refuse_an_explicit_native_they_cannot_serve(role: str) -> None:
    """``--engine native`` on a transport the native loop does not speak (python-can's
    ``socketcand``): the same one line and exit 2 from either node, no traceback."""
    res = subprocess.run(
        _node(role, "native", "socketcand"), cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert res.returncode == 2, res.stderr[-2000:]
    last = res.stderr.strip().splitlines()[-1]
    assert last.startswith("bench: error: --engine native: "), last
    assert "socketcand" in last and "udp_multicast and socketcan" in last, last
    assert "Traceback" not in res.stderr and "Python node" not in res.stderr


@pytest.mark.parametrize("role", ["plant", "controller"])
def test_both_nodes_fall_back_from_auto_with_one_line(role: str) -> None:
    """``auto`` (the default) on that transport: one line naming why, then the Python
    node takes the bus (python-can's socketcand driver, which here has no daemon to
    reach: its own one-line error follows)."""
    res = subprocess.run(
        _node(role, None, "socketcand"), cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    lines = res.stderr.strip().splitlines()
    why = [ln for ln in lines if "the Python node serves this run" in ln]
    assert len(why) == 1 and why[0].startswith(f"{role}: "), res.stderr[-2000:]
    assert "socketcand" in why[0] and "--engine native" not in res.stderr
    assert lines[-1].startswith("bench: error: interface socketcand"), lines[-1]
    assert "Traceback" not in res.stderr
