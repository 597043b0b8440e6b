"""The virtual robot: servers speaking the real sensors' protocols, fed from a Log (a recorded
dive or a simulated run), so the live stage can be run without the robot.

- :class:`~undertow.sim.robot.a50.A50Server` / :class:`~undertow.sim.robot.a50.A50Reports`:
  a Water Linked DVL A50 on TCP (JSON lines, json_v3), answering its commands;
- :class:`~undertow.sim.robot.ping1d.Ping1DServer`: a Blue Robotics Ping1D on UDP (brping's
  message definitions), answering each distance request with the log's newest range;
- :class:`~undertow.sim.robot.mavlink.MavlinkSender`: an ArduSub autopilot's ATTITUDE,
  SCALED_IMU2, SCALED_PRESSURE2 (and DISTANCE_SENSOR) sent with pymavlink;
- :class:`~undertow.sim.robot.autopilot.VirtualAutopilot` (on that link by
  :class:`~undertow.sim.robot.autopilot_link.AutopilotLink`): an autopilot that consumes
  external navigation with ArduSub 4.x EKF3's rules (:mod:`~undertow.sim.robot.autopilot_rules`,
  :mod:`~undertow.sim.robot.autopilot_nav`) and reports what it uses;
- :class:`~undertow.sim.robot.player.Player`: plays the log in real time x rate with
  :class:`~undertow.sim.robot.player.Faults`, listing every message in a
  :class:`~undertow.sim.robot.player.Manifest`; :func:`~undertow.sim.robot.decode.served_log`
  turns a manifest back into a Log.

A50 lines and Ping distances are written with the codecs of :mod:`undertow.io` the live links
read them with (:mod:`~undertow.io.a50_json`, :mod:`~undertow.io.ping`), and ``served_log``
reads a manifest back with those and the MAVLink mapping (:mod:`~undertow.io.mavlink`). The
``serve`` command puts the servers together (``undertow serve``).
"""

from __future__ import annotations

from .player import CLOCK_TARGETS, Faults, Manifest, PlayClock, Player, Served

__all__ = ["CLOCK_TARGETS", "Faults", "Manifest", "PlayClock", "Player", "Served"]
