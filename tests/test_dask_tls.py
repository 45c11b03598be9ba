"""docs/SCALING.md's remote cluster over TLS: ``bench sweep --scheduler tls://...`` with Dask's
TLS configuration, and one line (exit 2) without it.

The certificate is made here (openssl); a scheduler and a worker run as the recipe starts
them, on 127.0.0.1, and the sweep reads its certificate from the environment variables
that docs/SCALING.md sets.
"""

from __future__ import annotations

import csv
import json
import os
import re
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DASK = Path(sys.executable).with_name("dask")


def _tls_env(d: Path) -> dict[str, str]:
    """The environment of docs/SCALING.md's recipe: Dask's TLS configuration."""
    return {
        "DASK_DISTRIBUTED__COMM__REQUIRE_ENCRYPTION": "True",
        "DASK_DISTRIBUTED__COMM__TLS__CA_FILE": str(d / "ca.pem"),
        "DASK_DISTRIBUTED__COMM__TLS__CLIENT__CERT": str(d / "cert.pem"),
        "DASK_DISTRIBUTED__COMM__TLS__CLIENT__KEY": str(d / "key.pem"),
    }


def _wait_for(log: Path, pattern: str, proc: subprocess.Popen[bytes], timeout: float) -> str:
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        m = re.search(pattern, log.read_text(errors="replace"))
        if m:
            return m.group(0)
        if proc.poll() is not None:
            break
        time.sleep(0.2)
    pytest.fail(f"{pattern!r} not in {log.name}: {log.read_text(errors='replace')[-2000:]}")


@pytest.fixture(scope="module")
def tls_cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, Path]]:
    pytest.importorskip("distributed")
    if shutil.which("openssl") is None or not DASK.exists():
        pytest.skip("needs openssl and the dask command")
    d = tmp_path_factory.mktemp("tls")
    # a CA of the test's own, and a certificate for 127.0.0.1 signed by it
    subprocess.run(
        ["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1",
         "-subj", "/CN=bench-test-ca", "-keyout", str(d / "ca-key.pem"), "-out", str(d / "ca.pem")],
        check=True, capture_output=True,
    )  # fmt: skip
    subprocess.run(
        ["openssl", "req", "-newkey", "rsa:2048", "-nodes", "-subj", "/CN=127.0.0.1",
         "-keyout", str(d / "key.pem"), "-out", str(d / "req.pem")],
        check=True, capture_output=True,
    )  # fmt: skip
    (d / "ext.cnf").write_text("subjectAltName=IP:127.0.0.1,DNS:localhost\n")
    subprocess.run(
        ["openssl", "x509", "-req", "-in", str(d / "req.pem"), "-CA", str(d / "ca.pem"),
         "-CAkey", str(d / "ca-key.pem"), "-CAcreateserial", "-days", "1",
         "-extfile", str(d / "ext.cnf"), "-out", str(d / "cert.pem")],
        check=True, capture_output=True,
    )  # fmt: skip
    tls = ["--tls-ca-file", str(d / "ca.pem"), "--tls-cert", str(d / "cert.pem")]
    tls += ["--tls-key", str(d / "key.pem")]
    procs: list[subprocess.Popen[bytes]] = []
    try:
        s_log = d / "scheduler.log"
        with s_log.open("wb") as f:
            cmd = [str(DASK), "scheduler", "--protocol", "tls", "--host", "127.0.0.1"]
            cmd += ["--port", "0", "--no-dashboard", *tls]
            procs.append(subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT))
        addr = _wait_for(s_log, r"tls://127\.0\.0\.1:\d+", procs[0], 60.0)
        w_log = d / "worker.log"
        with w_log.open("wb") as f:
            cmd = [str(DASK), "worker", addr, "--nworkers", "1", "--nthreads", "1"]
            cmd += ["--no-dashboard", *tls]
            procs.append(subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT))
        _wait_for(w_log, r"Starting established connection", procs[1], 60.0)
        yield addr, d
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def _sweep(addr: str, out: Path, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "bench", "sweep", "xue-fig13", "-e", "square-wave",
         "--grid", "seed=1,2", "--duration", "0.3", "-q",
         "--executor", "dask", "--scheduler", addr, "--out", str(out)],
        cwd=ROOT, capture_output=True, text=True, timeout=300,
        env={**os.environ, **env},
    )  # fmt: skip


def test_a_sweep_on_a_tls_scheduler(tls_cluster: tuple[str, Path], tmp_path: Path) -> None:
    addr, d = tls_cluster
    res = _sweep(addr, tmp_path / "out", _tls_env(d))
    assert res.returncode == 0, res.stderr[-3000:]
    with (tmp_path / "out" / "results.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert sorted(r["seed"] for r in rows) == ["1", "2"]
    assert all(r["theta_err_abs_max_deg"] not in ("", "nan") for r in rows)
    sweep = json.loads((tmp_path / "out" / "sweep.json").read_text())
    assert sweep["throughput"]["executor"] == "dask"
    assert sweep["throughput"]["scheduler"] == addr


def test_without_the_tls_configuration_one_line(
    tls_cluster: tuple[str, Path], tmp_path: Path
) -> None:
    addr, _ = tls_cluster
    env = {k: v for k, v in os.environ.items() if not k.startswith("DASK_")}
    res = subprocess.run(
        [sys.executable, "-m", "bench", "sweep", "xue-fig13", "-e", "square-wave",
         "--grid", "seed=1", "--duration", "0.3", "-q",
         "--executor", "dask", "--scheduler", addr, "--out", str(tmp_path / "x")],
        cwd=ROOT, capture_output=True, text=True, timeout=120, env=env,
    )  # fmt: skip
    assert res.returncode == 2
    err = res.stderr.strip()
    assert err.count("\n") == 0 and "Traceback" not in err, err
    assert f"--scheduler {addr}: cannot connect" in err and "Dask's TLS configuration" in err


def test_udp_multicast_stays_on_the_local_link() -> None:
    """docs/RELIABILITY.md: the bench's udp_multicast buses send for this host only (hop
    limit 0, ``UDP_HOP_LIMIT``), python-can's as the native nodes'."""
    import socket

    from bench.wire._bus import BusSpec, own_udp_port, udp_multicast_group

    group = udp_multicast_group()
    bus = BusSpec("udp_multicast", group, own_udp_port()).open()
    try:
        sock = bus._multicast._socket  # type: ignore[attr-defined]
        if sock.family == socket.AF_INET6:
            hops = sock.getsockopt(socket.IPPROTO_IPV6, socket.IPV6_MULTICAST_HOPS)
        else:
            hops = sock.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL)
        assert hops == 0
    finally:
        bus.shutdown()
