"""A loopback port where nobody listens, held so nobody else can start listening on it.

A test that stops its simulator and then connects to the same port races every other test
worker: the port is free again, and another worker's simulator may bind it in between (the
driver then reads some other device, as a CI run once did: "exception code 2" from a
stranger instead of "connection lost"). A socket bound but never put to ``listen()`` makes
the kernel refuse connections to that port while it stays ours.
"""

from __future__ import annotations

import socket
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def refusing_port(port: int, host: str = "127.0.0.1") -> Iterator[int]:
    """Hold ``port`` (or, if someone took it already, a fresh one) bound and not listening."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    # The stopped server's accepted connections may sit in TIME_WAIT on this port.
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        try:
            sock.bind((host, port))
        except OSError:
            sock.bind((host, 0))
        yield sock.getsockname()[1]
    finally:
        sock.close()
