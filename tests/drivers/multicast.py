"""A udp_multicast CAN bus for one test at a time.

python-can binds every ``udp_multicast`` bus to one port on all addresses, and Linux hands such
a socket the datagrams of every group any socket on the host has joined (``IP_MULTICAST_ALL``):
two tests on different random groups still hear each other's nodes (a torquer module answered
another test's SDO request with its own object). A lock file serializes them across pytest's
workers; the wait is for the other test to end, never a deadline.
"""

from __future__ import annotations

import fcntl
import random
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

LOCK = Path(tempfile.gettempdir()) / "fbs-tests-udp-multicast.lock"


@contextmanager
def lone_multicast_group() -> Iterator[str]:
    """A random group address (239.x.y.z), no other test on udp_multicast until the block ends."""
    with open(LOCK, "a") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield ".".join(["239"] + [str(random.randrange(1, 255)) for _ in range(3)])
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)
