"""Live sensor links: each connects to one sensor protocol, reconnects with backoff after a drop,
stamps every measurement (:class:`~undertow.live.links.base.ClockPolicy`), counts what it
dropped (:class:`~undertow.live.links.base.LinkCounters`) and delivers
:class:`~undertow.records.Record` objects to a callback or a bounded queue.

- :class:`~undertow.live.links.a50_tcp.A50TcpLink`: Water Linked DVL A50, TCP JSON (port 16171);
- :class:`~undertow.live.links.ping1d.Ping1DLink`: Blue Robotics Ping1D (``brping``), UDP or
  serial;
- :class:`~undertow.live.links.mavlink_udp.MavlinkLink`: the autopilot over MAVLink
  (``pymavlink``).

The protocols' codecs are formats of :mod:`undertow.io` (:mod:`~undertow.io.a50_json`,
:mod:`~undertow.io.ping`, :mod:`~undertow.io.mavlink`), shared with the offline readers;
:func:`~undertow.records.records_to_log` turns the records into a Log.
"""

from __future__ import annotations

from .a50_tcp import A50TcpLink
from .base import Backoff, ClockPolicy, Link, LinkCounters
from .mavlink_udp import MavlinkLink
from .ping1d import Ping1DLink

__all__ = [
    "A50TcpLink",
    "Backoff",
    "ClockPolicy",
    "Link",
    "LinkCounters",
    "MavlinkLink",
    "Ping1DLink",
]
