"""A simulated sensor bridge on a pseudo-terminal, for ``soakcal sim --serial``.

The simulated bridges listen on TCP (``socket://host:port``, which pyserial's
``serial_for_url`` opens); a reader written for a USB-serial port wants a device
path instead. :func:`open_pty_link` opens a pseudo-terminal pair and copies bytes
both ways between its master side and one TCP connection to the bridge, so the
slave side (``/dev/pts/N``) is a serial port carrying the bridge protocol
(docs/sensor-bridge.md) at whatever baud rate the reader sets (a pty ignores it).

POSIX only (``os.openpty``). The slave stays open here too, so a reader may close
and reopen the port without the link hanging up.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import tty
from dataclasses import dataclass, field

CHUNK = 4096
WRITE_RETRY_S = 0.005  # a reader not reading fills the pty's buffer: wait, do not block


@dataclass
class PtyLink:
    """One bridge exposed on a pseudo-terminal: open ``path`` as a serial port."""

    path: str
    master_fd: int
    slave_fd: int
    writer: asyncio.StreamWriter
    _pump: asyncio.Task[None] | None = field(default=None, repr=False)

    async def close(self) -> None:
        loop = asyncio.get_running_loop()
        loop.remove_reader(self.master_fd)
        if self._pump is not None:
            self._pump.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._pump
        self.writer.close()
        with contextlib.suppress(ConnectionError):
            await self.writer.wait_closed()
        for fd in (self.master_fd, self.slave_fd):
            with contextlib.suppress(OSError):
                os.close(fd)


async def open_pty_link(host: str, port: int) -> PtyLink:
    """Connect to the bridge at ``host:port`` and expose it on a new pseudo-terminal."""
    if not hasattr(os, "openpty"):
        raise OSError("pseudo-terminals need a POSIX system (os.openpty)")
    reader, writer = await asyncio.open_connection(host, port)
    master, slave = os.openpty()
    tty.setraw(slave)  # bytes as sent: no echo, no line editing, no CR/LF translation
    os.set_blocking(master, False)
    link = PtyLink(os.ttyname(slave), master, slave, writer)
    loop = asyncio.get_running_loop()

    def from_reader() -> None:  # the user's program wrote to the port: on to the bridge
        try:
            data = os.read(master, CHUNK)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:  # EIO: no slave open (cannot happen while we hold it), closed
            return
        if data:
            writer.write(data)

    async def to_reader() -> None:  # the bridge replied: into the port
        while data := await reader.read(CHUNK):
            view = memoryview(data)
            while view:
                try:
                    view = view[os.write(master, view):]
                except BlockingIOError:
                    await asyncio.sleep(WRITE_RETRY_S)

    loop.add_reader(master, from_reader)
    link._pump = asyncio.create_task(to_reader())
    return link
