"""The sensor links a live session opens, from the ``live`` settings (any subset)."""

from __future__ import annotations

from collections.abc import Callable

from ..errors import ConfigError
from ..records import Record
from ..settings import LiveSettings
from .links.a50_tcp import DEFAULT_PORT, A50TcpLink
from .links.base import Link

#: the streams each link delivers (what the filter waits for before it starts)
LINK_STREAMS = {
    "dvl": ("dvl", "dead_reckoning"),
    "sonar": ("sonar",),
    "mavlink": ("imu", "pressure"),
}
#: the highest Ping1D request rate the link allows (Hz of wall time)
MAX_PING_RATE_HZ = 100.0


def parse_tcp(address: str) -> tuple[str, int]:
    """(host, port) of ``tcp://HOST[:PORT]`` or ``HOST[:PORT]`` (port 16171 by default)."""
    text = str(address).strip().removeprefix("tcp://").rstrip("/")
    host, sep, port = text.rpartition(":") if text.count(":") == 1 else (text, "", "")
    if not sep:
        host, port = text, str(DEFAULT_PORT)
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not host or not 0 < number < 65536:
        raise ConfigError(f"live.dvl '{address}': expected tcp://HOST[:PORT]")
    return host, number


def open_links(live: LiveSettings, callback: Callable[[Record], None],
               now: Callable[[], float], wake: Callable[[], None] | None = None,
               ) -> dict[str, Link]:  # fmt: skip
    """The configured links (not started), keyed dvl / sonar / mavlink; a ConfigError names a
    bad address. Ping requests run at ``ping_rate_hz`` of sensor time (``time_scale`` times as
    often in wall time, at most :data:`MAX_PING_RATE_HZ`). The A50 and MAVLink links are
    ``deferred``: the caller's loop decodes what they receive (``Link.pump`` each turn);
    ``wake`` is called for what may hold a DVL report (A50 bytes, MAVLink DVL messages). With
    an A50 link (whose reports wake the loop), MAVLink over UDP is ``polled``: the loop reads
    its socket itself, each datagram stamped with its kernel receive time (no thread wakes for
    each; a DVL message on MAVLink then waits for the loop's next turn)."""
    links: dict[str, Link] = {}
    # a wall-time delay d is d * time_scale sensor seconds: the clock tolerance scales with it
    max_offset = live.max_clock_offset_s * live.time_scale
    if live.dvl:
        host, port = parse_tcp(live.dvl)
        links["dvl"] = A50TcpLink(host, port, callback, now=now, max_offset_s=max_offset,
                                  reset_dead_reckoning=live.reset_dead_reckoning,
                                  calibrate_gyro=live.calibrate_gyro, deferred=True,
                                  wake=wake)  # fmt: skip
    if live.sonar:
        from .links.ping1d import Ping1DLink

        rate = min(live.ping_rate_hz * live.time_scale, MAX_PING_RATE_HZ)
        links["sonar"] = Ping1DLink(live.sonar, callback, rate_hz=rate, now=now)
    if live.mavlink:
        from ..io.mavlink import MavlinkConfig
        from .links.mavlink_udp import MavlinkLink

        config = MavlinkConfig(pressure=live.mavlink_pressure)
        links["mavlink"] = MavlinkLink(live.mavlink, callback, now=now, max_offset_s=max_offset,
                                       config=config, deferred=True, wake=wake,
                                       kernel_filter=True, polled="dvl" in links)  # fmt: skip
    if not links:
        raise ConfigError("live: no sensor link given (--dvl, --sonar and/or --mavlink)")
    return links


def expected_streams(links: dict[str, Link]) -> set[str]:
    """The streams the open links deliver."""
    return {s for name in links for s in LINK_STREAMS[name]}
