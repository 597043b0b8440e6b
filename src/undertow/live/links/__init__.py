"""Live sensor links: each connects to one sensor protocol, reconnects with backoff after a drop,
stamps every measurement (:class:`~undertow.io.links.common.ClockPolicy`), counts what it
dropped (:class:`~undertow.io.links.common.LinkCounters`) and delivers
:class:`~undertow.io.links.common.Record` objects to a callback or a bounded queue.

- :class:`~undertow.io.links.a50_tcp.A50TcpLink`: Water Linked DVL A50, TCP JSON (port 16171);
- :class:`~undertow.io.links.ping1d.Ping1DLink`: Blue Robotics Ping1D (``brping``), UDP or serial;
- :class:`~undertow.io.links.mavlink_udp.MavlinkLink`: the autopilot over MAVLink (``pymavlink``).

:func:`~undertow.io.links.common.records_to_log` turns the records into a Log.
"""

from __future__ import annotations

from .a50_tcp import A50TcpLink
from .common import (
    Backoff,
    ClockPolicy,
    Link,
    LinkCounters,
    Record,
    ScaledClock,
    records_to_log,
)

_LAZY = {"MavlinkLink": "mavlink_udp", "Ping1DLink": "ping1d"}


def __getattr__(name: str):
    # imported on first use: io.mavlink imports .common, so an eager import would be circular
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(name)


__all__ = [
    "A50TcpLink",
    "Backoff",
    "ClockPolicy",
    "Link",
    "LinkCounters",
    "MavlinkLink",
    "Ping1DLink",
    "Record",
    "ScaledClock",
    "records_to_log",
]
