"""Datagrams read with the time the kernel received them, for links whose socket the consumer's
loop reads itself (``polled``): a datagram read late is stamped as if read at once.

Linux socket(7): ``SO_TIMESTAMPNS`` attaches each datagram's receive time (``CLOCK_REALTIME``,
so ``time.time`` seconds) as a ``struct timespec``; ``SO_RXQ_OVFL`` attaches the count of the
datagrams the socket dropped so far (the receive buffer full), to the next datagram it keeps.
Elsewhere the options may be missing: the time is then the read's, and no drops are counted.
The first datagrams after timestamps are first asked for on a machine may carry the read's time
too: Linux enables them in deferred work and stamps what arrived before on reading it
(net/socket.c, ``__sock_recv_timestamp``).
"""

from __future__ import annotations

import socket
import struct
import sys
import time

_LINUX = sys.platform.startswith("linux")  # (its values where Python lacks the names)
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35 if _LINUX else None)
SO_RXQ_OVFL = getattr(socket, "SO_RXQ_OVFL", 40 if _LINUX else None)
_TIMESPEC = struct.Struct("@qq")
_DROPS = struct.Struct("@I")


def enable(sock: socket.socket) -> None:
    """Receive times and drop counts on ``sock``, made non-blocking (for :class:`Reader`)."""
    for option in (SO_TIMESTAMPNS, SO_RXQ_OVFL):
        if option is None:
            continue
        try:
            sock.setsockopt(socket.SOL_SOCKET, option, 1)
        except OSError:  # (a kernel without it)
            pass
    sock.setblocking(False)


class Reader:
    """Reads the datagrams waiting on a socket :func:`enable` set up, each with its receive
    time on the link's clock ``now`` (its ``at(wall)`` maps a ``time.time`` instant, as
    :class:`~undertow._util.clocks.ScaledClock` does; ``time.time`` itself needs none; any
    other clock gets the read time). ``dropped`` counts the datagrams the kernel dropped (the
    caller may take and reset it)."""

    def __init__(self, sock: socket.socket, now) -> None:
        self.sock = sock
        self.now = now
        at = getattr(now, "at", None)
        self._at = float if at is None and now is time.time else at
        self._drops = 0  # the socket's count so far
        self.dropped = 0
        self.address = None  # the sender of the last datagram read

    def read(self) -> tuple[bytes, float] | None:
        """(datagram, receive time) of the next waiting datagram; None when none waits (or the
        socket was closed meanwhile)."""
        try:
            data, ancillary, _, self.address = self.sock.recvmsg(65535, 256)
        except OSError:  # BlockingIOError: nothing waiting; or closed by a reconnect
            return None
        wall = None
        for level, kind, value in ancillary:
            if level != socket.SOL_SOCKET:
                continue
            if kind == SO_TIMESTAMPNS and len(value) >= _TIMESPEC.size:
                sec, nsec = _TIMESPEC.unpack_from(value)
                wall = sec + nsec * 1e-9
            elif kind == SO_RXQ_OVFL and len(value) >= _DROPS.size:
                drops = _DROPS.unpack_from(value)[0]
                self.dropped += (drops - self._drops) % (1 << 32)
                self._drops = drops
        at = self._at
        return data, (at(wall) if at is not None and wall is not None else self.now())
