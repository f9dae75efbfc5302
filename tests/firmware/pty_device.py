"""The device end of a pseudo-terminal, served from a thread (test helper).

``PtyDevice(on_line=...)`` answers each received line with the bytes the
callback returns (a command/reply bridge); ``PtyDevice(stream=...)`` writes the
callback's bytes whenever the line can take more (a free-running stream). The
host side opens ``device.path`` like any serial port.
"""

from __future__ import annotations

import contextlib
import os
import select
import threading
import tty
from collections.abc import Callable


class PtyDevice:
    def __init__(self, on_line: Callable[[bytes], list[bytes]] | None = None,
                 stream: Callable[[], bytes] | None = None) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)  # no echo, no newline translation: a clean 8-bit line
        self.path = os.ttyname(self.slave)
        self.on_line = on_line
        self.stream = stream
        self.received: list[bytes] = []
        self.inject: Callable[[bytes], bytes] | None = None  # corrupts replies when set
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        buf = b""
        pending = b""
        while not self._stop.is_set():
            want_write = bool(pending) or self.stream is not None
            r, w, _ = select.select([self.master], [self.master] if want_write else [], [], 0.02)
            if r:
                try:
                    buf += os.read(self.master, 4096)
                except OSError:
                    continue
                while b"\n" in buf:
                    line, buf = buf.split(b"\n", 1)
                    self.received.append(line + b"\n")
                    if self.on_line is not None:
                        reply = b"".join(self.on_line(line + b"\n"))
                        pending += self.inject(reply) if self.inject else reply
            if w:
                if not pending and self.stream is not None:
                    pending = self.stream()
                with contextlib.suppress(BlockingIOError):
                    pending = pending[os.write(self.master, pending[:4096]):]

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        os.close(self.master)
        os.close(self.slave)
