"""UDP ports of their own for the tests' udp_multicast buses.

python-can's udp_multicast binds with ``SO_REUSEADDR``/``SO_REUSEPORT`` and
Linux delivers a multicast datagram to every socket bound to its port (any
group), so only the port keeps two runs on one host apart.  A port is
handed out once per test process, at random, and only after a bind without
the reuse options has shown that no other socket holds it (nor the next
ones, which a latency link's second bus uses).
"""

from __future__ import annotations

import random
import socket

_GIVEN: set[int] = set()


def _free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind(("", port))
        except OSError:
            return False
    return True


def free_port(span: int = 2) -> int:
    """A port ``p`` such that ``p .. p + span - 1`` are unused on this host."""
    rng = random.SystemRandom()
    for _ in range(1000):
        p = rng.randrange(20000, 60000 - span)
        block = range(p, p + span)
        if any(q in _GIVEN for q in block):
            continue
        if all(_free(q) for q in block):
            _GIVEN.update(block)
            return p
    raise RuntimeError("no free UDP port block found")
