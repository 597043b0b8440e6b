"""The virtual robot's sensors: servers speaking the real protocols, fed from a Log.

- :class:`~undertow.io.servers.a50.A50Server` / :class:`~undertow.io.servers.a50.A50Reports`:
  a Water Linked DVL A50 on TCP (JSON lines, json_v3), answering its commands;
- :class:`~undertow.io.servers.ping1d.Ping1DServer`: a Blue Robotics Ping1D on UDP (brping's
  message definitions), answering each distance request with the log's newest range;
- :class:`~undertow.io.servers.mavlink.MavlinkSender`: an ArduSub autopilot's ATTITUDE,
  SCALED_IMU2, SCALED_PRESSURE2 (and DISTANCE_SENSOR) sent with pymavlink;
- :class:`~undertow.io.servers.player.Player`: plays the log in real time x rate with
  :class:`~undertow.io.servers.player.Faults`, listing every message in a
  :class:`~undertow.io.servers.player.Manifest`; :func:`~undertow.io.servers.decode.served_log`
  turns a manifest back into a Log.

``undertow.jobs.serve.serve`` puts them together (``undertow serve``).
"""

from __future__ import annotations

from .player import CLOCK_TARGETS, Faults, Manifest, PlayClock, Player, Served

__all__ = ["CLOCK_TARGETS", "Faults", "Manifest", "PlayClock", "Player", "Served"]
